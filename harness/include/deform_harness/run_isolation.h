// deformbench harness: one model's run in a process of its own. runModelIsolated() forks, runs
// runModel() in the child and sends the finished RunRecord back through a pipe, so a plugin that
// crashes (a signal) in init() or step() takes down only its own run: the record comes back as
// `failed` with the signal ("killed by signal 11 (SIGSEGV)") and the other models of the scene
// run and are written as usual. The child is a copy of the parent (fork without exec), so it
// runs the same code on the same organ and parameters: the run is as deterministic as in
// process, and step() is timed inside the child exactly as runModel() times it.
#pragma once

#include <deform_harness/runner.h>

#include <vector>

namespace deform::harness {

/// runModel() in a forked child. Never throws for the model's trouble: a child killed by a
/// signal, exiting early or sending an unreadable record becomes status Failed with the reason.
/// Cache entries the child stored are on disk; its cache events come back in the record.
RunRecord runModelIsolated(const ModelInfo& info, const ParamValues& params, const Scene& scene,
                           const Organ& organ, Cache& cache, const RunOptions& options = {});

/// The fields runModel() fills (every field but the error and the output files), as bytes and
/// back; deserializeRunRecord() throws std::runtime_error on a short or inconsistent buffer.
std::vector<char> serializeRunRecord(const RunRecord& record);
RunRecord deserializeRunRecord(const std::vector<char>& bytes);

}  // namespace deform::harness
