// Calibrating a model's calibratable parameters to the reference (see calibration.h).
#include <deform/engine/scene.h>
#include <deform/internal/atomic_file.h>
#include <deform_harness/calibration.h>
#include <deform_harness/json_file.h>
#include <deform_harness/tables.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <map>
#include <nlopt.hpp>
#include <set>
#include <sstream>
#include <utility>

namespace deform::harness {

namespace fs = std::filesystem;
using json = nlohmann::json;
using ojson = nlohmann::ordered_json;
using Clock = std::chrono::steady_clock;

// ------------------------------------------------------------------------ the optimiser layer

double CalibDimension::value(double u) const {
  u = std::clamp(u, 0.0, 1.0);
  if (logToHalf)
    return 0.5 - std::exp(std::log(0.5 - lo) + u * (std::log(0.5 - hi) - std::log(0.5 - lo)));
  if (log) return std::exp(std::log(lo) + u * (std::log(hi) - std::log(lo)));
  return lo + u * (hi - lo);
}

double CalibDimension::unit(double v) const {
  double u = logToHalf ? (std::log(0.5 - std::clamp(v, lo, hi)) - std::log(0.5 - lo)) /
                             (std::log(0.5 - hi) - std::log(0.5 - lo))
             : log ? (std::log(std::max(v, lo)) - std::log(lo)) / (std::log(hi) - std::log(lo))
                   : (v - lo) / (hi - lo);
  if (!std::isfinite(u)) u = 0;
  return std::clamp(u, 0.0, 1.0);
}

std::vector<double> haltonPoint(long long i, int n) {
  static const int primes[] = {2, 3, 5, 7, 11, 13, 17, 19, 23, 29, 31, 37, 41, 43, 47, 53};
  std::vector<double> x(static_cast<size_t>(n), 0.5);
  for (int d = 0; d < n && d < 16; ++d) {
    const int b = primes[d];
    double f = 1, r = 0;
    for (long long k = i; k > 0; k /= b) {
      f /= b;
      r += f * double(k % b);
    }
    x[size_t(d)] = r;
  }
  return x;
}

OptimiserResult minimiseInBox(
    const std::vector<CalibDimension>& dims, const std::vector<double>& start,
    const BatchObjective& objective, const OptimiserOptions& options,
    const std::function<void(const std::vector<double>&, double)>& onTrial) {
  const int n = int(dims.size());
  OptimiserResult out;
  std::map<std::vector<double>, double> seen;  // unit point -> objective
  std::vector<double> bestU;
  double bestF = INFINITY;
  const auto toValues = [&](const std::vector<double>& u) {
    std::vector<double> v(static_cast<size_t>(n));
    for (int d = 0; d < n; ++d) v[size_t(d)] = dims[size_t(d)].value(u[size_t(d)]);
    return v;
  };
  // Evaluates the unit points not seen yet as one batch (at most the budget left).
  const auto evaluate = [&](const std::vector<std::vector<double>>& us) {
    std::vector<std::vector<double>> fresh, values;
    for (const auto& u : us) {
      if (seen.count(u) || std::find(fresh.begin(), fresh.end(), u) != fresh.end()) continue;
      if (out.evaluations + int(fresh.size()) >= options.budget) break;
      fresh.push_back(u);
      values.push_back(toValues(u));
    }
    if (fresh.empty()) return;
    const std::vector<double> f = objective(values);
    for (size_t i = 0; i < fresh.size(); ++i) {
      const double fi = i < f.size() && std::isfinite(f[i]) ? f[i] : INFINITY;
      seen[fresh[i]] = fi;
      ++out.evaluations;
      if (fi < bestF) {
        bestF = fi;
        bestU = fresh[i];
      }
      if (onTrial) onTrial(values[i], fi);
    }
  };

  std::vector<double> u0(static_cast<size_t>(n));
  for (int d = 0; d < n; ++d)
    u0[size_t(d)] =
        dims[size_t(d)].unit(d < int(start.size()) ? start[size_t(d)] : dims[size_t(d)].lo);
  evaluate({u0});

  // Global stage: Halton points, one batch.
  int g = options.globalPoints;
  if (g < 0) g = std::min(std::max(2, 4 * n + 2), std::max(0, (options.budget - 1) * 2 / 5));
  g = std::min(g, std::max(0, options.budget - out.evaluations));
  std::vector<std::vector<double>> batch;
  for (int i = 1; i <= g; ++i) batch.push_back(haltonPoint(i, n));
  evaluate(batch);
  out.globalPoints = g;

  // Local stage: BOBYQA (NLopt needs n >= 2 for it) or COBYLA from the best point.
  if (out.evaluations < options.budget && !bestU.empty()) {
    const nlopt::algorithm alg = n >= 2 ? nlopt::LN_BOBYQA : nlopt::LN_COBYLA;
    out.localMethod = n >= 2 ? "bobyqa" : "cobyla";
    nlopt::srand(19);  // NLopt's own random numbers (unused by these methods): fixed anyway
    nlopt::opt opt(alg, unsigned(n));
    opt.set_lower_bounds(std::vector<double>(size_t(n), 0.0));
    opt.set_upper_bounds(std::vector<double>(size_t(n), 1.0));
    // The first step: about the spacing of the global points, never beyond the box.
    const double spacing = 0.5 / std::pow(double(std::max(g, 1)), 1.0 / n);
    std::vector<double> step(static_cast<size_t>(n));
    for (int d = 0; d < n; ++d) {
      const double room = std::max(bestU[size_t(d)], 1.0 - bestU[size_t(d)]);
      step[size_t(d)] = std::min(std::max(spacing, 0.02), room);
    }
    opt.set_initial_step(step);
    opt.set_xtol_abs(options.xtol);
    // Repeated points (NLopt may ask for one twice) cost nothing: allow a few more calls.
    opt.set_maxeval(4 * (options.budget - out.evaluations) + 10);
    struct Ctx {
      std::function<double(const std::vector<double>&)> f;
    } ctx;
    ctx.f = [&](const std::vector<double>& u) {
      std::vector<double> c(u.size());
      for (size_t i = 0; i < u.size(); ++i) c[i] = std::clamp(u[i], 0.0, 1.0);
      if (!seen.count(c)) {
        if (out.evaluations >= options.budget) throw nlopt::forced_stop();
        evaluate({c});
      }
      const double f = seen.count(c) ? seen[c] : INFINITY;
      return std::isfinite(f) ? f : 1e300;
    };
    opt.set_min_objective([](const std::vector<double>& x, std::vector<double>&,
                             void* data) { return static_cast<Ctx*>(data)->f(x); },
                          &ctx);
    std::vector<double> x = bestU;
    double fx = 0;
    try {
      opt.optimize(x, fx);
    } catch (const nlopt::forced_stop&) {
      // budget spent
    } catch (const std::runtime_error&) {
      // NLopt gave up (roundoff, invalid step): the best trial so far stands
    }
  }
  out.best = bestU.empty() ? toValues(u0) : toValues(bestU);
  out.bestValue = bestF;
  return out;
}

// ------------------------------------------------------------------------ metrics and files

namespace {

/// Each metric and its name in calibration.json and on the command line.
constexpr std::pair<CalibMetric, const char*> kMetricNames[] = {
    {CalibMetric::RmseAll, "rmse_all"},
    {CalibMetric::Rmse50, "rmse_50"},
    {CalibMetric::LossRatio, "loss_ratio"},
    {CalibMetric::MarkerRms, "marker_rms"}};

/// Why a trial's run has no error figure: the case's reference run when it failed (a child that
/// timed out with it, say; the model then ran without it), else the run's own last note.
std::string noErrorWhy(const CaseResult& c, const RunRecord& run) {
  if (c.result)
    for (const RunRecord& r : c.result->runs)
      if (r.isReference && r.status != RunStatus::Ok)
        return ": the reference " + r.label + " " + notRunReason(r);
  return run.notes.empty() ? "" : ": " + run.notes.back();
}

}  // namespace

bool calibMetricFromName(const std::string& name, CalibMetric& out) {
  for (const auto& [metric, text] : kMetricNames)
    if (name == text) {
      out = metric;
      return true;
    }
  return false;
}

const char* calibMetricName(CalibMetric m) {
  for (const auto& [metric, text] : kMetricNames)
    if (m == metric) return text;
  return "?";
}

std::string calibrationOrgan(const std::string& mesh, double resolution, double scale) {
  const auto num = [](double v) {
    std::ostringstream s;
    s << std::setprecision(12) << v;
    return s.str();
  };
  if (mesh.empty()) return "";
  if (mesh.rfind("phantom:", 0) == 0)
    return mesh + ", resolution " + num(resolution) + (scale != 1.0 ? ", scale " + num(scale) : "");
  return fs::absolute(fs::path(mesh)).lexically_normal().string() + ", scale " + num(scale);
}

bool calibrationApplies(const CalibrationParams& c, const std::string& organ) {
  return c.organs.empty() || organ.empty() ||
         std::find(c.organs.begin(), c.organs.end(), organ) != c.organs.end();
}

std::string calibrationOrgan(const ojson& organ) {
  return calibrationOrgan(organ.value("mesh", std::string()), organ.value("resolution", 1.0),
                          organ.value("scale", 1.0));
}

const CalibrationParams* calibrationFor(const std::vector<CalibrationParams>& calibrations,
                                        const std::string& plugin, const std::string& model,
                                        const std::string& organ, bool skipOtherOrgans) {
  const CalibrationParams* elsewhere = nullptr;
  for (const CalibrationParams& c : calibrations) {
    // A fitted material is the whole scene's, not a twin's (tables truth-cube runs it alone).
    if (c.plugin != plugin || c.model != model || !c.material.empty()) continue;
    if (calibrationApplies(c, organ)) return &c;
    if (!elsewhere && !c.shipped) elsewhere = &c;
  }
  // A calibration is per organ: fitted on another, it would pass for one of this organ.
  if (elsewhere && !skipOtherOrgans)
    throw InputError(elsewhere->file, "/organs",
                     "fitted on " + elsewhere->organs.front() +
                         (elsewhere->organs.size() > 1 ? " and others" : "") +
                         ", not on this scene's organ (" + organ + ")");
  return nullptr;
}

std::vector<std::string> calibrationDifferences(const CalibrationParams& c, const json& resolved,
                                                const std::vector<std::string>& except) {
  std::vector<std::string> out;
  for (const auto& [k, fitted] : c.held.items()) {
    if (std::find(except.begin(), except.end(), k) != except.end() || !resolved.contains(k) ||
        resolved[k] == fitted)
      continue;
    out.push_back(k + " = " + resolved[k].dump() + " (fitted with " + fitted.dump() + ")");
  }
  return out;
}

std::string calibrationDifferenceNote(const CalibrationParams& c, const json& resolved,
                                      const std::vector<std::string>& except) {
  std::string list;
  for (const std::string& d : calibrationDifferences(c, resolved, except))
    list += (list.empty() ? "" : ", ") + d;
  return list.empty() ? "" : "calibration " + c.file + " was fitted with other parameters: " + list;
}

CalibrationParams readCalibrationFile(const std::string& file) {
  json doc = readJsonFile<json>(file, "calibration file");
  if (!doc.is_object() || doc.value("format", "") != "deformbench-calibration/1")
    throw InputError(file, "/format", "not a calibration file (format deformbench-calibration/1)");
  CalibrationParams c;
  c.file = file;
  if (!doc.contains("plugin") || !doc["plugin"].is_string() || !doc.contains("model") ||
      !doc["model"].is_string())
    throw InputError(file, "/plugin", "\"plugin\" and \"model\" must be strings");
  c.plugin = doc["plugin"].get<std::string>();
  c.model = doc["model"].get<std::string>();
  if (!doc.contains("params") || !doc["params"].is_object())
    throw InputError(file, "/params", "\"params\" must be an object");
  c.params = doc["params"];
  if (doc.contains("organs")) {
    const json& organs = doc["organs"];
    if (!organs.is_array() ||
        !std::all_of(organs.begin(), organs.end(), [](const json& o) { return o.is_string(); }))
      throw InputError(file, "/organs", "\"organs\" must be an array of strings");
    for (const json& o : organs) c.organs.push_back(o.get<std::string>());
  }
  if (doc.contains("held")) {
    if (!doc["held"].is_object())
      throw InputError(file, "/held", "\"held\" must be an object of parameter values");
    c.held = doc["held"];
  }
  if (doc.contains("material")) {
    const json& m = doc["material"];
    if (!m.is_object() ||
        !std::all_of(m.begin(), m.end(), [](const json& v) { return v.is_number(); }))
      throw InputError(file, "/material", "\"material\" must be an object of numbers");
    c.material = m;
  }
  if (doc.contains("truth_cube") && doc["truth_cube"].is_object()) c.truthCube = doc["truth_cube"];
  if (doc.contains("at_bound")) {
    const json& b = doc["at_bound"];
    if (!b.is_object() || !std::all_of(b.begin(), b.end(), [](const json& v) {
          return v.is_string() && (v.get<std::string>() == "min" || v.get<std::string>() == "max");
        }))
      throw InputError(file, "/at_bound", "\"at_bound\" must be an object of \"min\" or \"max\"");
    c.atBound = b;
  }
  return c;
}

std::string calibratedRunNote(const CalibrationParams& c, const json& resolved,
                              const std::vector<std::string>& except) {
  std::string note = calibrationDifferenceNote(c, resolved, except);
  const std::string bound = calibrationBoundNote(c);
  if (!bound.empty()) note += (note.empty() ? "" : "; ") + bound;
  return note;
}

std::string boundWords(const CalibrationParams& c, const std::string& key) {
  if (!c.atBound.contains(key)) return "";
  return c.atBound[key] == "max" ? "at its upper bound" : "at its lower bound";
}

std::string calibrationBoundNote(const CalibrationParams& c) {
  std::string list;
  for (const auto& [k, v] : c.atBound.items())
    list += (list.empty() ? "" : ", ") + k + " fitted " + boundWords(c, k);
  return list.empty() ? ""
                      : "calibration " + c.file + ": " + list +
                            " (the best fit may lie beyond the searched range)";
}

std::vector<std::pair<std::string, std::string>> addCalibratedTwins(
    ojson& scene, const std::vector<CalibrationParams>& calibrations) {
  std::vector<std::pair<std::string, std::string>> added;
  if (!scene.contains("models") || !scene["models"].is_array()) return added;
  ojson models = scene["models"];
  ojson out = ojson::array();
  const std::string organ = calibrationOrgan(scene.value("organ", ojson::object()));
  std::set<std::string> labels;
  for (const ojson& m : models) labels.insert(m.value("label", m.value("plugin", "")));
  for (const ojson& m : models) {
    out.push_back(m);
    const std::string plugin = m.value("plugin", "");
    const std::string model = m.value("model", plugin);
    const std::string label = m.value("label", "");
    const std::string twinLabel = (label.empty() ? model : label) + "+cal";
    // A twin already (tables truth-cube adds its own) or twinned: nothing to add.
    const auto endsWith = [](const std::string& s, const std::string& tail) {
      return s.size() >= tail.size() && s.compare(s.size() - tail.size(), tail.size(), tail) == 0;
    };
    if (endsWith(label, "+cal") || labels.count(twinLabel)) continue;
    const CalibrationParams* c = calibrationFor(calibrations, plugin, model, organ, true);
    if (!c) continue;
    ojson twin = m;
    twin["label"] = twinLabel;
    ojson params = ojson::object();
    // json -> ordered_json through text (no implicit conversion between the two types).
    for (const auto& [k, v] : c->params.items()) params[k] = ojson::parse(v.dump());
    const ojson written = m.value("params", ojson::object());
    for (const auto& [k, v] : written.items()) params[k] = v;
    twin["params"] = params;
    added.emplace_back(label, twin["label"].get<std::string>());
    out.push_back(twin);
  }
  scene["models"] = out;
  return added;
}

// ------------------------------------------------------------------------ the command

namespace {

struct SceneInfo {
  std::string file;
  std::string stem;                     ///< unique within the calibration
  ojson doc;                            ///< the scene as written
  ojson modelParams = ojson::object();  ///< the scene's params for the model, when it names it
  bool hasModel = false;
  std::string organ;            ///< calibrationOrgan() of its organ
  double smallestExtent = NAN;  ///< m: the organ's smallest bounding-box side
};

SceneInfo loadScene(const std::string& file, const std::string& plugin, const std::string& model,
                    CalibMetric metric) {
  SceneInfo s;
  s.file = file;
  const Scene parsed = parseSceneFile(file);  // validates (throws InputError)
  if (metric == CalibMetric::MarkerRms) {
    if (parsed.markers.measured.empty())
      throw InputError(file, "/markers/measured",
                       "--metric marker_rms needs measured marker positions in every scene");
  } else if (!parsed.reference)
    throw InputError(file, "/reference",
                     "calibration needs a reference in every scene; add \"reference\": "
                     "{\"plugin\": \"reference_fem\", \"params\": {}}");
  if (metric == CalibMetric::Rmse50 &&
      std::find(parsed.nearest.begin(), parsed.nearest.end(), 50) == parsed.nearest.end())
    throw InputError(file, "/samples/nearest", "--metric rmse_50 needs 50 among the nearest");
  s.organ = calibrationOrgan(parsed.organ.mesh, parsed.organ.resolution, parsed.organ.scale);
  s.smallestExtent = boundingBox(loadOrgan(parsed).surface.V).size().minCoeff();
  std::ifstream in(file);
  s.doc = ojson::parse(in);
  for (const ojson& m : s.doc.value("models", ojson::array())) {
    if (m.value("plugin", "") == plugin && m.value("model", plugin) == model) {
      s.modelParams = m.value("params", ojson::object());
      s.hasModel = true;
      break;
    }
  }
  // Paths inside the scene (a mesh file) are relative to the scene's folder: make them absolute
  // so the trial scenes written elsewhere still find them.
  if (s.doc.contains("organ") && s.doc["organ"].contains("mesh")) {
    const std::string mesh = s.doc["organ"]["mesh"].get<std::string>();
    if (mesh.rfind("phantom:", 0) != 0 && !fs::path(mesh).is_absolute())
      s.doc["organ"]["mesh"] = fs::absolute(fs::path(file).parent_path() / mesh).string();
  }
  return s;
}

/// The marker_rms of run `label` in a case's results.json: the mean over its measured instants
/// of the registered marker RMS; NaN with `why` when there is none.
double markerRmsOf(const fs::path& results, const std::string& label, std::string& why) {
  try {
    std::ifstream in(results);
    const json doc = json::parse(in);
    for (const json& r : doc.at("runs")) {
      if (r.value("label", "") != label) continue;
      const json m = r.value("markers", json::object());
      if (m.value("status", "") != "ok") {
        why = "markers " + m.value("status", std::string("absent")) + ": " +
              m.value("reason", std::string("no markers in results.json"));
        return NAN;
      }
      double sum = 0;
      int n = 0;
      for (const json& at : m.value("at", json::array())) {
        if (!at.contains("rms_error_translation_m") || !at["rms_error_translation_m"].is_number())
          continue;
        sum += at["rms_error_translation_m"].get<double>();
        ++n;
      }
      if (n == 0) why = "no compared instant with measured marker positions";
      return n ? sum / n : NAN;
    }
    why = "no run " + label + " in results.json";
  } catch (const std::exception& e) {
    why = std::string("cannot read results.json: ") + e.what();
  }
  return NAN;
}

/// Calibrated dimensions on the organ's material (--material) carry this prefix in a trial's
/// values; the rest are the model's parameters.
constexpr const char* kMaterialPrefix = "material.";

bool isMaterialKey(const std::string& key) {
  return key.rfind(kMaterialPrefix, 0) == 0;
}

double metricOf(const ErrorMetrics& e, CalibMetric m) {
  switch (m) {
    case CalibMetric::RmseAll:
      return e.rmseAll;
    case CalibMetric::Rmse50:
      for (const auto& [k, v] : e.rmseNearest)
        if (k == 50) return v;
      return NAN;
    case CalibMetric::LossRatio:
      return e.lossRatio;
    case CalibMetric::MarkerRms:
      return NAN;  // read from the markers (markerRmsOf), not the reference's errors
  }
  return NAN;
}

std::string fmtValue(double v) {
  std::ostringstream s;
  s << std::setprecision(4) << v;
  return s.str();
}

}  // namespace

std::map<std::string, std::string> limitLengthsToOrgan(std::vector<CalibDimension>& dims,
                                                       const ModelInfo& info, double extent) {
  std::map<std::string, std::string> notes;
  for (CalibDimension& d : dims) {
    const ParamSpec* p = info.param(d.key);
    if (!p || p->unit != "m" || !std::isfinite(extent) || !(d.hi > extent) || !(extent > d.lo))
      continue;
    notes[d.key] = "upper bound lowered from " + fmtValue(d.hi) +
                   " m to the training organs' smallest extent, " + fmtValue(extent) + " m";
    d.hi = extent;
  }
  return notes;
}

std::map<std::string, std::string> fittedAtBound(const std::vector<CalibDimension>& dims,
                                                 const std::vector<double>& values) {
  std::map<std::string, std::string> out;
  for (size_t d = 0; d < dims.size() && d < values.size(); ++d) {
    const double u = dims[d].unit(values[d]);
    if (u <= kAtBoundFraction) out[dims[d].key] = "min";
    if (u >= 1 - kAtBoundFraction) out[dims[d].key] = "max";
  }
  return out;
}

namespace {

/// One model run of a trial: its metric (NaN: failed) and why it failed.
struct RunOutcome {
  double value = NAN;
  std::string status;  ///< "ok", "diverged", "failed: ...", ...
};

class Calibrator {
 public:
  Calibrator(PluginLoader& loader, const CalibrateOptions& o, const ModelInfo& info,
             std::vector<CalibDimension> dims, std::vector<SceneInfo> train,
             std::vector<SceneInfo> validate)
      : m_loader(loader),
        m_o(o),
        m_info(info),
        m_dims(std::move(dims)),
        m_train(std::move(train)),
        m_validate(std::move(validate)) {}

  /// Runs (point, scene) pairs; values[point][scene].
  std::vector<std::vector<RunOutcome>> runBatch(const std::vector<ojson>& paramSets,
                                                const std::vector<SceneInfo>& scenes,
                                                const std::string& group) {
    std::vector<SceneCase> cases;
    for (size_t p = 0; p < paramSets.size(); ++p) {
      const std::string tag = group == "trials" ? std::to_string(m_trialDirs + int(p)) : group;
      for (const SceneInfo& s : scenes) {
        SceneCase c;
        c.scene = s.doc;
        ojson entry = {{"plugin", m_o.plugin}};
        if (m_info.name != m_o.plugin) entry["model"] = m_info.name;
        entry["label"] = "calibrated";
        ojson params = s.modelParams;
        for (const auto& [k, v] : paramSets[p].items()) {
          if (isMaterialKey(k)) {
            c.scene["organ"]["material"][k.substr(std::string(kMaterialPrefix).size())] = v;
          } else {
            params[k] = v;
          }
        }
        entry["params"] = params;
        c.scene["models"] = ojson::array({entry});
        c.scene["output"] = {{"surfaces", "none"}};
        const fs::path dir = m_o.outDir / (group == "trials" ? "trials" : "runs") / tag / s.stem;
        c.sceneFile = dir / "scene.json";
        c.outDir = dir;
        c.options = m_o.cases;
        cases.push_back(std::move(c));
      }
    }
    if (group == "trials") m_trialDirs += int(paramSets.size());
    std::vector<std::vector<RunOutcome>> out(paramSets.size(),
                                             std::vector<RunOutcome>(scenes.size()));
    runSceneCases(
        cases, m_loader, m_o.cases.dispatcher, [](size_t) {},
        [&](size_t i, CaseResult&& c) {
          RunOutcome& r = out[i / scenes.size()][i % scenes.size()];
          const RunRecord* run = c.run("calibrated");
          if (!c.error.empty()) {
            r.status = "failed: " + c.error;
          } else if (!run) {
            r.status = "failed: no run";
          } else if (run->status != RunStatus::Ok) {
            r.status = std::string(statusName(run->status)) +
                       (run->message.empty() ? "" : ": " + run->message);
          } else if (m_o.metric == CalibMetric::MarkerRms) {
            // Against measurements: a run that did not do what the scene asked scores worst.
            std::string why;
            r.value = run->valid ? markerRmsOf(c.outDir / "results.json", "calibrated", why) : NAN;
            if (!run->valid) why = "invalid: " + run->invalidReason;
            r.status = std::isfinite(r.value) ? "ok" : why;
          } else if (!run->valid) {
            // A run that did not do what the scene asked (it did not settle, let go of its
            // grasp, collapsed, gave up on a solve) fits nothing, however small its error.
            r.status = "invalid: " + run->invalidReason;
          } else if (!run->error) {
            r.status = "no error" + noErrorWhy(c, *run);
          } else if (!run->referenceValid.value_or(true)) {
            // An error against a state that is not the solid's fits nothing.
            r.status = "against an invalid reference: " + run->referenceInvalidReason;
          } else {
            r.value = metricOf(*run->error, m_o.metric);
            r.status = std::isfinite(r.value) ? "ok" : "no metric";
          }
        });
    return out;
  }

  /// The model's parameters outside the calibrated ones, resolved as each training scene runs
  /// them, where all scenes agree (CalibrationParams::held).
  ojson heldParams() const {
    std::vector<json> resolved;
    for (const SceneInfo& s : m_train)
      resolved.push_back(paramsToJson(
          resolveParams(m_info.params, json::parse(s.modelParams.dump()), s.file, "/params")));
    ojson held = ojson::object();
    for (const ParamSpec& ps : m_info.params) {
      if (resolved.empty() ||
          std::any_of(m_dims.begin(), m_dims.end(),
                      [&](const CalibDimension& d) { return d.key == ps.key; }) ||
          !std::all_of(resolved.begin(), resolved.end(),
                       [&](const json& r) { return r[ps.key] == resolved.front()[ps.key]; }))
        continue;
      held[ps.key] = ojson::parse(resolved.front()[ps.key].dump());
    }
    return held;
  }

  /// A trial's values by key (the material's with their prefix).
  ojson pointParams(const std::vector<double>& values) const {
    ojson p = ojson::object();
    for (size_t d = 0; d < m_dims.size(); ++d) p[m_dims[d].key] = values[d];
    return p;
  }

  /// The model's parameters (material = false) or the organ's material (true) of a trial.
  static ojson split(const ojson& point, bool material) {
    ojson out = ojson::object();
    for (const auto& [k, v] : point.items()) {
      if (isMaterialKey(k) != material) continue;
      out[material ? k.substr(std::string(kMaterialPrefix).size()) : k] = v;
    }
    return out;
  }

  /// The scored value of a run: its metric, or the scene's worst when it failed (and never
  /// above the worst, so a failure never beats a run).
  double scored(const RunOutcome& r, size_t scene) const {
    const double worst = m_worst[scene];
    return std::isfinite(r.value) ? std::min(r.value, worst) : worst;
  }

  /// The start of the search: each dimension's default (the first training scene's own value
  /// where it writes one).
  std::vector<double> defaultValues() const {
    std::vector<double> defaults;
    for (const CalibDimension& d : m_dims) {
      double v = d.lo;
      if (isMaterialKey(d.key)) {
        // The first training scene's material (runCalibration checked it writes it).
        defaults.push_back(
            m_train[0]
                .doc["organ"]["material"][d.key.substr(std::string(kMaterialPrefix).size())]
                .get<double>());
        continue;
      }
      const ParamSpec* ps = m_info.param(d.key);
      if (ps) v = std::get<double>(ps->defaultValue);
      // A training scene that writes the value starts there instead.
      if (m_train[0].modelParams.contains(d.key) && m_train[0].modelParams[d.key].is_number())
        v = m_train[0].modelParams[d.key].get<double>();
      defaults.push_back(v);
    }
    return defaults;
  }

  /// "before", "after" and "per_scene" of a set of scenes (train or validation).
  static ojson setSummary(const std::vector<SceneInfo>& scenes, const std::vector<RunOutcome>& b,
                          const std::vector<RunOutcome>& a) {
    ojson per = ojson::array();
    double sb = 0, sa = 0;
    bool okB = true, okA = true;
    for (size_t s = 0; s < scenes.size(); ++s) {
      per.push_back({{"scene", scenes[s].file},
                     {"before", numberOrNull(b[s].value)},
                     {"after", numberOrNull(a[s].value)},
                     {"status_before", b[s].status},
                     {"status_after", a[s].status}});
      sb += b[s].value;
      sa += a[s].value;
      okB = okB && std::isfinite(b[s].value);
      okA = okA && std::isfinite(a[s].value);
    }
    const double n = double(std::max<size_t>(1, scenes.size()));
    return ojson{{"before", okB && !scenes.empty() ? numberOrNull(sb / n) : ojson(nullptr)},
                 {"after", okA && !scenes.empty() ? numberOrNull(sa / n) : ojson(nullptr)},
                 {"per_scene", per}};
  }

  /// "defaults", "space", "at_bound" and "warnings" of calibration.json.
  void describeSpace(ojson& doc, const std::vector<double>& defaults,
                     const std::vector<double>& best) const {
    ojson defaultsJson = ojson::object();
    ojson space = ojson::object();
    for (size_t d = 0; d < m_dims.size(); ++d) {
      defaultsJson[m_dims[d].key] = defaults[d];
      space[m_dims[d].key] = {{"min", m_dims[d].lo},
                              {"max", m_dims[d].hi},
                              {"scale", m_dims[d].logToHalf ? "log(0.5 - x)"
                                        : m_dims[d].log     ? "log"
                                                            : "linear"}};
    }
    doc["defaults"] = defaultsJson;
    for (const auto& [key, note] : m_boundNotes) space[key]["note"] = note;
    doc["space"] = space;
    // A fit at a bound: the best value may lie beyond it (or the model cannot match the
    // reference with this parameter); within 1% of the range, in its own scale.
    ojson atBound = ojson::object();
    ojson warnings = ojson::array();
    for (const auto& bound : fittedAtBound(m_dims, best)) {
      const std::string& key = bound.first;
      const std::string& side = bound.second;
      atBound[key] = side;
      const CalibDimension& d =
          *std::find_if(m_dims.begin(), m_dims.end(), [&](const auto& x) { return x.key == key; });
      warnings.push_back(key + " fitted at its " + (side == "max" ? "upper" : "lower") + " bound " +
                         fmtValue(side == "max" ? d.hi : d.lo) +
                         ": the best fit may lie beyond the range, or the model cannot match "
                         "the " +
                         (m_o.metric == CalibMetric::MarkerRms ? "measurements" : "reference") +
                         " with it");
    }
    doc["at_bound"] = atBound;
    doc["warnings"] = warnings;
  }

  ojson run(Progress* progress) {
    const auto start = Clock::now();
    const auto elapsed = [&] {
      return std::chrono::duration<double>(Clock::now() - start).count();
    };
    std::ofstream trials(m_o.outDir / "trials.csv");
    trials << "trial";
    for (const auto& d : m_dims) trials << "," << d.key;
    for (const auto& s : m_train) trials << "," << s.stem;
    trials << ",objective,status\n";

    // Trial 0: the defaults (the scene's own values where it writes them). It solves and caches
    // each scene's reference, and sets the worst values failures score.
    const std::vector<std::vector<RunOutcome>> before =
        runBatch({ojson::object()}, m_train, "trials");
    m_worst.assign(m_train.size(), 0);
    const double fallback = m_o.metric == CalibMetric::LossRatio ? 100.0 : 1.0;
    for (size_t s = 0; s < m_train.size(); ++s)
      m_worst[s] = std::isfinite(before[0][s].value) ? 10 * before[0][s].value : fallback;
    const std::vector<double> defaults = defaultValues();
    int trialNo = 0;
    double best = INFINITY;
    int failedRuns = 0, scoredRuns = 0;
    size_t failedScene = 0;  ///< a scene whose run failed, and why (the last such run)
    std::string failedWhy;
    const auto record = [&](const std::vector<double>& values,
                            const std::vector<RunOutcome>& runs) {
      double sum = 0;
      std::string status = "ok";
      for (size_t s = 0; s < runs.size(); ++s) {
        sum += scored(runs[s], s);
        if (!std::isfinite(runs[s].value)) {
          ++failedRuns;
          status = m_train[s].stem + ": " + runs[s].status;
          failedScene = s;
          failedWhy = runs[s].status;
        } else {
          ++scoredRuns;
        }
      }
      const double f = sum / double(runs.size());
      m_history[values] = runs;
      trials << trialNo;
      for (double v : values) trials << "," << std::setprecision(8) << v;
      for (const RunOutcome& r : runs)
        trials << "," << (std::isfinite(r.value) ? fmtValue(r.value) : std::string(""));
      std::string st = status;
      std::replace(st.begin(), st.end(), ',', ';');
      std::replace(st.begin(), st.end(), '\n', ' ');
      trials << "," << std::setprecision(8) << f << "," << st << "\n" << std::flush;
      best = std::min(best, f);
      ++trialNo;
      if (progress) {
        progress->finish("trial " + std::to_string(trialNo - 1) + ": " + fmtValue(f) +
                             ", best so far " + fmtValue(best) + " (" +
                             calibMetricName(m_o.metric) + ")",
                         status == "ok" ? "ok" : "scored worst");
      }
      return f;
    };
    // The start trial is recorded by the optimiser's first evaluation: reuse the runs above
    // when its values are the defaults (always, except when a default lies outside the box).
    bool startPending = true;
    std::vector<double> startValues;
    for (size_t d = 0; d < m_dims.size(); ++d)
      startValues.push_back(m_dims[d].value(m_dims[d].unit(defaults[d])));
    bool defaultsInBox = true;
    for (size_t d = 0; d < m_dims.size(); ++d)
      if (std::fabs(startValues[d] - defaults[d]) > 1e-9 * std::fabs(defaults[d]))
        defaultsInBox = false;

    const BatchObjective objective = [&](const std::vector<std::vector<double>>& points) {
      std::vector<double> f(points.size(), INFINITY);
      std::vector<ojson> sets;
      std::vector<size_t> idx;
      for (size_t i = 0; i < points.size(); ++i) {
        if (startPending && defaultsInBox && i == 0) {
          f[0] = record(points[0], before[0]);
          continue;
        }
        sets.push_back(pointParams(points[i]));
        idx.push_back(i);
      }
      startPending = false;
      if (!sets.empty()) {
        const auto runs = runBatch(sets, m_train, "trials");
        for (size_t j = 0; j < idx.size(); ++j) f[idx[j]] = record(points[idx[j]], runs[j]);
      }
      return f;
    };
    OptimiserOptions oo;
    oo.budget = m_o.budget;
    const OptimiserResult res = minimiseInBox(m_dims, defaults, objective, oo);
    // Not one run measured: a "best" trial would be the start, fitted to nothing.
    if (scoredRuns == 0)
      throw InputError(m_train[failedScene].file, "",
                       "no trial run could be scored (" + failedWhy + "); see " +
                           (m_o.outDir / "trials.csv").string());
    const ojson calibrated = pointParams(res.best);

    // Validation (and the per-scene values of the best trial): defaults and calibrated.
    const auto known = m_history.find(res.best);
    const auto after = known != m_history.end()
                           ? known->second
                           : runBatch({calibrated}, m_train, "train_calibrated")[0];
    ojson validation =
        ojson{{"before", nullptr}, {"after", nullptr}, {"per_scene", ojson::array()}};
    if (!m_validate.empty()) {
      const auto vb = runBatch({ojson::object()}, m_validate, "validation_defaults")[0];
      const auto va = runBatch({calibrated}, m_validate, "validation_calibrated")[0];
      validation = setSummary(m_validate, vb, va);
    }

    ojson doc;
    doc["format"] = "deformbench-calibration/1";
    doc["model"] = m_info.name;
    doc["plugin"] = m_o.plugin;
    doc["metric"] = calibMetricName(m_o.metric);
    if (!m_o.label.empty()) doc["label"] = m_o.label;
    doc["params"] = split(calibrated, false);
    if (!split(calibrated, true).empty()) doc["material"] = split(calibrated, true);
    if (!m_truthCube.empty()) doc["truth_cube"] = m_truthCube;
    // The organs it was fitted on: a calibration applies to scenes of these organs only.
    ojson organs = ojson::array();
    for (const SceneInfo& sc : m_train)
      if (std::find(organs.begin(), organs.end(), sc.organ) == organs.end())
        organs.push_back(sc.organ);
    doc["organs"] = organs;
    doc["held"] = heldParams();
    describeSpace(doc, defaults, res.best);
    doc["train"] = setSummary(m_train, before[0], after);
    doc["validation"] = validation;
    doc["objective"] = numberOrNull(res.bestValue);
    doc["evaluations"] = res.evaluations;
    doc["model_runs"] = res.evaluations * int(m_train.size());
    doc["failed_runs"] = failedRuns;
    doc["budget"] = m_o.budget;
    doc["optimiser"] = {
        {"global", "halton"},
        {"global_points", res.globalPoints},
        {"local", res.localMethod.empty() ? ojson(nullptr) : ojson(res.localMethod)}};
    doc["wall_s"] = elapsed();
    writeFileAtomic(m_o.outDir / "calibration.json", doc.dump(2) + "\n");
    return doc;
  }

 private:
  PluginLoader& m_loader;
  const CalibrateOptions& m_o;
  const ModelInfo& m_info;
  std::vector<CalibDimension> m_dims;
  std::vector<SceneInfo> m_train, m_validate;
  std::vector<double> m_worst;
  std::map<std::vector<double>, std::vector<RunOutcome>> m_history;  ///< values -> runs
  int m_trialDirs = 0;

 public:
  std::map<std::string, std::string> m_boundNotes;  ///< key -> why its range was narrowed
  ojson m_truthCube = ojson::object();              ///< calibration.json's "truth_cube"
};

/// calibrate --truth-cube: writes the scene of every level for the model to DIR/scenes/ and adds
/// the trained level's to `train`, the others' to `validate`. Returns calibration.json's
/// "truth_cube".
ojson truthCubeScenes(PluginLoader& loader, const CalibrateOptions& o,
                      std::vector<std::string>& train, std::vector<std::string>& validate) {
  if (o.metric != CalibMetric::MarkerRms)
    throw InputError("--metric", calibMetricName(o.metric),
                     "--truth-cube measures against the beads: marker_rms");
  const TruthCubeModel m = truthCubeModel(loader, o.plugin, false);
  if (!m.problem.empty()) throw InputError("--model", o.plugin, m.problem);
  const std::vector<double> strains = truthCubeStrains(o.truthCubeData);
  const size_t level = size_t(o.truthCubeLevel - 1);
  if (o.truthCubeLevel < 1 || level >= strains.size())
    throw InputError("--truth-cube", std::to_string(o.truthCubeLevel),
                     "the data hold levels 1 to " + std::to_string(strains.size()));
  std::vector<std::pair<fs::path, ojson>> scenes;
  for (size_t l = 0; l < strains.size(); ++l)
    scenes.emplace_back(
        o.outDir / "scenes" / ("truth_cube_level_" + std::to_string(l + 1) + ".json"),
        truthCubeLevelScene(o.truthCubeData, l, m, o.truthCubeContact, false));
  fs::create_directories(o.outDir / "scenes");
  for (size_t l = 0; l < scenes.size(); ++l) {
    writeFileAtomic(scenes[l].first, scenes[l].second.dump(2) + "\n");
    (l == level ? train : validate).push_back(scenes[l].first.string());
  }
  return {{"level", o.truthCubeLevel},
          {"strain", strains[level]},
          {"contact", o.truthCubeContact},
          {"data", o.truthCubeData.empty() ? std::string("shipped") : o.truthCubeData}};
}

}  // namespace

ojson runCalibration(PluginLoader& loader, const CalibrateOptions& o, Progress* progress) {
  if (o.budget < 1) throw InputError("--budget", "", "must be at least 1 (trials)");
  if (o.train.empty() && o.truthCubeLevel == 0)
    throw InputError("calibrate", "", "name at least one training scene, or --truth-cube LEVEL");
  if (!o.cases.child)
    throw std::logic_error("runCalibration: trials run in child processes (cases.child)");
  const std::string why = pluginProblem(loader, o.plugin);
  if (!why.empty()) throw InputError("--model", "", "plugin '" + o.plugin + "': " + why);
  const ModelInfo& info = loader.load(o.plugin, o.model);
  std::vector<CalibDimension> dims;
  for (const ParamSpec& p : info.params) {
    if (!p.calibratable) continue;
    if (!o.params.empty() && std::find(o.params.begin(), o.params.end(), p.key) == o.params.end())
      continue;
    dims.push_back({p.key, p.calibMin, p.calibMax, p.calibScale == ParamScale::Log});
  }
  for (const std::string& k : o.material) {
    if (k != "young" && k != "poisson")
      throw InputError("--material", k, "expected young or poisson");
    if (o.metric != CalibMetric::MarkerRms)
      throw InputError("--material", k,
                       "the organ's material is fitted to measurements only (--metric "
                       "marker_rms): fitted to a reference made of it, it would be circular");
  }
  if (dims.empty() && o.params.empty() && o.material.empty())
    throw InputError("--model", "",
                     "model '" + info.name + "' of plugin '" + o.plugin +
                         "' declares no calibratable parameter");
  for (const std::string& k : o.params) {
    const ParamSpec* p = info.param(k);
    if (!p || !p->calibratable)
      throw InputError("--param", "",
                       "'" + k + "' is not a calibratable parameter of " + info.name +
                           " (see deformbench plugins)");
  }
  std::vector<std::string> trainFiles = o.train, validateFiles = o.validate;
  std::error_code ec;
  fs::create_directories(o.outDir, ec);
  if (ec) throw InputError(o.outDir.string(), "", "cannot create the output folder");
  const ojson truthCube = o.truthCubeLevel != 0
                              ? truthCubeScenes(loader, o, trainFiles, validateFiles)
                              : ojson::object();
  std::vector<SceneInfo> train, validate;
  std::map<std::string, int> stems;
  const auto load = [&](const std::string& f) {
    SceneInfo s = loadScene(f, o.plugin, info.name, o.metric);
    std::string stem = fs::path(f).stem().string();
    if (stems[stem]++) stem += "_" + std::to_string(stems[stem]);
    s.stem = stem;
    return s;
  };
  for (const std::string& f : trainFiles) train.push_back(load(f));
  for (const std::string& f : validateFiles) validate.push_back(load(f));
  for (const std::string& k : o.material) {
    const ojson& m = train[0].doc.contains("organ") ? train[0].doc["organ"] : ojson::object();
    const ojson* v =
        m.contains("material") && m["material"].contains(k) ? &m["material"][k] : nullptr;
    if (!v || !v->is_number())
      throw InputError(train[0].file, "/organ/material/" + k,
                       "--material " + k + " starts from the scene's value: write it");
    const double x = v->get<double>();
    if (k == "young") dims.push_back({kMaterialPrefix + k, x / 10, x * 10, true});
    if (k == "poisson") dims.push_back({kMaterialPrefix + k, 0.3, 0.4999, false, true});
  }
  double extent = INFINITY;
  for (const SceneInfo& s : train) extent = std::min(extent, s.smallestExtent);
  const std::map<std::string, std::string> boundNotes = limitLengthsToOrgan(dims, info, extent);
  Calibrator c(loader, o, info, std::move(dims), std::move(train), std::move(validate));
  c.m_boundNotes = boundNotes;
  c.m_truthCube = truthCube;
  return c.run(progress);
}

}  // namespace deform::harness
