// Error against run time: sweeping each model over its accuracy knob (see sweep.h).
#include <deform/internal/atomic_file.h>
#include <deform/sdk/cache.h>
#include <deform_harness/json_file.h>
#include <deform_harness/sweep.h>

#include <cmath>
#include <fstream>
#include <map>
#include <optional>
#include <sstream>

namespace deform::harness {

namespace fs = std::filesystem;
using json = nlohmann::json;
using ojson = nlohmann::ordered_json;

SweepKnob sweepKnob(const ModelInfo& info, bool quick) {
  SweepKnob k;
  k.param = info.knob.param;
  for (const ParamValue& v : quick ? info.knob.quickValues : info.knob.values)
    k.values.push_back(std::visit([](const auto& x) { return json(x); }, v));
  return k;
}

void markPareto(std::vector<SweepPoint>& points) {
  const auto usable = [](const SweepPoint& p) {
    return p.status == "ok" && p.valid && std::isfinite(p.msMedian) && std::isfinite(p.rmseNearest);
  };
  for (SweepPoint& p : points) {
    p.pareto = false;
    if (!usable(p)) continue;
    bool dominated = false;
    for (const SweepPoint& q : points) {
      if (&q == &p || !usable(q) || q.calibrated != p.calibrated) continue;
      if (q.msMedian <= p.msMedian && q.rmseNearest <= p.rmseNearest &&
          (q.msMedian < p.msMedian || q.rmseNearest < p.rmseNearest)) {
        dominated = true;
        break;
      }
    }
    p.pareto = !dominated;
  }
}

namespace {

std::string valueText(const json& v) {
  return v.is_string() ? v.get<std::string>() : v.dump();
}

ojson num(double v) {
  return std::isfinite(v) ? ojson(v) : ojson(nullptr);
}

/// A point of the sweep: a model at one value of its knob (at its calibration for "+cal").
struct Planned {
  std::string model, plugin, label, param;
  json value;
  const CalibrationParams* calibration = nullptr;  ///< the "+cal" points'
};

/// The scene's models, each once per value of its knob (and once more per value at its
/// calibration): the scene's new "models" and the planned points, in the same order.
ojson plannedModels(ojson& scene, PluginLoader& loader, const SweepOptions& options,
                    std::vector<Planned>& planned) {
  ojson models = ojson::array();
  const std::string organ = calibrationOrgan(scene.value("organ", ojson::object()));
  for (const auto& m : scene["models"]) {
    const std::string plugin = m.value("plugin", "");
    const std::string modelName = m.value("model", plugin);
    // The knob the plugin declares; none when it does not load (the run then reports why).
    SweepKnob knob;
    try {
      knob = sweepKnob(loader.load(plugin, m.value("model", "")), options.quick);
    } catch (const std::exception&) {
    }
    std::vector<json> values = knob.values;
    if (values.empty()) values.push_back(nullptr);
    // With a calibration of this model (--calibration), every point once more at the
    // calibrated parameters (the scene's own values still win): a second curve, "+cal".
    const CalibrationParams* calibration =
        calibrationFor(options.calibrations, plugin, modelName, organ, false);
    for (const bool calibrated : {false, true}) {
      if (calibrated && !calibration) continue;
      for (const json& v : values) {
        ojson copy = m;
        if (!copy.contains("params")) copy["params"] = ojson::object();
        if (calibrated) {
          ojson params = ojson::parse(calibration->params.dump());
          for (const auto& [k, pv] : copy["params"].items()) params[k] = pv;
          copy["params"] = params;
        }
        std::string label = modelName;
        if (!knob.param.empty()) {
          copy["params"][knob.param] = ojson::parse(v.dump());
          label += "[" + knob.param + "=" + valueText(v) + "]";
        }
        if (calibrated) label += "+cal";
        copy["label"] = label;
        models.push_back(copy);
        planned.push_back(
            {modelName, plugin, label, knob.param, v, calibrated ? calibration : nullptr});
      }
    }
  }
  return models;
}

/// A point's outcome from the case that ran it.
void fillPoint(SweepPoint& s, const Planned& planned, const CaseResult& c) {
  const RunRecord* r = c.run(s.label);
  // A calibrated point whose other parameters differ from those of the fit (the knob apart).
  const CalibrationParams* calibration = planned.calibration;
  if (r && calibration) s.note = calibrationDifferenceNote(*calibration, r->params, s.param);
  if (c.missing.count(s.plugin)) {
    s.status = "missing plugin: " + c.missing.at(s.plugin);
  } else if (!r) {
    s.status = c.error.empty() ? "not run" : "not run: " + c.error;
  } else {
    s.status = statusName(r->status);
    s.valid = r->valid;
    s.invalidReason = r->invalidReason;
    if (r->stepStats.samples > 0) {
      s.msMedian = r->stepStats.median;
      s.msP95 = r->stepStats.p95;
    }
    if (r->error) {
      s.rmseNearest = r->error->rmseNearest.empty() ? NAN : r->error->rmseNearest.back().second;
      for (const auto& [k, v] : r->error->rmseNearest)
        if (k == 50) s.rmseNearest = v;
      s.rmseAll = r->error->rmseAll;
      s.max = r->error->max;
      s.lossRatio = r->error->lossRatio;
    }
  }
}

/// The reference's status in the case that solved it.
std::string referenceStatus(const CaseResult& c, const Scene& parsed) {
  if (c.result)
    for (const RunRecord& r : c.result->runs)
      if (r.isReference) return statusName(r.status);
  return c.missing.count(parsed.reference->plugin) ? "missing" : "not run";
}

/// sweep.json and sweep.csv.
void writeSweepFiles(const std::vector<SweepPoint>& points,
                     const std::vector<std::string>& pointResults, const std::string& sceneFile,
                     const Scene& parsed, const std::string& refStatus, const std::string& results,
                     const SweepOptions& options) {
  ojson doc;
  doc["format"] = "deformbench-sweep/1";
  doc["scene"] = {{"name", parsed.name}, {"file", sceneFile}, {"sha256", parsed.sha256}};
  doc["reference"] = parsed.reference->model;
  doc["reference_status"] = refStatus;
  doc["quick"] = options.quick;
  doc["haptic_budget_ms"] = 1.0;
  doc["results"] = results;
  doc["points"] = ojson::array();
  std::ostringstream csv;
  csv << "model,plugin,label,param,value,status,ms_median,ms_p95,rmse_50_m,rmse_all_m,max_m,"
         "loss_ratio,pareto\n";
  for (size_t i = 0; i < points.size(); ++i) {
    const SweepPoint& p = points[i];
    doc["points"].push_back({{"model", p.model},
                             {"plugin", p.plugin},
                             {"label", p.label},
                             {"param", p.param},
                             {"value", ojson::parse(p.value.dump())},
                             {"status", p.status},
                             {"ms_median", num(p.msMedian)},
                             {"ms_p95", num(p.msP95)},
                             {"rmse_50", num(p.rmseNearest)},
                             {"rmse_all", num(p.rmseAll)},
                             {"max", num(p.max)},
                             {"loss_ratio", num(p.lossRatio)},
                             {"valid", p.valid},
                             {"invalid_reason", p.invalidReason},
                             {"pareto", p.pareto},
                             {"calibrated", p.calibrated},
                             {"note", p.note},
                             {"results", pointResults[i]}});
    const auto f = [](double v) {
      if (!std::isfinite(v)) return std::string();
      std::ostringstream s;
      s.precision(10);
      s << v;
      return s.str();
    };
    std::string value = p.value.is_null() ? "" : valueText(p.value);
    csv << p.model << ',' << p.plugin << ",\"" << p.label << "\"," << p.param << ',' << value
        << ",\"" << p.status << "\"," << f(p.msMedian) << ',' << f(p.msP95) << ','
        << f(p.rmseNearest) << ',' << f(p.rmseAll) << ',' << f(p.max) << ',' << f(p.lossRatio)
        << ',' << (p.pareto ? "yes" : "no") << '\n';
  }
  writeFileAtomic(options.outDir / "sweep.json", doc.dump(2) + "\n");
  writeFileAtomic(options.outDir / "sweep.csv", csv.str());
}

}  // namespace

std::vector<SweepPoint> runSweep(const std::string& sceneFile, PluginLoader& loader,
                                 const SweepOptions& options, Progress* progress) {
  ojson scene = readJsonFile(sceneFile, "scene file");
  // Validate the scene as given (unknown keys, ranges) before anything runs.
  const Scene parsed = parseSceneFile(sceneFile);
  if (!parsed.reference)
    throw InputError(sceneFile, "/reference",
                     "a sweep needs a reference (error against run time); add \"reference\": "
                     "{\"plugin\": \"reference_fem\", \"params\": {}}");
  // Mesh paths are relative to the scene file; the generated scene lives in DIR.
  if (scene.contains("organ") && scene["organ"].contains("mesh")) {
    const std::string mesh = scene["organ"]["mesh"];
    if (mesh.rfind("phantom:", 0) != 0 && !fs::path(mesh).is_absolute())
      scene["organ"]["mesh"] =
          fs::absolute(fs::path(sceneFile).parent_path() / mesh).lexically_normal().string();
  }

  std::vector<Planned> planned;
  const ojson models = plannedModels(scene, loader, options, planned);
  scene["models"] = models;
  // The points' outcomes (fillPoint), the reference's status, the results files.
  std::vector<SweepPoint> points;
  for (const Planned& p : planned) {
    SweepPoint s;
    s.model = p.model;
    s.plugin = p.plugin;
    s.label = p.label;
    s.param = p.param;
    s.value = p.value;
    s.calibrated = p.calibration != nullptr;
    points.push_back(s);
  }
  const auto fillPointOf = [&](size_t i, const CaseResult& c) {
    fillPoint(points[i], planned[i], c);
  };
  std::string refStatus = "not run";
  std::string results = "runs/results.json";
  std::vector<std::string> pointResults(points.size(), results);

  CaseOptions co = options.cases;
  if (!co.child) {
    // One scene with every point; the reference is solved once, only at the compared instants.
    // The runner reports each run started and finished: that is the progress.
    if (progress) progress->addTotal(int(planned.size()) + 1);
    co.progress = [progress](const std::string& line) {
      if (!progress) return;
      const std::string prefix = "running ";
      if (line.rfind(prefix, 0) == 0) {
        std::string label = line.substr(prefix.size());
        if (label.size() > 4 && label.compare(label.size() - 4, 4, " ...") == 0)
          label.resize(label.size() - 4);
        progress->start(label);
      } else {
        const auto colon = line.find(": ");
        progress->finish(line.substr(0, colon),
                         colon == std::string::npos ? line : line.substr(colon + 2));
      }
    };
    const CaseResult c = runSceneCase(scene, options.outDir / "sweep_scene.json",
                                      options.outDir / "runs", loader, co);
    for (size_t i = 0; i < points.size(); ++i) fillPointOf(i, c);
    refStatus = referenceStatus(c, parsed);
  } else {
    // One child case per point (scenes/point_<i>.json, runs/point_<i>/), handed to the
    // dispatcher. The first point whose plugin loads solves the reference (stage 0) and leaves
    // it in the cache; the others (stage 1) read it from there (`run --reuse-reference`), so
    // it is solved once and every point's error is against the same surfaces.
    std::error_code ec;
    fs::create_directories(options.outDir, ec);
    writeFileAtomic(options.outDir / "sweep_scene.json", scene.dump(2) + "\n");
    // --no-cache: the reference still goes through a cache, the sweep's own.
    if (co.cacheDir && co.cacheDir->empty()) co.cacheDir = options.outDir / "cache";
    co.child->runArgs.push_back("--reuse-reference");
    std::optional<size_t> first;
    for (size_t i = 0; i < planned.size() && !first; ++i)
      if (pluginProblem(loader, planned[i].plugin).empty()) first = i;
    std::vector<SceneCase> cases;
    for (size_t i = 0; i < planned.size(); ++i) {
      SceneCase c;
      c.scene = scene;
      c.scene["models"] = ojson::array({models[i]});
      const std::string id = "point_" + std::to_string(i);
      c.sceneFile = options.outDir / "scenes" / (id + ".json");
      c.outDir = options.outDir / "runs" / id;
      c.options = co;
      c.options.stage = first && i == *first ? 0 : 1;
      cases.push_back(std::move(c));
      pointResults[i] = "runs/" + id + "/results.json";
    }
    if (first) results = pointResults[*first];
    if (progress) progress->addTotal(int(planned.size()));
    runSceneCases(
        cases, loader, co.dispatcher,
        [&](size_t i) {
          if (progress) progress->start(points[i].label);
        },
        [&](size_t i, CaseResult&& c) {
          fillPointOf(i, c);
          if (first && i == *first) refStatus = referenceStatus(c, parsed);
          if (progress) progress->finish(points[i].label, points[i].status);
        });
    if (!first)
      refStatus = pluginProblem(loader, parsed.reference->plugin).empty() ? "not run" : "missing";
  }
  markPareto(points);

  writeSweepFiles(points, pointResults, sceneFile, parsed, refStatus, results, options);
  return points;
}

}  // namespace deform::harness
