// The `deformbench run` pipeline: plan, run (in this process or isolated, or read from the solve
// cache), compute the errors against the reference, write the results whole.
#include "solve_cache.h"

#include <deform/engine/interaction.h>
#include <deform/geometry/mesh_check.h>
#include <deform/internal/atomic_file.h>
#include <deform/sdk/contact.h>
#include <deform_harness/results.h>
#include <deform_harness/run_isolation.h>
#include <deform_harness/runner.h>
#include <deform_harness/stability.h>

#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <iterator>
#include <memory>
#include <optional>
#include <set>
#include <sstream>

namespace deform::harness {

namespace fs = std::filesystem;

namespace {

/// Marks every model run with whether its reference is valid (DESIGN "Metrics": reference_valid
/// false marks every error computed against a reference that is invalid, failed or not
/// converged; a reference whose solver gave up on a solve is invalid by assessValidity()).
void markReferenceValidity(const RunRecord& ref, std::vector<RunRecord>& runs) {
  const bool ok = ref.status == RunStatus::Ok && ref.valid;
  std::string why;
  if (!ok) {
    why = "the reference " + ref.label + " is " +
          (ref.status == RunStatus::Ok ? "invalid: " + ref.invalidReason : notRunReason(ref));
  }
  for (RunRecord& r : runs) {
    if (r.isReference) continue;
    r.referenceValid = ok;
    r.referenceInvalidReason = why;
  }
}

/// "150 pairs of triangles".
std::string pairsText(long long n) {
  return std::to_string(n) + (n == 1 ? " pair" : " pairs") + " of triangles";
}

/// The first compared instant (else the end of the run) at which the run's surface passes
/// through itself, as "at t = 1 s" with the pairs counted; nullopt when none does.
std::optional<std::pair<std::string, SelfIntersectionCount>> selfIntersection(
    const RunRecord& r, const SelfIntersectionCheck& check) {
  const auto found = [](const SelfIntersectionCount& c) { return c.free + c.atHeld > 0; };
  for (const SurfaceSnapshot& c : r.compared) {
    if (const SelfIntersectionCount n = check(c.positions); found(n)) {
      std::ostringstream at;
      at << "at t = " << c.time << " s";
      return std::make_pair(at.str(), n);
    }
  }
  if (!r.compared.empty()) return std::nullopt;
  const SelfIntersectionCount n = check(r.finalSurface);
  if (!found(n)) return std::nullopt;
  return std::make_pair(std::string("at the end of the run"), n);
}

/// A surface that passes through itself is no state of the solid: the reference (which has no
/// self-contact) is then invalid, and a model's run says so in its notes. A fold of the reference
/// only at the edge of what the scene holds (a clamp's box, a grasp's jaws: rigid regions without
/// contact) is the scene's idealised boundary, which every model shares: a note.
void checkSelfIntersections(const Scene& scene, const Organ& organ, std::vector<RunRecord>& runs) {
  const SelfIntersectionCheck check(scene, organ);
  for (RunRecord& r : runs) {
    if (r.status != RunStatus::Ok) continue;
    const auto at = selfIntersection(r, check);
    if (!at) continue;
    const auto& [when, n] = *at;
    if (!r.isReference) {
      r.notes.push_back("the surface passes through itself " + when + " (" +
                        pairsText(n.free + n.atHeld) + ")");
    } else if (n.free > 0 && r.valid) {
      r.valid = false;
      r.invalidReason =
          "its surface passes through itself " + when + " (" + pairsText(n.free) +
          (n.atHeld > 0 ? ", and " + std::to_string(n.atHeld) + " at a held edge" : std::string()) +
          "): no state of a solid (the reference has no self-contact)";
    } else if (n.free == 0) {
      r.notes.push_back("the surface folds through itself at the edge of the held region " + when +
                        " (" + pairsText(n.atHeld) +
                        "): the clamp or the jaws are rigid regions without contact");
    }
  }
}

}  // namespace

SelfIntersectionCheck::SelfIntersectionCheck(const Scene& scene, const Organ& organ)
    : m_rest(organ.surface), m_judged(findSelfIntersections(organ.surface, 1).ok()) {
  if (!m_judged) return;
  // The vertices the scene holds (grasped, fixed), then the held region's edge: them and their
  // neighbours (a fold there spans the strip).
  std::vector<char> held(size_t(m_rest.numVertices()), 0);
  for (int v : rmseExcludedVertices(scene, m_rest.V)) held[size_t(v)] = 1;
  if (!organ.fixed.empty())
    for (int v : fixedNodeIndices(m_rest.V, organ.fixed, m_rest)) held[size_t(v)] = 1;
  m_atEdge = heldRegionAndEdge(m_rest.F, held);
}

SelfIntersectionCount SelfIntersectionCheck::operator()(const MatX3& positions) const {
  const int nv = m_rest.numVertices();
  if (!m_judged || positions.rows() < nv) return {};
  return countSelfIntersections({positions.topRows(nv), m_rest.F}, m_atEdge);
}

void computeRunErrors(const Scene& scene, const Organ& organ, std::vector<RunRecord>& runs) {
  const auto ref =
      std::find_if(runs.begin(), runs.end(), [](const RunRecord& r) { return r.isReference; });
  if (ref == runs.end()) return;
  checkSelfIntersections(scene, organ, runs);
  markReferenceValidity(*ref, runs);
  if (ref->status != RunStatus::Ok) {
    for (RunRecord& r : runs) {
      if (!r.isReference) r.notes.push_back("no error: the reference run is " + notRunReason(*ref));
    }
    return;
  }
  // A collapse (issue 35, as stability's verdict "collapsed"): where the reference moves the
  // organ by under 10% of its size, a model that went through its support or moved by more than
  // its size did not model the scene.
  if (ref->valid && relativeDisplacement(organ.surface.V, ref->finalSurface) >= 0 &&
      relativeDisplacement(organ.surface.V, ref->finalSurface) < 0.1) {
    const std::vector<int> held =
        organ.fixed.empty() ? std::vector<int>{}
                            : fixedNodeIndices(organ.surface.V, organ.fixed, organ.surface);
    for (RunRecord& r : runs) {
      if (r.isReference || r.status != RunStatus::Ok || !r.valid) continue;
      const std::string why = collapseProblem(
          organ.surface.V,
          r.finalSurface.topRows(std::min(r.finalSurface.rows(), organ.surface.V.rows())), held);
      if (why.empty()) continue;
      r.valid = false;
      r.invalidReason =
          "collapsed: " + why + ", while the reference moves the organ by under 10% of its size";
    }
  }
  const Interaction interaction(scene, organ.surface);
  const Vec3 focus = interaction.focusPoint();
  if (ref->compared.empty()) {
    for (RunRecord& r : runs) {
      if (!r.isReference)
        r.notes.push_back("no error: the run ended before every compared instant");
    }
    return;
  }
  std::vector<MatX3> refSurfaces;
  for (const auto& s : ref->compared) refSurfaces.push_back(s.positions);
  const std::vector<int> excluded = rmseExcludedVertices(scene, organ.surface.V);
  for (RunRecord& r : runs) {
    if (r.isReference || r.status != RunStatus::Ok) continue;
    if (r.compared.size() != refSurfaces.size()) {
      r.notes.push_back("no error: the run has surfaces at different instants than the reference");
      continue;
    }
    std::vector<MatX3> mine;
    for (const auto& s : r.compared) mine.push_back(s.positions);
    r.error = computeErrors(mine, refSurfaces, organ.surface.V, focus, scene.nearest, excluded);
    r.referenceModel = ref->model;
  }
}

namespace {

std::string eventName(Cache::EventKind k) {
  switch (k) {
    case Cache::EventKind::Hit:
      return "hit";
    case Cache::EventKind::Miss:
      return "miss";
    case Cache::EventKind::Corrupt:
      return "corrupt (deleted)";
    case Cache::EventKind::Stored:
      return "stored";
    case Cache::EventKind::Disabled:
      return "disabled";
    case Cache::EventKind::StoreFailed:
      return "store failed";
  }
  return "?";
}

/// The note a run gets for each cache entry it could not store (once per kind).
void noteCacheStoreFailures(RunRecord& rec) {
  std::set<std::string> kinds;
  for (const Cache::Event& e : rec.cacheEvents) {
    if (e.what != Cache::EventKind::StoreFailed || !kinds.insert(e.kind).second) continue;
    rec.notes.push_back("warning: the cache entry " + e.kind + " could not be stored (" + e.detail +
                        "); the run went on without the cache");
  }
}

/// Runs longer than this many steps get a warning before they start and progress lines.
constexpr long long kLongRunSteps = 1000000;

std::string longRunWarning(const Scene& scene, const RunOptions& run) {
  const long long n =
      run.maxSteps >= 0 ? std::min(run.maxSteps, scene.numSteps()) : scene.numSteps();
  if (n <= kLongRunSteps) return "";
  std::ostringstream s;
  s << "warning: " << n << " steps per run (dt " << scene.dt << " s over " << scene.duration
    << " s): each model steps that many times; progress is printed as it goes";
  return s.str();
}

/// Prints "LABEL: step K of N (P%)" at most every 10 s (and never for short runs).
std::function<void(int, int)> stepProgress(const std::string& label,
                                           const std::function<void(const std::string&)>& out) {
  auto last =
      std::make_shared<std::chrono::steady_clock::time_point>(std::chrono::steady_clock::now());
  return [label, out, last](int done, int total) {
    const auto now = std::chrono::steady_clock::now();
    if (now - *last < std::chrono::seconds(total > kLongRunSteps ? 2 : 10)) return;
    *last = now;
    std::ostringstream s;
    s << "  " << label << ": step " << done << " of " << total << " (" << std::setprecision(3)
      << 100.0 * done / std::max(total, 1) << "%)";
    out(s.str());
  };
}

/// The SHA-256 and vertex count of each written final surface, in results.json beside its path,
/// so that `report` can refuse a surface that is not the one this results.json describes.
void signSurfaces(const fs::path& dir, const std::vector<RunRecord>& runs,
                  nlohmann::ordered_json& doc) {
  for (size_t i = 0; i < runs.size() && i < doc["runs"].size(); ++i) {
    if (runs[i].finalSurfaceFile.empty()) continue;
    auto& j = doc["runs"][i];
    j["final_surface_vertices"] = runs[i].finalSurface.rows();
    j["final_surface_sha256"] = sha256File((dir / runs[i].finalSurfaceFile).string());
  }
}

/// The top-level entries of outDir that its results.json names (run folders, the rest surface,
/// .compared.bin files): what a new results.json replaces.
std::set<std::string> namedEntries(const fs::path& outDir) {
  std::set<std::string> out;
  std::error_code ec;
  for (fs::directory_iterator it(outDir, ec), end; !ec && it != end; it.increment(ec))
    if (it->path().filename().string().size() > 13 &&
        it->path().filename().string().rfind(".compared.bin") ==
            it->path().filename().string().size() - 13)
      out.insert(it->path().filename().string());
  try {
    std::ifstream in(outDir / "results.json");
    if (!in) return out;
    const nlohmann::json doc = nlohmann::json::parse(in);
    const auto add = [&](const nlohmann::json& v) {
      if (!v.is_string()) return;
      const fs::path p = fs::path(v.get<std::string>()).lexically_normal();
      if (p.empty() || p.is_absolute()) return;
      const std::string first = p.begin()->string();
      if (first != ".." && first != "." && first.rfind(".staging.", 0) != 0) out.insert(first);
    };
    if (doc.contains("organ") && doc["organ"].is_object())
      add(doc["organ"].value("rest_surface", nlohmann::json()));
    for (const auto& r : doc.value("runs", nlohmann::json::array()))
      if (r.is_object())
        for (const char* k : {"final_surface", "surface_series", "grasp_forces"})
          if (r.contains(k)) add(r[k]);
  } catch (const std::exception&) {
    // unreadable: only its results.json goes
  }
  return out;
}

/// Moves what `staging` holds into outDir: the old results.json first out, then the entries it
/// named, then the new entries in, results.json last.
void swapInResults(const fs::path& staging, const fs::path& outDir) {
  const std::set<std::string> stale = namedEntries(outDir);
  fs::remove(outDir / "results.json");
  for (const std::string& e : stale) fs::remove_all(outDir / e);
  for (const auto& entry : fs::directory_iterator(staging)) {
    const std::string name = entry.path().filename().string();
    if (name == "results.json") continue;
    fs::remove_all(outDir / name);
    fs::rename(entry.path(), outDir / name);
  }
  fs::rename(staging / "results.json", outDir / "results.json");
  fs::remove_all(staging);
}

}  // namespace

fs::path comparedSurfaceFile(const fs::path& outDir, const std::string& label) {
  return outDir / (sanitizeLabel(label) + ".compared.bin");
}

bool readComparedSurface(const fs::path& file, MatX3& positions) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return false;
  const std::vector<char> bytes((std::istreambuf_iterator<char>(in)),
                                std::istreambuf_iterator<char>());
  try {
    ByteReader r(bytes);
    r.matrix(positions);
    return r.atEnd();
  } catch (const std::exception&) {
    return false;
  }
}

BenchmarkResult runBenchmark(const std::string& sceneFile, PluginLoader& loader,
                             const BenchmarkOptions& options) {
  const auto explain = [&](const std::string& s) {
    if (options.explain) options.explain(s);
  };
  const auto progress = [&](const std::string& s) {
    if (options.progress) options.progress(s);
  };
  BenchmarkResult result;
  result.scene = parseSceneFile(sceneFile);
  const Scene& scene = result.scene;
  result.organ = loadOrgan(scene, &result.organLog);
  for (const auto& line : result.organLog) explain("organ: " + line);
  explain("organ " + result.organ.source + ": " +
          std::to_string(result.organ.surface.numVertices()) + " vertices, " +
          std::to_string(result.organ.surface.numFaces()) + " triangles");

  const std::vector<PlannedRun> planned = planRuns(scene, loader, options);
  forceSingleThreadedNumerics();

  const fs::path cacheDir = options.cacheDir ? *options.cacheDir : Cache::defaultDir();
  Cache cache(cacheDir);
  explain(cacheDir.empty() ? std::string("cache disabled") : "cache folder " + cacheDir.string());

  // Output folder must be writable before hours of runs, not after.
  std::error_code ec;
  fs::create_directories(options.outDir, ec);
  if (ec || !fs::is_directory(options.outDir))
    throw InputError(options.outDir.string(), "", "cannot create the output folder");
  if (const std::string w = longRunWarning(scene, options.run); !w.empty()) progress(w);

  for (const PlannedRun& p : planned) {
    progress("running " + p.label + " ...");
    std::optional<CacheKey> refKey;
    RunRecord rec;
    bool fromCache = false;
    const bool shared = options.reuseReference && !cacheDir.empty() &&
                        (p.isReference || (options.reuseModelSolves &&
                                           solveOnlyAtComparedInstants(*p.info, p.params)));
    if (shared) {
      refKey = solveKey(sceneFile, scene, result.organ, loader, p, options.run);
      fromCache = readCachedSolve(cache, *refKey, p.isReference, rec);
      if (fromCache) {
        rec.model = p.info->name;
        rec.params = paramsToJson(p.params);
        explain((p.isReference ? "reference " : "model ") + p.label + " read from the cache " +
                kReferenceRunKind);
      }
    }
    if (!fromCache) {
      RunOptions ro = options.run;
      if (!ro.onStep && options.progress) ro.onStep = stepProgress(p.label, options.progress);
      rec = options.isolateRuns
                ? runModelIsolated(*p.info, p.params, scene, result.organ, cache, ro)
                : runModel(*p.info, p.params, scene, result.organ, cache, ro);
      if (refKey && rec.status == RunStatus::Ok) {
        cache.clearEvents();
        storeCachedSolve(cache, *refKey, rec);
        for (const auto& e : cache.events()) rec.cacheEvents.push_back(e);
      }
    }
    noteCacheStoreFailures(rec);
    rec.plugin = p.spec.plugin;
    rec.label = p.label;
    rec.jsonPath = p.spec.jsonPath;
    rec.isReference = p.isReference;
    for (const auto& e : rec.cacheEvents)
      explain("cache " + eventName(e.what) + ": " + p.label + " " + e.kind + " " + e.key);
    if (rec.status == RunStatus::Unsupported) explain("skipped " + p.label + ": " + rec.message);
    if (rec.status != RunStatus::Unsupported) {
      if (rec.worlds.empty()) {
        explain(p.label + ": no Bullet or ODE world (the scene's tools are kinematic)");
      } else {
        for (const auto& w : rec.worlds) explain(p.label + ": created " + w);
      }
      if (rec.contactPairs >= 0)
        explain(p.label + ": contact: " + std::to_string(rec.contactPairs) +
                " broadphase pairs tested, " + std::to_string(rec.contacts) +
                " penetrating proxies resolved");
    }
    if (rec.solvedSteps >= 0) {
      explain(p.label + ": quasi-static, solved at " + std::to_string(rec.solvedSteps) + " of " +
              std::to_string(rec.steps) +
              " steps (the compared instants and the grasp closings; the interaction was "
              "prepared every step)");
    }
    if (!p.calibrationNote.empty()) rec.notes.push_back(p.calibrationNote);
    rec.calibration = p.calibrationFile;
    for (const auto& note : rec.notes) explain(p.label + ": " + note);
    progress(p.label + ": " + statusName(rec.status) +
             (rec.message.empty() ? "" : " (" + rec.message + ")"));
    result.runs.push_back(std::move(rec));
  }
  computeRunErrors(scene, result.organ, result.runs);

  // Everything is written into a staging folder first and swapped in whole: a rerun that fails
  // while writing (a full disk) leaves the previous results as they were, never a results.json
  // beside surfaces of another run (docs/results-format.md, "Writing").
  const fs::path staging = options.outDir / (".staging." + std::to_string(::getpid()));
  fs::remove_all(staging, ec);
  try {
    fs::create_directories(staging);
    writeRunSurfaces(staging, scene, result.organ, result.runs);
    if (options.writeComparedSurface)
      for (const RunRecord& r : result.runs)
        if (r.status == RunStatus::Ok && !r.compared.empty()) {
          ByteWriter w;
          w.matrix(r.compared.back().positions);
          writeFileAtomic(comparedSurfaceFile(staging, r.label),
                          std::string_view(w.bytes().data(), w.bytes().size()));
        }
    auto doc = resultsJson(scene, result.organ, result.organLog, result.runs, machineInfo());
    signSurfaces(staging, result.runs, doc);
    writeResults(staging, doc);
    swapInResults(staging, options.outDir);
  } catch (const std::exception& e) {
    fs::remove_all(staging, ec);
    if (dynamic_cast<const InputError*>(&e)) throw;
    throw InputError(options.outDir.string(), "",
                     std::string("cannot write the results: ") + e.what());
  }
  result.resultsPath = options.outDir / "results.json";
  return result;
}

}  // namespace deform::harness
