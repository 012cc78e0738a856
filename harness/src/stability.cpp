// The stiff and extreme sweep, one child process per case (see stability.h).
#include <deform/cache.h>
#include <deform/mesh.h>
#include <deform/phantom.h>
#include <deform_harness/child_process.h>
#include <deform_harness/dispatch.h>
#include <deform_harness/stability.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

namespace deform::harness {

namespace fs = std::filesystem;
using ojson = nlohmann::ordered_json;

namespace {

std::string g(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

ojson vec(const Vec3& v) {
  return ojson::array({v.x(), v.y(), v.z()});
}

/// Parameters the sweep gives a plugin instead of its defaults (data): the reference FEM at a
/// modest element count, and smaller precomputations with --quick so a case stays in seconds.
ojson stabilityParams(const std::string& plugin, bool quick) {
  if (plugin == "reference_fem") return {{"elements", quick ? 1500 : 5000}};
  if (!quick) return ojson::object();
  if (plugin == "particle_bem") return {{"coarse_vertices", 200}, {"points", 150}};
  if (plugin == "metaballs") return {{"spheres", 150}};
  if (plugin == "fem_hex") return {{"elements", 300}};
  return ojson::object();
}

}  // namespace

std::vector<StabilityCase> stabilityCases(bool quick) {
  std::vector<StabilityCase> cases;
  const std::vector<double> youngs =
      quick ? std::vector<double>{1e3, 1e5, 1e7} : std::vector<double>{1e3, 1e4, 1e5, 1e6, 1e7};
  const std::vector<double> dts =
      quick ? std::vector<double>{1e-3, 1.0 / 30} : std::vector<double>{1e-3, 1e-2, 1.0 / 30};
  for (double e : youngs) {
    for (double dt : dts) {
      StabilityCase c;
      c.id = "E" + g(e) + "_dt" + g(std::round(dt * 1e4) / 1e4);
      c.group = "stiffness_dt";
      c.young = e;
      c.dt = dt;
      c.force = 1.0;
      c.description = "E = " + g(e) + " Pa, dt = " + g(dt) + " s, 1 N down at the top, gravity";
      cases.push_back(c);
    }
  }
  for (double nu : quick ? std::vector<double>{0.499} : std::vector<double>{0.45, 0.49, 0.499}) {
    StabilityCase c;
    c.id = "nu" + g(nu);
    c.group = "poisson";
    c.young = 1e4;
    c.poisson = nu;
    c.force = 1.0;
    c.description = "nu = " + g(nu) + ", E = 10 kPa, 1 N down at the top, gravity";
    cases.push_back(c);
  }
  for (double f : quick ? std::vector<double>{200} : std::vector<double>{20, 200}) {
    StabilityCase c;
    c.id = "force" + g(f) + "N";
    c.group = "force";
    c.force = f;
    c.description = g(f) + " N down at the top (E = 5.5 kPa), gravity";
    cases.push_back(c);
  }
  std::vector<std::pair<std::string, std::string>> extremes = {
      {"pull", "a grasp at the top pulled three organ-lengths up"},
      {"invert",
       "a grasp at the top pushed down through the organ to half a height below its base "
       "(inverts the region)"}};
  if (!quick)
    extremes.push_back({"flatten", "a probe pressing the top down to a tenth of the height"});
  for (const auto& [id, what] : extremes) {
    StabilityCase c;
    c.id = id;
    c.group = id;
    c.extra = id;
    c.description = what + std::string(" (E = 5.5 kPa), gravity");
    cases.push_back(c);
  }
  return cases;
}

ojson stabilityScene(const StabilityCase& c, const std::string& plugin, const ojson& params,
                     bool quick) {
  const double resolution = quick ? 0.4 : 0.7;
  const SurfaceMesh s = makePhantom("cube", resolution);
  const Box b = boundingBox(s.V);
  const double size = b.size().maxCoeff();
  const double duration = quick ? 0.2 : 0.5;
  const Vec3 top =
      s.V.row(nearestVertex(s.V, Vec3(b.center().x(), b.center().y(), b.hi.z()))).transpose();
  const Vec3 m = Vec3::Constant(0.05 * b.diagonal());
  ojson j;
  j["name"] = "stability-" + c.id;
  j["description"] = "Stability case " + c.id + ": " + c.description + "; cube phantom (" +
                     g(size) + " m), bottom tenth fixed.";
  j["organ"] = {{"mesh", "phantom:cube"},
                {"resolution", resolution},
                {"material", {{"young", c.young}, {"poisson", c.poisson}, {"density", 1000}}},
                {"fixed",
                 {{"box",
                   {vec(b.lo - m), vec(Vec3(b.hi.x() + m.x(), b.hi.y() + m.y(),
                                            b.lo.z() + 0.1 * b.size().z()))}}}}};
  j["gravity"] = {0, 0, -9.81};
  j["dt"] = c.dt;
  j["duration"] = std::max(duration, 3 * c.dt);
  if (c.force > 0) {
    j["loads"] = ojson::array({{{"type", "point_force"},
                                {"at", vec(top)},
                                {"force", {0, 0, -c.force}},
                                {"start", 0.0},
                                {"end", 1e3}}});
  }
  const double radius = 0.2 * size;
  const Vec3 grip = top - Vec3(0, 0, 0.1 * size);
  if (c.extra == "pull" || c.extra == "invert") {
    const Vec3 to = c.extra == "pull" ? Vec3(grip + Vec3(0, 0, 3 * size))
                                      : Vec3(grip.x(), grip.y(), b.lo.z() - 0.5 * b.size().z());
    j["tools"] = ojson::array({{{"type", "grasper"},
                                {"radius", radius},
                                {"trajectory",
                                 {{{"t", 0.0}, {"pos", vec(grip)}, {"jaw", "closed"}},
                                  {{"t", 0.8 * duration}, {"pos", vec(to)}}}}}});
  } else if (c.extra == "flatten") {
    const double r = 0.6 * size;
    const Vec3 start(b.center().x(), b.center().y(), b.hi.z() + r);
    const Vec3 end(b.center().x(), b.center().y(), b.lo.z() + 0.1 * b.size().z() + r);
    j["tools"] = ojson::array(
        {{{"type", "probe"},
          {"radius", r},
          {"trajectory",
           {{{"t", 0.0}, {"pos", vec(start)}}, {{"t", 0.8 * duration}, {"pos", vec(end)}}}}}});
  }
  j["models"] = ojson::array({{{"plugin", plugin}, {"label", plugin}, {"params", params}}});
  j["samples"] = {{"nearest", {10}}};
  j["output"] = {{"surfaces", "final"}};
  return j;
}

StabilityRecord classifyStabilityRun(int waitStatus, bool timedOut, double timeoutS,
                                     const fs::path& resultsJson, const std::string& stderrTail) {
  StabilityRecord r;
  ChildOutcome outcome;
  outcome.waitStatus = waitStatus;
  outcome.timedOut = timedOut;
  std::string failure = childFailure(outcome, timeoutS, stderrTail);
  if (failure.empty() && !fs::exists(resultsJson))
    failure = "exit code 0" + (stderrTail.empty() ? "" : ": " + stderrTail);
  if (!failure.empty()) {
    r.status = "failed";
    r.message = failure;
    return r;
  }
  try {
    std::ifstream in(resultsJson);
    const ojson doc = ojson::parse(in);
    const ojson& run = doc.at("runs").at(0);
    const std::string status = run.at("status");
    r.message = run.value("message", "");
    if (status == "ok") {
      r.status = "stable";
    } else if (status == "diverged") {
      r.status = "diverged";
      r.step = run.value("steps", -1);
    } else if (status == "unsupported") {
      r.status = "unsupported";
    } else {
      r.status = "failed";
    }
  } catch (const std::exception& e) {
    r.status = "failed";
    r.message = std::string("unreadable results.json: ") + e.what();
  }
  return r;
}

namespace {

ojson recordJson(const StabilityRecord& r) {
  return {{"model", r.model},
          {"case", r.caseId},
          {"group", r.group},
          {"status", r.status},
          {"step", r.step < 0 ? ojson(nullptr) : ojson(r.step)},
          {"message", r.message},
          {"wall_s", r.wallS}};
}

}  // namespace

std::vector<StabilityRecord> runStability(PluginLoader& loader, const StabilityOptions& options,
                                          Progress* progress) {
  std::vector<std::string> models = options.models;
  if (models.empty()) models = loader.discover();
  std::vector<StabilityCase> cases = stabilityCases(options.quick);
  if (!options.cases.empty()) {
    std::vector<StabilityCase> kept;
    for (const auto& c : cases)
      if (std::find(options.cases.begin(), options.cases.end(), c.id) != options.cases.end())
        kept.push_back(c);
    for (const auto& want : options.cases) {
      if (std::none_of(cases.begin(), cases.end(),
                       [&](const StabilityCase& c) { return c.id == want; })) {
        std::string known;
        for (const auto& c : cases) known += (known.empty() ? "" : ", ") + c.id;
        throw InputError("--case", want, "unknown stability case (known: " + known + ")");
      }
    }
    cases = kept;
  }
  const double timeout = options.timeoutS > 0 ? options.timeoutS : (options.quick ? 60.0 : 120.0);
  const std::string exe = options.executable.empty() ? selfExecutable() : options.executable;
  fs::create_directories(options.outDir);

  /// A (model, case) to run: its record (status set when there is nothing to run).
  struct Pending {
    StabilityRecord record;
    fs::path dir, caseFile;
    std::string label;
  };
  std::vector<StabilityRecord> records;
  std::vector<Pending> pending;
  for (const std::string& plugin : models) {
    const std::string problem = pluginProblem(loader, plugin);
    for (const StabilityCase& c : cases) {
      const fs::path caseFile = options.outDir / "cases" / plugin / (c.id + ".json");
      if (options.resume && fs::exists(caseFile)) {
        try {
          std::ifstream in(caseFile);
          const ojson j = ojson::parse(in);
          StabilityRecord r;
          r.model = plugin;
          r.caseId = c.id;
          r.group = c.group;
          r.status = j.at("status");
          r.step = j["step"].is_null() ? -1 : j["step"].get<int>();
          r.message = j.value("message", "");
          r.wallS = j.value("wall_s", 0.0);
          r.resumed = true;
          records.push_back(r);
          continue;
        } catch (const std::exception&) {
          // unreadable: run it again
        }
      }
      Pending p;
      p.record.model = plugin;
      p.record.caseId = c.id;
      p.record.group = c.group;
      p.caseFile = caseFile;
      p.dir = options.outDir / "runs" / plugin / c.id;
      p.label = plugin + " " + c.id;
      if (!problem.empty()) {
        p.record.status = "failed";
        p.record.message = "plugin cannot be loaded: " + problem;
      }
      const fs::path sceneFile = options.outDir / "scenes" / plugin / (c.id + ".json");
      fs::create_directories(sceneFile.parent_path());
      writeFileAtomic(
          sceneFile,
          stabilityScene(c, plugin, stabilityParams(plugin, options.quick), options.quick).dump(2) +
              "\n");
      pending.push_back(p);
    }
  }
  if (progress) progress->addTotal(int(pending.size()));

  const auto finishCase = [&](const Pending& p) {
    fs::create_directories(p.caseFile.parent_path());
    writeFileAtomic(p.caseFile, recordJson(p.record).dump(2) + "\n");
    std::string result = p.record.status;
    if (p.record.step >= 0) result += " at step " + std::to_string(p.record.step);
    if (p.record.status == "failed") result += " (" + p.record.message + ")";
    if (progress) progress->finish(p.label, result);
    records.push_back(p.record);
  };

  // Each (model, case) is a "child" task (dispatch.h): here with --jobs, on MPI ranks, or in a
  // Slurm array whose outcome.json files a later --resume reads.
  std::vector<ojson> tasks;
  std::vector<Pending*> jobCase;
  for (Pending& p : pending) {
    if (!p.record.status.empty()) {  // plugin did not load: nothing to run
      finishCase(p);
      continue;
    }
    std::vector<std::string> argv = {exe};
    for (const auto& a : pluginDirArgs(options.pluginDirs)) argv.push_back(a);
    const fs::path scene = options.outDir / "scenes" / p.record.model / (p.record.caseId + ".json");
    argv.insert(argv.end(),
                {"run", fs::absolute(scene).string(), "--out", fs::absolute(p.dir).string()});
    if (!options.cacheDir.empty())
      argv.insert(argv.end(), {"--cache-dir", fs::absolute(options.cacheDir).string()});
    tasks.push_back({{"kind", "child"},
                     {"argv", argv},
                     {"log", fs::absolute(p.dir / "log.txt").string()},
                     {"timeout_s", timeout},
                     {"fresh_dir", fs::absolute(p.dir).string()},
                     {"outcome", fs::absolute(p.dir / "outcome.json").string()},
                     {"resume", options.resume}});
    jobCase.push_back(&p);
  }
  std::unique_ptr<Dispatcher> local;
  Dispatcher* dispatcher = options.dispatcher;
  if (!dispatcher) {
    local = localDispatcher(options.jobs);
    dispatcher = local.get();
  }
  dispatcher->run(
      tasks,
      [&](size_t i) {
        if (progress) progress->start(jobCase[i]->label);
      },
      [&](size_t i, const ojson& o) {
        Pending& p = *jobCase[i];
        StabilityRecord r;
        const std::string spawnError = o.value("spawn_error", "");
        if (!spawnError.empty()) {
          r.status = "failed";
          r.message = spawnError;
        } else {
          r = classifyStabilityRun(o.value("wait_status", 0), o.value("timed_out", false), timeout,
                                   p.dir / "results.json", lastLogLine(p.dir / "log.txt", 300));
        }
        p.record.status = r.status;
        p.record.step = r.step;
        p.record.message = r.message;
        p.record.wallS = o.value("wall_s", 0.0);
        finishCase(p);
      });

  // Records in (model, case) order whatever order the children finished in.
  std::map<std::pair<std::string, std::string>, StabilityRecord> byKey;
  for (const auto& r : records) byKey[{r.model, r.caseId}] = r;
  std::vector<StabilityRecord> ordered;
  for (const auto& plugin : models)
    for (const auto& c : cases)
      if (byKey.count({plugin, c.id})) ordered.push_back(byKey.at({plugin, c.id}));

  Table t;
  t.name = "stability";
  t.title = "every model over stiff, large-step and extreme cases";
  t.notes = {
      "Each case ran in its own process (`deformbench run` on scenes/<model>/<case>.json) "
      "with a " +
          g(timeout) + " s limit; failed = threw, crashed (signal) or timed out.",
      std::string("Organ: the cube phantom, bottom tenth fixed, gravity; ") +
          (options.quick ? "--quick case set." : "full case set.")};
  t.columns = {{"model", "model"},   {"case", "case"},       {"group", "group"},
               {"young", "E Pa"},    {"poisson", "nu"},      {"dt", "dt s"},
               {"force", "force N"}, {"status", "status"},   {"step", "step"},
               {"wall_s", "wall s"}, {"message", "message"}, {"scene", "scene"}};
  std::map<std::string, StabilityCase> caseById;
  for (const auto& c : cases) caseById[c.id] = c;
  int crashes = 0;
  for (const auto& r : ordered) {
    const StabilityCase& c = caseById.at(r.caseId);
    ojson row = recordJson(r);
    row["young"] = c.young;
    row["poisson"] = c.poisson;
    row["dt"] = c.dt;
    row["force"] = c.force;
    row["extra"] = c.extra;
    row["scene"] = "scenes/" + r.model + "/" + r.caseId + ".json";
    if (r.message.rfind("killed by signal", 0) == 0) ++crashes;
    t.rows.push_back(row);
  }
  t.notes.push_back("Crashes (killed by a signal): " + std::to_string(crashes) + ".");
  writeTable(t, options.outDir);
  return ordered;
}

}  // namespace deform::harness
