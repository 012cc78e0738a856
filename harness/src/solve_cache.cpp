// The solve cache of `deformbench run`: a solve that BenchmarkOptions::reuseReference may share,
// stored whole and read back (solve_cache.h).
#include "solve_cache.h"

#include <deform/engine/plugin_loader.h>
#include <deform/sdk/cache.h>
#include <deform_harness/runner.h>

#include <filesystem>
#include <fstream>
#include <string>

namespace deform::harness {

namespace fs = std::filesystem;

/// The key of a solve that BenchmarkOptions::reuseReference may share: the problem (the scene
/// without its models, reference, name, description and output, a mesh file's path made
/// absolute, and the organ as loaded), the plugin file (SHA-256), model and resolved parameters,
/// and the step limit. Neither the run's label nor whether it runs as the reference or as a model
/// enters: a convergence level at the reference's own parameters is the same solve.
CacheKey solveKey(const std::string& sceneFile, const Scene& scene, const Organ& organ,
                  PluginLoader& loader, const PlannedRun& p, const RunOptions& run) {
  nlohmann::json doc;
  {
    std::ifstream in(sceneFile);
    doc = nlohmann::json::parse(in);
  }
  for (const char* k : {"models", "reference", "name", "description", "output"}) doc.erase(k);
  if (doc.contains("organ") && doc["organ"].contains("mesh") && doc["organ"]["mesh"].is_string()) {
    const std::string mesh = doc["organ"]["mesh"];
    if (mesh.rfind("phantom:", 0) != 0 && !fs::path(mesh).is_absolute())
      doc["organ"]["mesh"] =
          fs::absolute(fs::path(sceneFile).parent_path() / mesh).lexically_normal().string();
  }
  CacheKey key;
  // /3: the validity rules of wave 3 (supports, instruments) changed what a stored valid means.
  // /5: the compared snapshots gained the registered marker error.
  key.add("harness.reference_run/5").add(doc.dump());
  key.add(organ.surface.V).add(organ.surface.F);
  key.add(sha256File(loader.locate(p.spec.plugin))).add(p.info->name).add(p.info->version);
  key.add(paramsToJson(p.params).dump());
  key.add(static_cast<long long>(run.maxSteps < 0 ? scene.numSteps() : run.maxSteps));
  key.add(run.quasiStaticAtComparedInstants ? (*run.quasiStaticAtComparedInstants ? 1 : 0) : -1);
  return key;
}

/// What a later run needs of a solve: its surfaces, counts, timings and the checks' inputs.
void storeCachedSolve(Cache& cache, const CacheKey& key, const RunRecord& r) {
  ByteWriter w;
  w.pod(static_cast<int>(r.steps));
  w.pod(static_cast<int>(r.plannedSteps));
  w.pod(static_cast<int>(r.solvedSteps));
  w.pod(static_cast<int>(r.fixedNodes));
  w.pod(static_cast<int>(r.fixedRegion));
  w.pod(r.graspResidual);
  w.pod(r.graspTravel);
  w.pod(static_cast<int>(r.equilibrium));
  w.pod(static_cast<int>(r.settledAt.has_value()));
  w.pod(r.settledAt.value_or(0.0));
  w.pod(static_cast<int>(r.valid));
  w.string(r.invalidReason);
  w.pod(r.peakDisplacement);
  w.pod(r.motionFloor);
  w.pod(r.fixedDrift);
  w.pod(r.precomputeS);
  w.pod(r.stepStats);
  w.pod(static_cast<int>(r.counts.size()));
  for (const auto& [k, v] : r.counts) {
    w.string(k);
    w.pod(v);
  }
  w.pod(static_cast<int>(r.phaseMs.size()));
  for (const auto& [k, v] : r.phaseMs) {
    w.string(k);
    w.pod(v);
  }
  w.pod(static_cast<int>(r.notes.size()));
  for (const std::string& n : r.notes) w.string(n);
  w.pod(r.dt);
  w.matrix(r.finalSurface);
  w.matrix(r.finalFaces);
  w.pod(static_cast<int>(r.compared.size()));
  for (const SurfaceSnapshot& s : r.compared) putSnapshotExtras(w, s);
  w.string(r.markerStatus);
  w.string(r.markerReason);
  cache.put(kReferenceRunKind, key, w.bytes());
}

bool readCachedSolve(Cache& cache, const CacheKey& key, bool reference, RunRecord& r) {
  const auto hit = cache.get(kReferenceRunKind, key);
  if (!hit) return false;
  try {
    ByteReader b(*hit);
    r.steps = b.pod<int>();
    r.plannedSteps = b.pod<int>();
    r.solvedSteps = b.pod<int>();
    r.fixedNodes = b.pod<int>();
    r.fixedRegion = b.pod<int>() != 0;
    r.graspResidual = b.pod<double>();
    r.graspTravel = b.pod<double>();
    r.equilibrium = b.pod<int>() != 0;
    const bool settled = b.pod<int>() != 0;
    const double at = b.pod<double>();
    if (settled) r.settledAt = at;
    r.valid = b.pod<int>() != 0;
    r.invalidReason = b.string();
    r.peakDisplacement = b.pod<double>();
    r.motionFloor = b.pod<double>();
    r.fixedDrift = b.pod<double>();
    r.precomputeS = b.pod<double>();
    r.stepStats = b.pod<StepStats>();
    for (int i = 0, n = b.pod<int>(); i < n; ++i) {
      std::string k = b.string();
      r.counts[k] = b.pod<long long>();
    }
    for (int i = 0, n = b.pod<int>(); i < n; ++i) {
      std::string k = b.string();
      r.phaseMs[k] = b.pod<double>();
    }
    for (int i = 0, n = b.pod<int>(); i < n; ++i) r.notes.push_back(b.string());
    r.dt = b.pod<Real>();
    b.matrix(r.finalSurface);
    b.matrix(r.finalFaces);
    const int n = b.pod<int>();
    for (int i = 0; i < n; ++i) r.compared.push_back(getSnapshotExtras(b));
    r.markerStatus = b.string();
    r.markerReason = b.string();
    if (!b.atEnd()) throw std::runtime_error("trailing bytes");
  } catch (const std::exception&) {
    r = RunRecord();
    cache.reject(kReferenceRunKind, key);
    return false;  // unreadable: solve again
  }
  r.status = RunStatus::Ok;
  r.notes.push_back(std::string(reference ? "reference" : "model solve") +
                    " read from the cache (an earlier run solved the same problem with the same "
                    "plugin and parameters): its timings are that run's");
  return true;
}

}  // namespace deform::harness
