// results.json, the surfaces written beside it, and where they were produced.
#include <deform/geometry/mesh_io.h>
#include <deform/internal/atomic_file.h>
#include <deform/sdk/cache.h>
#include <deform_harness/results.h>
#include <deform_harness/runner.h>
#include <dlfcn.h>

#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <fstream>
#include <set>
#include <sstream>

#ifndef DEFORM_SOURCE_DIR
#define DEFORM_SOURCE_DIR ""
#endif
#ifndef DEFORM_BUILD_TYPE
#define DEFORM_BUILD_TYPE ""
#endif
#ifndef DEFORM_VERSION
#define DEFORM_VERSION "0.1.0"
#endif

namespace deform::harness {

namespace fs = std::filesystem;
using json = nlohmann::ordered_json;

namespace {

std::string trim(std::string s) {
  const auto b = s.find_first_not_of(" \t\r\n");
  const auto e = s.find_last_not_of(" \t\r\n");
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}

std::string cpuModel() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) return trim(line.substr(colon + 1));
    }
  }
  return "";
}

std::string vectorUnits() {
#if defined(__x86_64__) && defined(__GNUC__)
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
      __builtin_cpu_supports("avx512dq"))
    return "avx512";
  return __builtin_cpu_supports("avx2") ? "avx2" : "sse2";
#else
  return "";
#endif
}

std::string gitDescribe() {
  const std::string src = DEFORM_SOURCE_DIR;
  if (src.empty() || !fs::exists(fs::path(src) / ".git")) return "";
  const std::string cmd = "git -C '" + src + "' describe --always --dirty --tags 2>/dev/null";
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return "";
  std::array<char, 256> buf{};
  std::string out;
  while (fgets(buf.data(), int(buf.size()), p)) out += buf.data();
  pclose(p);
  return trim(out);
}

/// JSON number, or null for NaN/Inf (JSON has neither).
json finite(double v) {
  return std::isfinite(v) ? json(v) : json(nullptr);
}

}  // namespace

// The plugins load OpenBLAS with RTLD_LOCAL, so it is found by its file name.
std::string loadedBlasKernels() {
  for (const char* lib : {"libblas.so.3", "libopenblas.so.0"}) {
    void* handle = ::dlopen(lib, RTLD_NOW | RTLD_NOLOAD);
    if (!handle) continue;
    using CoreNameFn = char* (*)();
    const auto coreName = reinterpret_cast<CoreNameFn>(::dlsym(handle, "openblas_get_corename"));
    const char* name = coreName ? coreName() : nullptr;
    std::string kernels = name ? name : "";
    ::dlclose(handle);
    if (!kernels.empty()) return kernels;
  }
  return "";
}

MachineInfo machineInfo() {
  MachineInfo m;
  m.cpu = cpuModel();
  m.vectorUnits = vectorUnits();
  m.blas = loadedBlasKernels();
#if defined(__clang__)
  m.compiler = std::string("Clang ") + __clang_version__;
#elif defined(__GNUC__)
  m.compiler = std::string("GCC ") + __VERSION__;
#else
  m.compiler = "unknown";
#endif
  m.buildType = DEFORM_BUILD_TYPE;
  if (m.buildType.empty()) {
#ifdef NDEBUG
    m.buildType = "Release";
#else
    m.buildType = "Debug";
#endif
  }
  m.git = gitDescribe();
  const std::time_t now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
  std::tm tm{};
  gmtime_r(&now, &tm);
  char buf[32];
  std::strftime(buf, sizeof(buf), "%Y-%m-%dT%H:%M:%SZ", &tm);
  m.timestamp = buf;
  m.version = DEFORM_VERSION;
  return m;
}

std::string sanitizeLabel(const std::string& label) {
  std::string s;
  for (char c : label) {
    const bool ok = std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '-' || c == '_';
    if (ok) {
      s += c;
    } else if (s.empty() || s.back() != '_') {
      s += '_';
    }
  }
  while (!s.empty() && (s.back() == '_' || s.back() == '.')) s.pop_back();
  while (!s.empty() && s.front() == '.') s.erase(s.begin());
  return s.empty() ? "run" : s;
}

void writeRunSurfaces(const fs::path& outDir, const Scene& scene, const Organ& organ,
                      std::vector<RunRecord>& runs) {
  // The rest surface beside the runs' surfaces: the viewer of `deformbench report` draws the
  // series as offsets from it.
  if (scene.surfaces != SurfaceOutput::None && organ.surface.V.rows() > 0) {
    std::error_code ec;
    fs::create_directories(outDir, ec);
    writeObj((outDir / kRestSurfaceFile).string(), organ.surface);
  }
  std::set<std::string> used;
  for (RunRecord& run : runs) {
    run.finalSurfaceFile.clear();
    run.seriesFile.clear();
    run.graspForceFile.clear();
    if (run.status == RunStatus::Unsupported) continue;
    std::string folder = sanitizeLabel(run.label);
    if (used.count(folder)) {
      int i = 2;
      while (used.count(folder + "_" + std::to_string(i))) ++i;
      folder += "_" + std::to_string(i);
    }
    used.insert(folder);
    const fs::path dir = outDir / folder;
    const bool ok = run.status == RunStatus::Ok;
    const bool wantFinal = ok && scene.surfaces != SurfaceOutput::None;
    const bool wantSeries = !run.series.empty();
    const bool wantForces = !run.graspForces.empty();
    if (!wantFinal && !wantSeries && !wantForces) continue;
    std::error_code ec;
    fs::create_directories(dir, ec);
    if (ec) throw InputError(dir.string(), "", "cannot create the folder: " + ec.message());

    if (wantFinal && run.finalSurface.rows() > 0) {
      SurfaceMesh mesh{run.finalSurface, run.finalFaces};
      writeObj((dir / "final.obj").string(), mesh);
      run.finalSurfaceFile = folder + "/final.obj";
    }
    if (wantSeries) {
      std::vector<std::pair<Real, std::string>> series;
      for (const SurfaceSnapshot& s : run.series) {
        if (!s.positions.allFinite()) break;
        char name[64];
        std::snprintf(name, sizeof(name), "surface_%06d.vtp", s.step);
        SurfaceMesh mesh{s.positions, organ.surface.F};
        if (s.positions.rows() != organ.surface.V.rows()) mesh.F = run.finalFaces;
        VecX disp(s.positions.rows());
        for (Eigen::Index i = 0; i < s.positions.rows(); ++i) {
          disp[i] = i < organ.surface.V.rows()
                        ? (s.positions.row(i) - organ.surface.V.row(i)).norm()
                        : 0.0;
        }
        writeVtp((dir / name).string(), mesh, {{"displacement", disp}});
        series.emplace_back(s.time, name);
      }
      writePvd((dir / "surfaces.pvd").string(), series);
      run.seriesFile = folder + "/surfaces.pvd";
    }
    if (wantForces) {
      std::ostringstream csv;
      csv.precision(17);
      csv << "step,time_s,tool,fx_N,fy_N,fz_N\n";
      for (const GraspForceSample& g : run.graspForces) {
        csv << g.step << ',' << g.step * scene.dt << ',' << g.tool << ',' << g.force.x() << ','
            << g.force.y() << ',' << g.force.z() << '\n';
      }
      writeFileAtomic(dir / "grasp_forces.csv", csv.str());
      run.graspForceFile = folder + "/grasp_forces.csv";
    }
  }
}

namespace {

/// "cache" of a run: its cache events counted by what happened.
json cacheJson(const std::vector<Cache::Event>& events) {
  json c = {{"hits", 0}, {"misses", 0}, {"stored", 0}, {"corrupt", 0}};
  for (const auto& e : events) {
    switch (e.what) {
      case Cache::EventKind::Hit:
        c["hits"] = c["hits"].get<int>() + 1;
        break;
      case Cache::EventKind::Miss:
      case Cache::EventKind::Disabled:
        c["misses"] = c["misses"].get<int>() + 1;
        break;
      case Cache::EventKind::Stored:
        c["stored"] = c["stored"].get<int>() + 1;
        break;
      case Cache::EventKind::Corrupt:
        c["corrupt"] = c["corrupt"].get<int>() + 1;
        break;
      case Cache::EventKind::StoreFailed:
        c["store_failed"] = c.value("store_failed", 0) + 1;
        break;
    }
  }
  return c;
}

/// "markers" of a run: status, reason, and with bound markers their positions at each compared
/// instant (and their errors where measured).
json markersJson(const RunRecord& run) {
  json m;
  m["status"] = run.markerStatus;
  if (!run.markerReason.empty()) m["reason"] = run.markerReason;
  if (run.markerStatus == "ok") {
    json at = json::array();
    for (const SurfaceSnapshot& s : run.compared) {
      json pts = json::array();
      for (Eigen::Index i = 0; i < s.markers.rows(); ++i)
        pts.push_back({finite(s.markers(i, 0)), finite(s.markers(i, 1)), finite(s.markers(i, 2))});
      json one = {{"t", s.time}, {"positions_m", pts}};
      if (s.markerRms >= 0) {
        one["rms_error_m"] = finite(s.markerRms);
        one["max_error_m"] = finite(s.markerMax);
        one["rms_error_translation_m"] = finite(s.markerRmsTranslation);
      }
      at.push_back(one);
    }
    m["at"] = at;
  }
  return m;
}

/// "hand_forces": the force the hand exerts on each dynamic instrument, per step (the hand feels
/// minus it).
json handForcesJson(const RunRecord& run) {
  json hands = json::array();
  for (size_t i = 0; i < run.instruments.size(); ++i) {
    json t = json::array(), f = json::array(), x = json::array();
    for (const HandForceSample& h : run.handForces) {
      if (h.instrument != static_cast<int>(i)) continue;
      t.push_back(h.step * run.dt);
      f.push_back({finite(h.force.x()), finite(h.force.y()), finite(h.force.z())});
      x.push_back({finite(h.position.x()), finite(h.position.y()), finite(h.position.z())});
    }
    hands.push_back({{"instrument", run.instruments[i]},
                     {"unit", "N"},
                     {"t_s", t},
                     {"force_N", f},
                     {"position_m", x}});
  }
  return hands;
}

}  // namespace

json runJson(const RunRecord& run) {
  json j;
  j["model"] = run.model;
  j["plugin"] = run.plugin;
  j["label"] = run.label;
  j["role"] = run.isReference ? "reference" : "model";
  j["params"] = json::parse(run.params.dump());
  j["status"] = statusName(run.status);
  j["message"] = run.message;
  if (!run.notes.empty()) j["notes"] = run.notes;
  if (!run.calibration.empty()) j["calibration"] = run.calibration;
  j["counts"] = json::object();
  for (const auto& [k, v] : run.counts) j["counts"][k] = v;
  j["precompute_s"] = run.precomputeS;
  j["steps"] = run.steps;
  j["planned_steps"] = run.plannedSteps;
  if (run.solvedSteps >= 0) j["solved_steps"] = run.solvedSteps;
  if (run.stepStats.samples > 0) {
    j["step_ms"] = {{"median", run.stepStats.median},
                    {"p95", run.stepStats.p95},
                    {"max", run.stepStats.max},
                    {"mean", run.stepStats.mean},
                    {"samples", run.stepStats.samples}};
  } else {
    j["step_ms"] = nullptr;
  }
  if (!run.phaseMs.empty()) {
    j["phase_ms"] = json::object();
    for (const auto& [k, v] : run.phaseMs) j["phase_ms"][k] = v;
  }
  j["numeric"] = json::object();
  for (const auto& [k, v] : run.numeric) j["numeric"][k] = v;
  j["fixed_nodes"] = run.fixedNodes;
  if (!run.cacheEvents.empty()) j["cache"] = cacheJson(run.cacheEvents);
  if (run.error) {
    const ErrorMetrics& e = *run.error;
    json err;
    err["reference"] = run.referenceModel;
    for (const auto& [k, v] : e.rmseNearest) err["rmse_" + std::to_string(k)] = finite(v);
    for (const auto& [k, v] : e.referenceNearest)
      err["reference_displacement_" + std::to_string(k)] = finite(v);
    // Which vertices rmse_k covers (docs/writing-a-plugin.md, "Metrics").
    err["rmse_k_samples"] = e.nearestSamples;
    if (e.excludedGrasped > 0) err["rmse_k_excluded_grasped"] = e.excludedGrasped;
    err["rmse_all"] = finite(e.rmseAll);
    err["max"] = finite(e.max);
    err["loss_ratio"] = finite(e.lossRatio);
    err["instants"] = e.instants;
    j["error"] = err;
  }
  if (!run.compared.empty()) {
    json at = json::array();
    for (const auto& s : run.compared) at.push_back(s.time);
    j["compared_at"] = at;
  }
  // Plates: the force the tissue exerts on each, at the last compared instant and at each.
  const auto plateForces = [&](const SurfaceSnapshot& s) {
    json forces = json::array();
    for (const Vec3& f : s.plateForces)
      forces.push_back({finite(f.x()), finite(f.y()), finite(f.z())});
    return forces;
  };
  if (!run.compared.empty() && !run.compared.back().plateForces.empty()) {
    j["plate_force_N"] = plateForces(run.compared.back());
    json at = json::array();
    for (const SurfaceSnapshot& s : run.compared)
      if (!s.plateForces.empty()) at.push_back({{"t", s.time}, {"plate_force_N", plateForces(s)}});
    j["plate_force_at"] = at;
  }
  if (!run.markerStatus.empty()) j["markers"] = markersJson(run);
  if (!run.emptyGrasps.empty()) j["empty_grasps"] = run.emptyGrasps;
  if (run.graspResidual >= 0) j["grasp_residual_m"] = finite(run.graspResidual);
  if (run.settledAt) {
    j["settled_at_s"] = *run.settledAt;
  } else if (run.equilibrium) {
    j["settled_at_s"] = nullptr;
  }
  // A run that did not end ok is never valid, whoever made its record.
  const bool valid = run.valid && run.status == RunStatus::Ok;
  j["valid"] = valid;
  if (!valid)
    j["invalid_reason"] = run.invalidReason.empty() ? notRunReason(run) : run.invalidReason;
  if (run.referenceValid) {
    j["reference_valid"] = *run.referenceValid;
    if (!*run.referenceValid) j["reference_invalid_reason"] = run.referenceInvalidReason;
  }
  if (!run.finalSurfaceFile.empty()) j["final_surface"] = run.finalSurfaceFile;
  if (!run.seriesFile.empty()) j["surface_series"] = run.seriesFile;
  if (!run.graspForceFile.empty()) j["grasp_forces"] = run.graspForceFile;
  if (!run.worlds.empty()) j["worlds"] = run.worlds;
  if (run.contactPairs >= 0)
    j["contact"] = {{"pairs_tested", run.contactPairs}, {"contacts", run.contacts}};
  if (!run.instruments.empty()) j["hand_forces"] = handForcesJson(run);
  if (!run.objectsFinal.empty()) {
    json o = json::array();
    for (const Vec3& p : run.objectsFinal) o.push_back({p.x(), p.y(), p.z()});
    j["objects_final_m"] = o;
  }
  return j;
}

json interactionJson(const Scene& scene, const Organ& organ) {
  const auto vec = [](const Vec3& v) { return json::array({v.x(), v.y(), v.z()}); };
  json j;
  json boxes = json::array();
  for (const Box& b : organ.fixed.boxes) boxes.push_back({vec(b.lo), vec(b.hi)});
  j["fixed"] = {{"boxes", boxes}, {"surface_vertices", organ.fixed.surfaceVertices}};
  if (!organ.fixed.rollers.empty()) {
    json rollers = json::array();
    for (const RollerBox& r : organ.fixed.rollers) {
      std::string axes;
      for (int k = 0; k < 3; ++k)
        if (r.axes & (1 << k)) axes += char('x' + k);
      rollers.push_back({{"box", {vec(r.box.lo), vec(r.box.hi)}}, {"axes", axes}});
    }
    j["fixed"]["rollers"] = rollers;
  }
  json tools = json::array();
  for (const ToolSpec& t : scene.tools) {
    json path = json::array();
    for (const KeyFrame& k : t.trajectory)
      path.push_back({{"t", k.t}, {"pos", vec(k.pos)}, {"jaw", k.jawClosed ? "closed" : "open"}});
    tools.push_back({{"type", t.type == ToolType::Grasper ? "grasper" : "probe"},
                     {"radius", t.radius},
                     {"trajectory", path}});
  }
  j["tools"] = tools;
  json loads = json::array();
  for (const LoadSpec& l : scene.loads) {
    json o = {{"type", l.type == LoadType::PointForce ? "point_force" : "pin_head"},
              {"at", vec(l.at)},
              {"start", l.start},
              {"end", finite(l.end)}};
    if (l.type == LoadType::PointForce) o["force"] = vec(l.force);
    loads.push_back(o);
  }
  j["loads"] = loads;
  return j;
}

json resultsJson(const Scene& scene, const Organ& organ, const std::vector<std::string>& organLog,
                 const std::vector<RunRecord>& runs, const MachineInfo& machine) {
  json doc;
  doc["format"] = "deformbench-results/1";
  doc["scene"] = {{"name", scene.name}, {"file", scene.file},         {"sha256", scene.sha256},
                  {"dt", scene.dt},     {"duration", scene.duration}, {"steps", scene.numSteps()}};
  doc["organ"] = {{"source", organ.source},
                  {"vertices", organ.surface.numVertices()},
                  {"triangles", organ.surface.numFaces()},
                  {"log", organLog}};
  if (scene.surfaces != SurfaceOutput::None) doc["organ"]["rest_surface"] = kRestSurfaceFile;
  doc["interaction"] = interactionJson(scene, organ);
  doc["machine"] = {{"cpu", machine.cpu},
                    {"vector_units", machine.vectorUnits},
                    {"blas", machine.blas},
                    {"compiler", machine.compiler},
                    {"build_type", machine.buildType},
                    {"git", machine.git},
                    {"timestamp", machine.timestamp},
                    {"deformbench", machine.version}};
  doc["runs"] = json::array();
  for (const RunRecord& r : runs) doc["runs"].push_back(runJson(r));
  return doc;
}

fs::path writeResults(const fs::path& outDir, const json& doc) {
  const fs::path path = outDir / "results.json";
  writeFileAtomic(path, doc.dump(2) + "\n");
  return path;
}

}  // namespace deform::harness
