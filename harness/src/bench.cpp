// CI timing tables (see bench.h).
#include <deform/geometry/phantom.h>
#include <deform/internal/atomic_file.h>
#include <deform/sdk/cache.h>
#include <deform/sdk/mesh.h>
#include <deform_harness/bench.h>
#include <deform_harness/format.h>
#include <deform_harness/json_file.h>
#include <deform_harness/results.h>

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <map>
#include <ostream>
#include <set>
#include <sstream>

namespace deform::harness {

namespace fs = std::filesystem;
using ojson = nlohmann::ordered_json;
using json = nlohmann::json;

namespace {

struct BenchCase {
  std::string id, plugin;
  ojson params;
  std::string scene;  ///< "liver_grasp" | "cube_poke" | "liver8k_grasp"
};

/// A parameter set as scene JSON.
ojson paramsJson(const ModelInfo::ParamSet& set) {
  ojson j = ojson::object();
  for (const auto& [k, v] : set) j[k] = std::visit([](const auto& x) { return ojson(x); }, v);
  return j;
}

/// The fixed case set: every plugin found that declares bench presets (ModelInfo::presets), on a
/// grasp-and-lift of the ~2.2k-vertex liver and a poke of the cube at its "bench" parameters,
/// and on the default scene's organ (scenes/liver_grasp_lift.json, the 8,122-vertex liver
/// phantom) at its "bench_8k" ones. A case's id is the plugin, its parameters (a true flag by
/// its name, other values by their value) and the scene: "pbd_bending/liver8k_grasp".
std::vector<BenchCase> benchCases(PluginLoader& loader) {
  std::vector<std::pair<std::string, const ModelInfo*>> plugins;
  for (const std::string& name : loader.discover()) {
    try {
      plugins.emplace_back(name, &loader.load(name));
    } catch (const std::exception&) {
      // a plugin that does not load has no presets to run
    }
  }
  const auto presets = [](const ModelInfo& info, const char* name) {
    const auto it = info.presets.find(name);
    return it == info.presets.end() ? std::vector<ModelInfo::ParamSet>{} : it->second;
  };
  std::vector<BenchCase> out;
  for (const char* scene : {"liver_grasp", "cube_poke"})
    for (const auto& [plugin, info] : plugins)
      for (const ModelInfo::ParamSet& set : presets(*info, "bench"))
        out.push_back({plugin + "/" + scene, plugin, paramsJson(set), scene});
  for (const auto& [plugin, info] : plugins)
    for (const ModelInfo::ParamSet& set : presets(*info, "bench_8k")) {
      const ojson params = paramsJson(set);
      std::string id = plugin;
      for (const auto& [k, v] : params.items())
        id += "_" + (v.is_boolean() ? k : v.is_string() ? v.get<std::string>() : v.dump());
      out.push_back({id + "/liver8k_grasp", plugin, params, "liver8k_grasp"});
    }
  return out;
}

/// The default scene (scenes/liver_grasp_lift.json) with the grasp closed from the first step:
/// the same phantom, material, support and grasper, lifting at the scene's speed (50 mm/s).
ojson defaultLiverScene(const BenchCase& c, int steps) {
  ojson j;
  j["name"] = "bench-" + c.id;
  j["description"] = "Timing case " + c.id + " (deformbench bench): the default scene's organ.";
  j["organ"] = {{"mesh", "phantom:liver"},
                {"material", {{"young", 5500}, {"poisson", 0.3}, {"density", 1000}}},
                {"fixed",
                 {{"boxes",
                   {{{-0.11, -0.08, -0.05}, {0.11, -0.035, 0.05}},
                    {{-0.11, -0.08, -0.05}, {0.11, 0.03, -0.032}}}}}}};
  j["gravity"] = {0, 0, 0};
  j["dt"] = 0.001;
  j["duration"] = steps * 0.001;
  const Vec3 p(-0.0235, 0.0744, -0.0232);
  j["tools"] = ojson::array(
      {{{"type", "grasper"},
        {"radius", 0.008},
        {"trajectory",
         {{{"t", 0.0}, {"pos", vecJson(p)}, {"jaw", "closed"}},
          {{"t", steps * 0.001}, {"pos", vecJson(p + Vec3(0, 0, 0.05 * steps * 0.001))}}}}}});
  j["models"] = ojson::array({{{"plugin", c.plugin}, {"label", c.plugin}, {"params", c.params}}});
  j["output"] = {{"surfaces", "none"}};
  return j;
}

ojson benchScene(const BenchCase& c, int steps) {
  if (c.scene == "liver8k_grasp") return defaultLiverScene(c, steps);
  ojson j;
  j["name"] = "bench-" + c.id;
  const bool liver = c.scene == "liver_grasp";
  const std::string phantom = liver ? "liver" : "cube";
  const double resolution = liver ? 0.27 : 0.6;
  const SurfaceMesh s = makePhantom(phantom, resolution);
  const Box b = boundingBox(s.V);
  const Vec3 m = Vec3::Constant(0.05 * b.diagonal());
  const Vec3 top =
      s.V.row(nearestVertex(s.V, Vec3(b.center().x(), b.center().y(), b.hi.z()))).transpose();
  j["description"] = "Timing case " + c.id + " (deformbench bench).";
  j["organ"] = {{"mesh", "phantom:" + phantom},
                {"resolution", resolution},
                {"material", {{"young", 5500}, {"poisson", 0.3}, {"density", 1000}}},
                {"fixed",
                 {{"box",
                   {vecJson(b.lo - m), vecJson(Vec3(b.hi.x() + m.x(), b.hi.y() + m.y(),
                                                    b.lo.z() + 0.15 * b.size().z()))}}}}};
  j["gravity"] = {0, 0, -9.81};
  j["dt"] = 0.001;
  j["duration"] = steps * 0.001;
  if (liver) {
    const Vec3 p = top - Vec3(0, 0, 0.2 * b.size().z());
    j["tools"] =
        ojson::array({{{"type", "grasper"},
                       {"radius", 0.25 * b.size().z()},
                       {"trajectory",
                        {{{"t", 0.0}, {"pos", vecJson(p)}, {"jaw", "closed"}},
                         {{"t", steps * 0.001}, {"pos", vecJson(p + Vec3(0, 0, 0.01))}}}}}});
  } else {
    j["loads"] = ojson::array(
        {{{"type", "point_force"}, {"at", vecJson(top)}, {"force", {0, 0, -1.0}}, {"start", 0.0}}});
  }
  j["models"] = ojson::array({{{"plugin", c.plugin}, {"label", c.plugin}, {"params", c.params}}});
  j["output"] = {{"surfaces", "none"}};
  return j;
}

/// The one-, five- and fifteen-minute load averages (empty where unavailable).
ojson loadAverage() {
  double l[3];
  if (::getloadavg(l, 3) != 3) return ojson::array();
  return ojson::array({l[0], l[1], l[2]});
}

double number(const json& c, const char* k) {
  return c.contains(k) && c[k].is_number() ? c[k].get<double>() : NAN;
}

/// The PBD case of a case's scene in the same file ("pbd/<scene>"), or null.
const json* pbdCase(const json& cases, const std::string& id) {
  const size_t slash = id.rfind('/');
  if (slash == std::string::npos) return nullptr;
  const std::string pbd = "pbd" + id.substr(slash);
  if (pbd == id) return nullptr;
  for (const json& c : cases)
    if (c.value("id", "") == pbd) return &c;
  return nullptr;
}

/// A case's time over PBD's on its scene in the same file; NaN when either is missing.
double xPbd(const json& doc, const json& c) {
  const json* p = pbdCase(doc["cases"], c.value("id", ""));
  if (!p) return NAN;
  const double a = number(c, "ms_median"), b = number(*p, "ms_median");
  return std::isfinite(a) && std::isfinite(b) && b > 0 ? a / b : NAN;
}

/// The relative spread (max - min) / median of a case, 0 when unknown.
double relativeSpread(const json& c) {
  const double med = number(c, "ms_median"), lo = number(c, "ms_min"), hi = number(c, "ms_max");
  return std::isfinite(med) && med > 0 && std::isfinite(lo) && std::isfinite(hi) ? (hi - lo) / med
                                                                                 : 0.0;
}

/// Whether absolute times of two bench files may be compared, and if not, why.
bool sameIdleMachine(const json& a, const json& b, std::string& why) {
  const auto machineOf = [](const json& d) {
    return d.contains("machine") ? d["machine"] : json::object();
  };
  const json ma = machineOf(a), mb = machineOf(b);
  if (!ma.contains("load_average") || !mb.contains("load_average") || !ma.contains("cores") ||
      !mb.contains("cores")) {
    why = "a file does not record its machine's cores and load";
    return false;
  }
  // One model name ("AMD EPYC") covers CPUs with and without AVX-512: an older file without
  // vector_units matches nothing.
  const auto cpu = [](const json& m) {
    return m.value("cpu", "?") + " " + m.value("vector_units", "(vector units unknown)");
  };
  if (!ma.contains("vector_units") || !mb.contains("vector_units") || cpu(ma) != cpu(mb) ||
      ma["cores"] != mb["cores"]) {
    why = "other machines (" + cpu(ma) + ", " + ma["cores"].dump() + " cores; " + cpu(mb) + ", " +
          mb["cores"].dump() + " cores)";
    return false;
  }
  // OpenBLAS's kernels (which the environment can choose) move the step times of the models that
  // solve with CHOLMOD or dense BLAS; a file from before `blas` was recorded is not refused.
  const std::string blasA = ma.value("blas", ""), blasB = mb.value("blas", "");
  if (!blasA.empty() && !blasB.empty() && blasA != blasB) {
    why = "other OpenBLAS kernels (" + blasA + "; " + blasB + ")";
    return false;
  }
  const double cores = ma["cores"].get<double>();
  for (const json* d : {&ma, &mb}) {
    const json& l = (*d)["load_average"];
    if (!l.is_array() || l.empty() || !l[0].is_number() || l[0].get<double>() > 0.5 * cores) {
      std::ostringstream w;
      w << "a run on a busy machine (load average " << (l.is_array() && !l.empty() ? l[0] : l)
        << " on " << cores << " cores)";
      why = w.str();
      return false;
    }
  }
  return true;
}

double medianOf(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

}  // namespace

ojson runBench(PluginLoader& loader, const BenchOptions& options, Progress* progress) {
  std::vector<BenchCase> cases;
  for (const BenchCase& c : benchCases(loader)) {
    if (!options.only.empty() &&
        std::find(options.only.begin(), options.only.end(), c.id) == options.only.end() &&
        std::find(options.only.begin(), options.only.end(), c.plugin) == options.only.end())
      continue;
    cases.push_back(c);
  }
  if (progress) progress->addTotal(int(cases.size()));
  // The generated scenes and their results are scratch: only the timings are kept.
  const fs::path work =
      fs::temp_directory_path() / ("deformbench_bench_" + std::to_string(::getpid()));
  const MachineInfo machine = machineInfo();
  ojson doc;
  doc["format"] = "deformbench-bench/1";
  doc["machine"] = {{"cpu", machine.cpu},
                    {"vector_units", machine.vectorUnits},
                    {"cores", long(::sysconf(_SC_NPROCESSORS_ONLN))},
                    {"load_average", loadAverage()},
                    {"compiler", machine.compiler},
                    {"build_type", machine.buildType},
                    {"git", machine.git},
                    {"timestamp", machine.timestamp}};
  doc["repeat"] = options.repeat;
  doc["steps"] = options.steps;
  doc["cases"] = ojson::array();
  for (const BenchCase& c : cases) {
    if (progress) progress->start(c.id);
    ojson entry = {{"id", c.id}, {"plugin", c.plugin}, {"params", c.params}};
    std::vector<double> reps;
    std::string status = "ok", message;
    for (int r = 0; r < std::max(1, options.repeat); ++r) {
      const CaseResult res =
          runSceneCase(benchScene(c, options.steps), work / "scenes" / (c.id + ".json"),
                       work / "runs" / c.id, loader, options.cases);
      if (res.missing.count(c.plugin)) {
        status = "missing";
        message = res.missing.at(c.plugin);
        break;
      }
      const RunRecord* run = res.run(c.plugin);
      if (!run || run->status != RunStatus::Ok || run->stepStats.samples == 0) {
        status = run ? statusName(run->status) : "not run";
        message = run ? run->message : res.error;
        break;
      }
      reps.push_back(run->stepStats.median);
    }
    entry["status"] = status;
    if (!message.empty()) entry["message"] = message;
    if (!reps.empty()) {
      entry["ms_median"] = medianOf(reps);
      entry["ms_min"] = *std::min_element(reps.begin(), reps.end());
      entry["ms_max"] = *std::max_element(reps.begin(), reps.end());
      entry["ms_repeats"] = reps;
    } else {
      entry["ms_median"] = nullptr;
    }
    if (progress) {
      std::ostringstream s;
      s << status;
      if (!reps.empty()) s << " " << std::setprecision(3) << medianOf(reps) << " ms";
      progress->finish(c.id, s.str());
    }
    doc["cases"].push_back(entry);
  }
  doc["machine"]["load_average_end"] = loadAverage();
  doc["machine"]["blas"] = loadedBlasKernels();  // the cases have loaded their plugins by now
  // Each case's ratio to PBD on its scene, in this run: what CI compares across machines.
  const json plain = json::parse(doc.dump());
  for (size_t i = 0; i < doc["cases"].size(); ++i) {
    const double x = xPbd(plain, plain["cases"][i]);
    doc["cases"][i]["x_pbd"] = std::isfinite(x) ? ojson(x) : ojson(nullptr);
  }
  std::error_code ec;
  fs::remove_all(work, ec);
  writeFileAtomic(options.out, doc.dump(2) + "\n");
  return doc;
}

json readBenchFile(const std::string& path) {
  json j = readJsonFile<json>(path, "bench file");
  if (!j.is_object() || j.value("format", "") != "deformbench-bench/1" || !j.contains("cases") ||
      !j["cases"].is_array())
    throw InputError(path, "/format", "not a deformbench-bench/1 file");
  for (size_t i = 0; i < j["cases"].size(); ++i) {
    const json& c = j["cases"][i];
    if (!c.is_object() || !c.contains("id") || !c["id"].is_string())
      throw InputError(path, "/cases/" + std::to_string(i), "a case needs a string \"id\"");
    for (const char* k : {"ms_median", "ms_min", "ms_max"})
      if (c.contains(k) && !c[k].is_null() && !c[k].is_number())
        throw InputError(path, "/cases/" + std::to_string(i) + "/" + k, "must be a number");
  }
  return j;
}

BenchComparison compareBench(const json& oldDoc, const json& newDoc, double threshold) {
  BenchComparison out;
  out.absolute = sameIdleMachine(oldDoc, newDoc, out.absoluteWhy);
  std::map<std::string, json> olds;
  for (const json& c : oldDoc["cases"]) olds[c["id"].get<std::string>()] = c;
  std::set<std::string> seen;
  // Slower or faster than the threshold and beyond the noise (relative, for ratios).
  const auto judge = [&](double ratio, double noise) {
    if (ratio > 1 + threshold && ratio - 1 > noise) return "SLOWER";
    if (ratio < 1 / (1 + threshold) && 1 - ratio > noise) return "faster";
    return "ok";
  };
  for (const json& c : newDoc["cases"]) {
    BenchComparison::Row row;
    row.id = c["id"];
    seen.insert(row.id);
    row.newMs = number(c, "ms_median");
    if (!olds.count(row.id)) {
      row.verdict = "new";
      out.rows.push_back(row);
      continue;
    }
    const json& o = olds.at(row.id);
    row.oldMs = number(o, "ms_median");
    if (!std::isfinite(row.oldMs) || !std::isfinite(row.newMs) || row.oldMs <= 0) {
      row.verdict = "not timed";
      out.rows.push_back(row);
      continue;
    }
    row.ratio = row.newMs / row.oldMs;
    row.noiseMs = std::max(relativeSpread(o) * row.oldMs, relativeSpread(c) * row.newMs);
    row.oldXPbd = xPbd(oldDoc, o);
    row.newXPbd = xPbd(newDoc, c);
    if (std::isfinite(row.oldXPbd) && std::isfinite(row.newXPbd) && row.oldXPbd > 0) {
      row.xRatio = row.newXPbd / row.oldXPbd;
      const json* po = pbdCase(oldDoc["cases"], row.id);
      const json* pn = pbdCase(newDoc["cases"], row.id);
      const double noise = std::max(relativeSpread(o), relativeSpread(c)) +
                           std::max(relativeSpread(*po), relativeSpread(*pn));
      row.verdict = judge(row.xRatio, noise);
    } else if (out.absolute) {
      row.verdict = judge(row.ratio, row.noiseMs / row.oldMs);
    } else {
      row.verdict = "not compared";
    }
    // Another configuration under the same id (a preset changed): its figures are shown but
    // not judged.
    if (o.value("params", json::object()) != c.value("params", json::object()))
      row.verdict = "params changed";
    if (row.verdict == std::string("SLOWER")) ++out.regressions;
    out.rows.push_back(row);
  }
  for (const auto& [id, o] : olds) {
    if (seen.count(id)) continue;
    BenchComparison::Row row;
    row.id = id;
    row.oldMs = number(o, "ms_median");
    row.verdict = "missing";
    out.rows.push_back(row);
  }
  return out;
}

void printBenchComparison(const BenchComparison& c, double threshold, std::ostream& out) {
  const auto f = [](double v, int p = 4) {
    if (!std::isfinite(v)) return std::string("-");
    std::ostringstream s;
    s << std::setprecision(p) << v;
    return s.str();
  };
  size_t w = 4;
  for (const auto& r : c.rows) w = std::max(w, r.id.size());
  out << (c.absolute ? "absolute times compared (same CPU and cores, both runs idle)"
                     : "absolute times not compared: " + c.absoluteWhy)
      << "; each case is judged by its time over PBD's on the same scene in the same run (x PBD)"
      << "\n";
  out << std::left << std::setw(int(w)) << "case"
      << "  " << std::setw(10) << "old ms" << std::setw(10) << "new ms" << std::setw(8) << "ratio"
      << std::setw(10) << "old xPBD" << std::setw(10) << "new xPBD" << std::setw(9) << "change"
      << std::setw(10) << "noise ms"
      << "verdict\n";
  for (const auto& r : c.rows) {
    out << std::left << std::setw(int(w)) << r.id << "  " << std::setw(10) << f(r.oldMs)
        << std::setw(10) << f(r.newMs) << std::setw(8) << f(r.ratio, 3) << std::setw(10)
        << f(r.oldXPbd, 3) << std::setw(10) << f(r.newXPbd, 3) << std::setw(9) << f(r.xRatio, 3)
        << std::setw(10) << f(r.noiseMs, 3) << r.verdict << "\n";
  }
  out << c.regressions << " case(s) slower by more than " << f(100 * threshold, 3)
      << "% and the noise (relative to PBD"
      << (c.absolute ? "; PBD itself and cases without it: absolute" : "") << ")\n";
}

}  // namespace deform::harness
