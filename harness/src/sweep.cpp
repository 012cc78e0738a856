// Error against run time: sweeping each model over its two cost axes (see sweep.h).
#include <deform/internal/atomic_file.h>
#include <deform/sdk/cache.h>
#include <deform_harness/json_file.h>
#include <deform_harness/sweep.h>

#include <algorithm>
#include <cmath>
#include <deque>
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

SweepAxes sweepAxes(const ModelInfo& info, bool quick) {
  const auto axis = [quick](const ModelInfo::Knob& knob) {
    ModelInfo only;
    only.knob = knob;
    return sweepKnob(only, quick);
  };
  SweepAxes a{axis(info.resolution), axis(info.effort)};
  if (a.resolution.param.empty() && a.effort.param.empty()) a.effort = sweepKnob(info, quick);
  return a;
}

namespace {

std::string valueText(const json& v) {
  return v.is_string() ? v.get<std::string>() : v.dump();
}

/// An ok, valid point with a time and a finite error `err`: ranked on a front.
bool usable(const SweepPoint& p, double err) {
  return p.status == "ok" && p.valid && std::isfinite(p.msMedian) && std::isfinite(err);
}

/// Whether `p` is on the front of error `err` against time over the points `among` accepts.
template <typename Among>
bool onFront(const std::vector<SweepPoint>& points, const SweepPoint& p, double SweepPoint::*err,
             const Among& among) {
  if (!usable(p, p.*err)) return false;
  for (const SweepPoint& q : points) {
    if (&q == &p || !usable(q, q.*err) || !among(q)) continue;
    if (q.msMedian <= p.msMedian && q.*err <= p.*err &&
        (q.msMedian < p.msMedian || q.*err < p.*err))
      return false;
  }
  return true;
}

}  // namespace

void markPareto(std::vector<SweepPoint>& points) {
  for (SweepPoint& p : points) {
    p.pareto = onFront(points, p, &SweepPoint::rmseNearest, [&p](const SweepPoint& q) {
      return q.calibrated == p.calibrated && q.model == p.model && q.plugin == p.plugin;
    });
    p.paretoOverall = onFront(points, p, &SweepPoint::rmseNearest,
                              [&p](const SweepPoint& q) { return q.calibrated == p.calibrated; });
  }
}

namespace {

/// Least-squares slope of ln(error - below) against ln(ms) over the usable points whose error is
/// above `below`; NaN with fewer than two distinct times.
double logSlope(const std::vector<const SweepPoint*>& points, double SweepPoint::*err,
                double below = 0) {
  std::vector<std::pair<double, double>> xy;
  for (const SweepPoint* p : points)
    if (usable(*p, p->*err) && p->msMedian > 0 && p->*err > below)
      xy.emplace_back(std::log(p->msMedian), std::log(p->*err - below));
  if (xy.size() < 2) return NAN;
  double mx = 0, my = 0;
  for (const auto& [x, y] : xy) mx += x, my += y;
  mx /= double(xy.size());
  my /= double(xy.size());
  double sxx = 0, sxy = 0;
  for (const auto& [x, y] : xy) sxx += (x - mx) * (x - mx), sxy += (x - mx) * (y - my);
  return sxx > 1e-12 ? sxy / sxx : NAN;
}

std::string mm(double m) {
  std::ostringstream s;
  s.precision(3);
  s << 1e3 * m << " mm";
  return s.str();
}

std::string fixed(double v, int digits) {
  std::ostringstream s;
  s.setf(std::ios::fixed);
  s.precision(digits);
  s << v;
  return s.str();
}

/// The usable points of `curve` on error `err`, and those of them on its front, by time.
void validAndFront(const std::vector<const SweepPoint*>& curve, double SweepPoint::*err,
                   std::vector<const SweepPoint*>& valid, std::vector<const SweepPoint*>& front) {
  valid.clear();
  front.clear();
  for (const SweepPoint* p : curve)
    if (usable(*p, p->*err)) valid.push_back(p);
  for (const SweepPoint* p : valid) {
    bool dominated = false;
    for (const SweepPoint* q : valid)
      if (q != p && q->msMedian <= p->msMedian && q->*err <= p->*err &&
          (q->msMedian < p->msMedian || q->*err < p->*err))
        dominated = true;
    if (!dominated) front.push_back(p);
  }
  std::sort(front.begin(), front.end(),
            [](const SweepPoint* a, const SweepPoint* b) { return a->msMedian < b->msMedian; });
}

/// The line of `curve` along one axis through `through`: the points whose value on the other axis
/// is `through`'s, in the order of increasing cost.
std::vector<const SweepPoint*> alongAxis(const std::vector<const SweepPoint*>& curve,
                                         bool resolution, const SweepPoint& through) {
  const nlohmann::json& other = resolution ? through.effort : through.resolution;
  std::vector<const SweepPoint*> line;
  for (const SweepPoint* p : curve)
    if ((resolution ? p->effort : p->resolution) == other) line.push_back(p);
  return line;
}

/// Aitken's delta-squared limit of three errors falling geometrically; NaN where they do not.
double aitkenLimit(double e1, double e2, double e3) {
  const double d1 = e2 - e1, d2 = e3 - e2;
  return d1 < 0 && d2 < 0 && d2 > d1 ? std::max(0.0, e3 - d2 * d2 / (d2 - d1)) : NAN;
}

/// The floor of one curve (SweepFloor) on error `err`. The most accurate valid point is looked at
/// along each axis: where a costlier value of the axis exists, it bought no accuracy; where the
/// point is at the axis' costliest value, the axis' last step tells whether the error still falls.
SweepFloor curveFloor(const std::vector<const SweepPoint*>& curve, double SweepPoint::*err) {
  SweepFloor f;
  std::vector<const SweepPoint*> valid, front;
  validAndFront(curve, err, valid, front);
  if (valid.size() < 2) {
    f.text = valid.empty() ? "no valid point" : "one valid point: no floor can be told";
    return f;
  }
  f.known = true;
  const SweepPoint& best = *front.back();
  f.ms = best.msMedian;
  std::string fallingAxis, flatWhy;  // flatWhy: why the error stopped falling
  std::vector<const SweepPoint*> fallingLine;
  for (const bool resolution : {true, false}) {
    const std::string& param = resolution ? best.resolutionParam : best.effortParam;
    if (param.empty()) continue;
    const std::vector<const SweepPoint*> line = alongAxis(curve, resolution, best);
    const auto at = std::find(line.begin(), line.end(), &best);
    if (at == line.end()) continue;
    if (at + 1 != line.end()) {  // a costlier value exists and is no more accurate
      flatWhy = "the costlier values of " + param + " past " +
                valueText(resolution ? best.resolution : best.effort) + " buy no accuracy";
      continue;
    }
    const SweepPoint* prev = at == line.begin() ? nullptr : *(at - 1);
    if (!prev || !usable(*prev, prev->*err) || !(prev->*err > 0) || !(best.*err > 0) ||
        !(prev->msMedian > 0) || prev->msMedian == best.msMedian)
      continue;
    const double slope =
        std::log(best.*err / prev->*err) / std::log(best.msMedian / prev->msMedian);
    if (!(slope >= f.lastSlope)) f.lastSlope = slope;  // the steepest (NaN at first)
    if (slope < SweepFloor::kFloorSlope) {
      fallingAxis = param;
      fallingLine.assign(line.begin(), line.end());
    } else if (flatWhy.empty()) {
      flatWhy = "the last step along " + param + " has slope " + fixed(slope, 2);
    }
  }
  f.reached = fallingAxis.empty();
  if (f.reached) {
    f.errorM = best.*err;
    f.text = "floor " + mm(f.errorM) + " at " + fixed(best.msMedian, 3) +
             " ms (the model's error): " +
             (flatWhy.empty() ? "its most accurate point is alone on its axes" : flatWhy);
    return f;
  }
  // Still falling: Aitken's delta-squared over the last three errors along that axis.
  const size_t n = fallingLine.size();
  if (n >= 3 && usable(*fallingLine[n - 3], fallingLine[n - 3]->*err))
    f.estimateM = aitkenLimit(fallingLine[n - 3]->*err, fallingLine[n - 2]->*err, best.*err);
  f.text = "still falling along " + fallingAxis + " (slope " + fixed(f.lastSlope, 2) + " at " +
           fixed(best.msMedian, 3) + " ms, best " + mm(best.*err) + ")" +
           (std::isfinite(f.estimateM) ? "; floor estimated at " + mm(f.estimateM)
                                       : "; no floor in reach of the sweep");
  return f;
}

/// A resolution whose most accurate point costs less than this factor times its coarsest point
/// costs nothing measurable (the timing noise of a sweep's points is about that).
constexpr double kSameCost = 1.1;

/// The descent along one axis' line (SweepMetricSummary::Descent) on error `err`.
SweepMetricSummary::Descent lineDescent(const std::vector<const SweepPoint*>& line,
                                        double SweepPoint::*err) {
  SweepMetricSummary::Descent d;
  std::vector<const SweepPoint*> valid;
  for (const SweepPoint* p : line)
    if (usable(*p, p->*err) && p->msMedian > 0 && p->*err > 0) valid.push_back(p);
  if (valid.size() < 2) return d;
  const auto best = std::min_element(
      valid.begin(), valid.end(),
      [err](const SweepPoint* a, const SweepPoint* b) { return a->*err < b->*err; });
  std::vector<const SweepPoint*> fall(valid.begin(), best + 1);
  d.reached = best + 1 != valid.end();
  double below = 0;  // what is taken off each error before its logarithm
  const size_t n = fall.size();
  if (d.reached) {
    d.floorM = (*best)->*err;
  } else if (n >= 3) {
    d.floorM = aitkenLimit(fall[n - 3]->*err, fall[n - 2]->*err, fall[n - 1]->*err);
    d.estimated = std::isfinite(d.floorM);
    if (d.estimated) below = d.floorM;
  }
  for (const SweepPoint* p : fall) d.points += p->*err > below ? 1 : 0;
  const double msFrom = fall.front()->msMedian, msTo = fall.back()->msMedian;
  const std::string toFloor = d.reached     ? " down to its floor " + mm(d.floorM)
                              : d.estimated ? " toward an estimated floor of " + mm(d.floorM)
                                            : " (still falling, no floor estimated)";
  if (fall.size() == 1) {
    d.text = "no descent: its coarsest resolution is its most accurate (" + mm(d.floorM) + ")";
  } else if (msTo < kSameCost * msFrom) {
    // The most accurate resolution costs no more than the coarsest (the time of the steps
    // elsewhere dominates): a slope against time would only be the timing noise.
    d.text = "falls from " + mm(fall.front()->*err) + " to " + mm(fall.back()->*err) + toFloor +
             " at no extra cost (" + fixed(msFrom, 3) + " to " + fixed(msTo, 3) + " ms)";
    d.sameCost = true;
  } else {
    d.slope = logSlope(fall, err, below);
    if (std::isfinite(d.slope))
      d.text = "slope " + fixed(d.slope, 2) + toFloor + " over " + std::to_string(d.points) +
               " points (" + fixed(msFrom, 3) + " to " + fixed(msTo, 3) + " ms)";
  }
  return d;
}

SweepMetricSummary metricSummary(const std::vector<const SweepPoint*>& curve,
                                 const SweepModelSummary& m, double SweepPoint::*err) {
  SweepMetricSummary s;
  // Along each axis at the other's costliest value: through the curve's last planned point.
  if (!m.resolutionParam.empty() && !curve.empty())
    s.slopeResolution = logSlope(alongAxis(curve, true, *curve.back()), err);
  if (!m.effortParam.empty() && !curve.empty())
    s.slopeEffort = logSlope(alongAxis(curve, false, *curve.back()), err);
  std::vector<const SweepPoint*> valid, front;
  validAndFront(curve, err, valid, front);
  s.slopeFront = logSlope(front, err);
  // The descent: along resolution through the most accurate point, at its effort value.
  if (!m.resolutionParam.empty() && !front.empty())
    s.descent = lineDescent(alongAxis(curve, true, *front.back()), err);
  s.floor = curveFloor(curve, err);
  return s;
}

}  // namespace

std::vector<SweepModelSummary> summariseSweep(const std::vector<SweepPoint>& points) {
  std::vector<SweepModelSummary> out;
  std::vector<std::vector<const SweepPoint*>> curves;
  for (const SweepPoint& p : points) {
    size_t i = 0;
    while (i < out.size() && !(out[i].model == p.model && out[i].plugin == p.plugin &&
                               out[i].calibrated == p.calibrated))
      ++i;
    if (i == out.size()) {
      out.push_back({.model = p.model,
                     .plugin = p.plugin,
                     .calibrated = p.calibrated,
                     .resolutionParam = p.resolutionParam,
                     .effortParam = p.effortParam,
                     .rmse50 = {},  // summed up below
                     .rmseAll = {}});
      curves.emplace_back();
    }
    curves[i].push_back(&p);
    ++out[i].points;
    if (usable(p, p.rmseNearest) || usable(p, p.rmseAll)) ++out[i].validPoints;
  }
  for (size_t i = 0; i < out.size(); ++i) {
    out[i].rmse50 = metricSummary(curves[i], out[i], &SweepPoint::rmseNearest);
    out[i].rmseAll = metricSummary(curves[i], out[i], &SweepPoint::rmseAll);
  }
  return out;
}

namespace {

ojson num(double v) {
  return std::isfinite(v) ? ojson(v) : ojson(nullptr);
}

/// A point of the sweep: a model at one value of each axis (at its calibration for "+cal").
struct Planned {
  std::string model, plugin, label;
  std::string resolutionParam, effortParam;
  json resolution, effort;
  const CalibrationParams* calibration = nullptr;  ///< the "+cal" points'
};

/// The scene's models, each once per point of its axes' grid (and once more per point at its
/// calibration): the scene's new "models" and the planned points, in the same order.
ojson plannedModels(ojson& scene, PluginLoader& loader, const SweepOptions& options,
                    std::vector<Planned>& planned) {
  ojson models = ojson::array();
  const std::string organ = calibrationOrgan(scene.value("organ", ojson::object()));
  for (const auto& m : scene["models"]) {
    const std::string plugin = m.value("plugin", "");
    const std::string modelName = m.value("model", plugin);
    // The axes the plugin declares; none when it does not load (the run then reports why).
    SweepAxes axes;
    try {
      axes = sweepAxes(loader.load(plugin, m.value("model", "")), options.quick);
    } catch (const std::exception&) {
    }
    std::vector<json> resolutions = axes.resolution.values, efforts = axes.effort.values;
    if (resolutions.empty()) resolutions.push_back(nullptr);
    if (efforts.empty()) efforts.push_back(nullptr);
    // With a calibration of this model (--calibration), every point once more at the
    // calibrated parameters (the scene's own values still win): a second curve, "+cal".
    const CalibrationParams* calibration =
        calibrationFor(options.calibrations, plugin, modelName, organ, false);
    for (const bool calibrated : {false, true}) {
      if (calibrated && !calibration) continue;
      for (const json& r : resolutions) {
        for (const json& e : efforts) {
          ojson copy = m;
          if (!copy.contains("params")) copy["params"] = ojson::object();
          if (calibrated) {
            ojson params = ojson::parse(calibration->params.dump());
            for (const auto& [k, pv] : copy["params"].items()) params[k] = pv;
            copy["params"] = params;
          }
          std::string values;
          for (const auto& [param, v] :
               {std::pair{axes.resolution.param, r}, std::pair{axes.effort.param, e}}) {
            if (param.empty()) continue;
            copy["params"][param] = ojson::parse(v.dump());
            values += (values.empty() ? "" : ",") + param + "=" + valueText(v);
          }
          const std::string label =
              modelName + (values.empty() ? "" : "[" + values + "]") + (calibrated ? "+cal" : "");
          copy["label"] = label;
          models.push_back(copy);
          planned.push_back({modelName, plugin, label, axes.resolution.param, axes.effort.param, r,
                             e, calibrated ? calibration : nullptr});
        }
      }
    }
  }
  return models;
}

/// sweep --calibrate: fits each default point of a model with calibratable parameters on the
/// sweep's scene and appends its calibrated twin to `models` and `planned` (the fits live in
/// `fits`, which must outlive the planned points).
void calibrateEachPoint(const ojson& scene, PluginLoader& loader, const SweepOptions& options,
                        ojson& models, std::vector<Planned>& planned,
                        std::deque<CalibrationParams>& fits, Progress* progress) {
  const size_t n = planned.size();
  for (size_t i = 0; i < n; ++i) {
    const Planned p = planned[i];
    if (p.calibration) continue;
    bool calibratable = false;
    try {
      for (const ParamSpec& s : loader.load(p.plugin, models[i].value("model", "")).params)
        calibratable = calibratable || s.calibratable;
    } catch (const std::exception&) {
    }
    if (!calibratable) continue;
    const fs::path dir = options.outDir / "calibrate" / ("point_" + std::to_string(i));
    ojson one = scene;
    one["models"] = ojson::array({models[i]});
    std::error_code ec;
    fs::create_directories(dir, ec);
    writeFileAtomic(dir / "scene.json", one.dump(2) + "\n");
    CalibrateOptions co;
    co.train = {(dir / "scene.json").string()};
    co.plugin = p.plugin;
    co.model = models[i].value("model", "");
    co.outDir = dir;
    co.metric = options.calibrateMetric;
    co.budget = options.calibrateBudget;
    co.label = "sweep --calibrate, point " + p.label;
    co.cases = options.cases;
    co.cases.child = options.calibrateChild;
    if (co.cases.cacheDir && co.cases.cacheDir->empty())
      co.cases.cacheDir = options.outDir / "cache";
    if (progress) {
      progress->addTotal(1);
      progress->start(p.label + " calibrating");
    }
    std::string outcome = "calibrated";
    try {
      runCalibration(loader, co, nullptr);
      fits.push_back(readCalibrationFile((dir / "calibration.json").string()));
    } catch (const std::exception& e) {
      outcome = std::string("not calibrated: ") + e.what();
    }
    if (progress) progress->finish(p.label + " calibrating", outcome);
    if (outcome != "calibrated") continue;
    const CalibrationParams& fit = fits.back();
    ojson twin = models[i];
    for (const auto& [k, v] : fit.params.items()) twin["params"][k] = ojson::parse(v.dump());
    Planned cal = p;
    cal.label = p.label + "+cal";
    cal.calibration = &fit;
    twin["label"] = cal.label;
    models.push_back(twin);
    planned.push_back(cal);
  }
}

/// A point's outcome from the case that ran it.
void fillPoint(SweepPoint& s, const Planned& planned, const CaseResult& c) {
  const RunRecord* r = c.run(s.label);
  // A calibrated point whose other parameters differ from those of the fit (the knob apart).
  const CalibrationParams* calibration = planned.calibration;
  if (r && calibration)
    s.note = calibratedRunNote(*calibration, r->params, {s.resolutionParam, s.effortParam});
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

/// What the "nearest" vertices of rmse_50 are nearest to in this scene, for the plots' labels.
std::string interactionName(const Scene& scene) {
  for (const ToolSpec& t : scene.tools)
    if (t.type == ToolType::Grasper) return "grasp";
  if (!scene.tools.empty()) return "tool";
  if (!scene.plates.empty()) return "plate";
  return "load";
}

/// sweep.json and sweep.csv.
void writeSweepFiles(const std::vector<SweepPoint>& points,
                     const std::vector<std::string>& pointResults, const std::string& sceneFile,
                     const Scene& parsed, const std::string& refStatus, const std::string& results,
                     const std::optional<ConvergenceResult>& check, const SweepOptions& options) {
  ojson doc;
  doc["format"] = "deformbench-sweep/1";
  doc["scene"] = {{"name", parsed.name}, {"file", sceneFile}, {"sha256", parsed.sha256}};
  doc["reference"] = parsed.reference->model;
  doc["reference_status"] = refStatus;
  // The reference's own discretisation error (its cached check, `converge --of-reference`): the
  // yardstick's uncertainty beside the models' floors; null when none is cached.
  doc["reference_check"] = nullptr;
  if (check) {
    ojson levels = ojson::array();
    for (const ConvergenceLevelResult& l : check->levels)
      levels.push_back({{"elements", l.elements}, {"h_m", l.h}, {"status", l.status}});
    const std::string warning = convergenceWarning(*check);
    doc["reference_check"] = {
        {"summary", convergenceSummary(*check)},
        {"warning", warning.empty() ? ojson(nullptr) : ojson(warning)},
        {"converged", check->converged},
        {"relative_error", num(check->relativeError)},
        {"bound_relative", num(check->boundRelative)},
        {"reason", check->reason.empty() ? ojson(nullptr) : ojson(check->reason)},
        {"levels", levels}};
  }
  doc["quick"] = options.quick;
  doc["haptic_budget_ms"] = 1.0;
  doc["nearest_to"] = interactionName(parsed);
  doc["results"] = results;
  doc["points"] = ojson::array();
  std::ostringstream csv;
  csv << "model,plugin,label,param,value,status,ms_median,ms_p95,rmse_50_m,rmse_all_m,max_m,"
         "loss_ratio,pareto,calibrated,resolution_param,resolution,effort_param,effort,"
         "pareto_overall\n";
  const auto axis = [](const std::string& param, const json& v) {
    return param.empty() ? ojson(nullptr)
                         : ojson{{"param", param}, {"value", ojson::parse(v.dump())}};
  };
  for (size_t i = 0; i < points.size(); ++i) {
    const SweepPoint& p = points[i];
    doc["points"].push_back({{"model", p.model},
                             {"plugin", p.plugin},
                             {"label", p.label},
                             {"param", p.param},
                             {"value", ojson::parse(p.value.dump())},
                             {"resolution", axis(p.resolutionParam, p.resolution)},
                             {"effort", axis(p.effortParam, p.effort)},
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
                             {"pareto_overall", p.paretoOverall},
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
    const auto text = [](const json& v) { return v.is_null() ? "" : valueText(v); };
    const auto yes = [](bool b) { return b ? "yes" : "no"; };
    csv << p.model << ',' << p.plugin << ",\"" << p.label << "\"," << p.param << ','
        << text(p.value) << ",\"" << p.status << "\"," << f(p.msMedian) << ',' << f(p.msP95) << ','
        << f(p.rmseNearest) << ',' << f(p.rmseAll) << ',' << f(p.max) << ',' << f(p.lossRatio)
        << ',' << yes(p.pareto) << ',' << yes(p.calibrated) << ',' << p.resolutionParam << ','
        << text(p.resolution) << ',' << p.effortParam << ',' << text(p.effort) << ','
        << yes(p.paretoOverall) << '\n';
  }
  doc["models"] = ojson::array();
  for (const SweepModelSummary& m : summariseSweep(points)) {
    const auto metric = [](const SweepMetricSummary& s) {
      const SweepFloor& f = s.floor;
      return ojson{{"slope_resolution", num(s.slopeResolution)},
                   {"slope_effort", num(s.slopeEffort)},
                   {"slope_front", num(s.slopeFront)},
                   {"descent_resolution",
                    {{"slope", num(s.descent.slope)},
                     {"floor_m", num(s.descent.floorM)},
                     {"reached", s.descent.reached},
                     {"estimated", s.descent.estimated},
                     {"same_cost", s.descent.sameCost},
                     {"points", s.descent.points},
                     {"text", s.descent.text}}},
                   {"floor",
                    {{"known", f.known},
                     {"reached", f.reached},
                     {"error_m", num(f.errorM)},
                     {"at_ms", num(f.ms)},
                     {"estimate_m", num(f.estimateM)},
                     {"last_slope", num(f.lastSlope)},
                     {"text", f.text}}}};
    };
    doc["models"].push_back({{"model", m.model},
                             {"plugin", m.plugin},
                             {"calibrated", m.calibrated},
                             {"resolution_param", m.resolutionParam},
                             {"effort_param", m.effortParam},
                             {"points", m.points},
                             {"valid_points", m.validPoints},
                             {"rmse_50", metric(m.rmse50)},
                             {"rmse_all", metric(m.rmseAll)}});
  }
  writeFileAtomic(options.outDir / "sweep.json", doc.dump(2) + "\n");
  writeFileAtomic(options.outDir / "sweep.csv", csv.str());
}

}  // namespace

std::vector<SweepPoint> runSweep(const std::string& sceneFile, PluginLoader& loader,
                                 const SweepOptions& options, Progress* progress,
                                 std::optional<ConvergenceResult>* referenceCheck) {
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
  ojson models = plannedModels(scene, loader, options, planned);
  std::deque<CalibrationParams> fits;  // --calibrate's, one per calibrated point
  if (options.calibrate)
    calibrateEachPoint(scene, loader, options, models, planned, fits, progress);
  scene["models"] = models;
  // The points' outcomes (fillPoint), the reference's status, the results files.
  std::vector<SweepPoint> points;
  for (const Planned& p : planned) {
    // The outcome (status, timings, errors, validity, note) is filled in by fillPoint.
    points.push_back({.model = p.model,
                      .plugin = p.plugin,
                      .label = p.label,
                      .resolutionParam = p.resolutionParam,
                      .effortParam = p.effortParam,
                      .resolution = p.resolution,
                      .effort = p.effort,
                      .param = p.resolutionParam.empty() ? p.effortParam : p.resolutionParam,
                      .value = p.resolutionParam.empty() ? p.effort : p.resolution,
                      .status = {},
                      .invalidReason = {},
                      .calibrated = p.calibration != nullptr,
                      .note = {}});
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

  const std::optional<ConvergenceResult> check =
      cachedReferenceCheck(sceneFile, loader, options.cases.cacheDir);
  writeSweepFiles(points, pointResults, sceneFile, parsed, refStatus, results, check, options);
  if (referenceCheck) *referenceCheck = check;
  return points;
}

}  // namespace deform::harness
