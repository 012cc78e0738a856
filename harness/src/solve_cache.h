// The solve cache of `deformbench run` (BenchmarkOptions::reuseReference): a solve that later runs
// of the same problem read instead of solving again. Internal to the harness library.
#pragma once

#include <deform/engine/plugin_loader.h>
#include <deform/engine/scene.h>
#include <deform/sdk/cache.h>
#include <deform_harness/runner.h>

#include <string>

namespace deform::harness {

/// The cache kind of a shared solve.
inline constexpr const char* kReferenceRunKind = "harness.reference_run";

/// The key of a solve that may be shared (solve_cache.cpp says what enters it).
CacheKey solveKey(const std::string& sceneFile, const Scene& scene, const Organ& organ,
                  PluginLoader& loader, const PlannedRun& p, const RunOptions& run);

/// Stores what a later run needs of the solve r.
void storeCachedSolve(Cache& cache, const CacheKey& key, const RunRecord& r);

/// Reads a stored solve into r (status Ok, a note that it was read); false when there is none
/// or it is unreadable (then it is rejected from the cache).
bool readCachedSolve(Cache& cache, const CacheKey& key, bool reference, RunRecord& r);

}  // namespace deform::harness
