// deformbench harness: error against run time. Each model of a scene is swept over the grid of
// its two cost axes (ModelInfo::resolution x ModelInfo::effort; the single ModelInfo::knob of an
// older plugin; the one point of its scene parameters when it declares none), every point runs
// through the loader and the runner against the scene's reference, and the points with each
// model's Pareto front (no other point of the model is both faster and more accurate in rmse_50)
// and each model's slopes and floor (summariseSweep) are written as DIR/sweep.json and
// DIR/sweep.csv; the plot (harness/scripts/plot_sweep.py) is DIR/sweep.png.
#pragma once

#include <deform/sdk/registry.h>
#include <deform_harness/calibration.h>
#include <deform_harness/cases.h>
#include <deform_harness/convergence.h>
#include <deform_harness/progress.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace deform::harness {

/// A cost axis: the parameter and the values swept, in the order of increasing cost.
struct SweepKnob {
  std::string param;
  std::vector<nlohmann::json> values;
};

/// The knob a model declares (ModelInfo::knob; "" param when it has none). quick: its quick
/// values.
SweepKnob sweepKnob(const ModelInfo& info, bool quick);

/// The two axes a model is swept over: ModelInfo::resolution and ::effort; for a plugin that
/// declares neither, its knob as the effort axis. quick: their quick values.
struct SweepAxes {
  SweepKnob resolution, effort;
};
SweepAxes sweepAxes(const ModelInfo& info, bool quick);

struct SweepPoint {
  std::string model, plugin, label;
  /// The point's values on the axes ("" param: the model has no such axis).
  std::string resolutionParam, effortParam;
  nlohmann::json resolution, effort;
  /// The first axis the model has (resolution, else effort): the single knob of sweep.json
  /// before the two axes.
  std::string param;
  nlohmann::json value;
  std::string status;
  double msMedian = NAN, msP95 = NAN;
  double rmseNearest = NAN;  ///< rmse_50 (or the scene's last nearest k), m
  double rmseAll = NAN, max = NAN, lossRatio = NAN;
  bool valid = true;           ///< the run did what the scene asked (DESIGN "Metrics")
  std::string invalidReason;   ///< when !valid
  bool pareto = false;         ///< on its model's front (default and calibrated apart)
  bool paretoOverall = false;  ///< on the front of every model's points
  bool calibrated = false;     ///< run at a --calibration file's parameters (its own front)
  /// Calibrated points: calibratedRunNote() (the knob apart), "" when it says nothing.
  std::string note;
};

/// Marks the points on the Pareto fronts of (msMedian, rmseNearest): ok, valid points with an
/// error. `pareto`: the front of the point's model; `paretoOverall`: the front over all models.
/// Invalid points are listed, never ranked. Calibrated and default points form separate fronts.
void markPareto(std::vector<SweepPoint>& points);

/// Where a model's error stops falling, on one metric. The model's most accurate valid point is
/// looked at along each of its axes: the floor is reached when, along every axis, either a
/// costlier value exists (and so bought no accuracy) or the last step to the point falls by less
/// than kFloorSlope in d ln(error) / d ln(ms); `errorM` is then the point's error. Otherwise the
/// error still falls along an axis, and `estimateM` extrapolates the last three errors along it
/// (Aitken's delta-squared) where they fall geometrically.
struct SweepFloor {
  static constexpr double kFloorSlope = -0.1;
  bool known = false;    ///< at least two valid points
  bool reached = false;  ///< the error stopped falling within the sweep
  double errorM = NAN, ms = NAN;
  double estimateM = NAN;  ///< not reached: the extrapolated floor (NaN when none)
  double lastSlope = NAN;  ///< the steepest last step along an axis ending at the best point
  std::string text;        ///< one line: "floor 1.2 mm (the model's error) ..."
};

/// One model's curve (its default or its calibrated points) on one metric.
struct SweepMetricSummary {
  /// Least-squares d ln(error) / d ln(ms): along the resolution axis (the points at the costliest
  /// effort value), along the effort axis (at the finest resolution) and over the front. NaN
  /// where fewer than two valid points lie on the line.
  double slopeResolution = NAN, slopeEffort = NAN, slopeFront = NAN;
  /// The descent along the resolution axis through the most accurate point (at its effort
  /// value), from the line's coarsest point to its most accurate one. Where a finer resolution is
  /// less accurate (`reached`), the slope of ln(error) up to the most accurate point; where the
  /// error still falls at the finest, of ln(error - floor) with the floor extrapolated (Aitken's
  /// delta-squared over the last three errors) when one can be, else of ln(error). So a
  /// discretisation converging toward the model's own error reads as its rate of approach, with
  /// the floor it approaches beside it.
  struct Descent {
    double slope = NAN;
    double floorM = NAN;  ///< the most accurate error (reached), the estimate, or NaN (none)
    bool reached = false, estimated = false;
    /// The most accurate point costs less than 1.1 times the coarsest: the resolution costs
    /// nothing measurable and no slope is given (NaN); the text gives the fall.
    bool sameCost = false;
    int points = 0;    ///< points fitted
    std::string text;  ///< one line: "slope -0.43 toward an estimated floor of 0.907 mm"
  } descent;
  SweepFloor floor;
};

struct SweepModelSummary {
  std::string model, plugin;
  bool calibrated = false;
  std::string resolutionParam, effortParam;
  int points = 0, validPoints = 0;
  SweepMetricSummary rmse50, rmseAll;
};

/// Each model's slopes and floor, one summary per model and calibration, in the points' order.
std::vector<SweepModelSummary> summariseSweep(const std::vector<SweepPoint>& points);

struct SweepOptions {
  bool quick = false;
  std::filesystem::path outDir;
  /// cases.child unset: one scene with every point, in this process (runs/results.json). Set:
  /// each point is a child case (scenes/point_<i>.json, runs/point_<i>/) handed to
  /// cases.dispatcher; the first loadable point solves the reference and caches it (dispatch
  /// stage 0), the others read it back (stage 1, `run --reuse-reference`). The points are the
  /// same either way, timings apart.
  CaseOptions cases;
  /// --calibration: each calibrated model is swept twice, at its defaults and calibrated.
  std::vector<CalibrationParams> calibrations;
  /// --calibrate: every default point of a model with calibratable parameters is fitted on the
  /// sweep's scene (runCalibration with the model at that point: `calibrateBudget` trials on
  /// `calibrateMetric`, DIR/calibrate/point_<i>/) and run once more at its fit, "+cal": what a
  /// user gets for the time when each configuration is tuned. The trials run as children
  /// (`calibrateChild`) through cases.dispatcher and share the scene's cached reference.
  bool calibrate = false;
  int calibrateBudget = 12;
  CalibMetric calibrateMetric = CalibMetric::Rmse50;
  std::optional<ChildCaseOptions> calibrateChild;
};

/// Runs the sweep of a scene; writes sweep.json and sweep.csv (and the scene it ran into
/// DIR/sweep_scene.json). Throws InputError for a bad scene. referenceCheck, if given, gets the
/// reference's cached check that sweep.json's reference_check holds (cachedReferenceCheck).
std::vector<SweepPoint> runSweep(const std::string& sceneFile, PluginLoader& loader,
                                 const SweepOptions& options, Progress* progress,
                                 std::optional<ConvergenceResult>* referenceCheck = nullptr);

}  // namespace deform::harness
