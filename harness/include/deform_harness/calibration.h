// deformbench harness: calibrating a model's calibratable parameters (ParamSpec::calibratable) to
// the reference of training scenes, `deformbench calibrate` (issue G2).
//
// The objective of a parameter set (a "trial") is the metric (rmse_all, rmse_50 or loss_ratio)
// of the model against each training scene's reference, averaged over the scenes. Each model
// run is a case (cases.h): a scene holding the model and the scene's reference, run by
// `deformbench run --reuse-reference` in a child process, so a crash, a hang or a divergence is
// a failed run; such a run scores the worst value of its scene (10 x its error at the defaults,
// or 1 m / a loss ratio of 100 when the defaults failed too) and the search goes on. The
// reference of each scene is solved by the first run of that scene and read from the cache
// (runner.h, BenchmarkOptions::reuseReference) by every later one.
//
// The search is in the unit box of the parameters' declared scales (log or linear between
// their calibration bounds): trial 0 is the model's defaults (the scene's own values where a
// training scene writes them), then a global stage of Halton points (quasi-random, so the run
// is deterministic; evaluated as one batch, so `--jobs N` runs N model runs at once), then
// NLopt's BOBYQA (COBYLA for one parameter) from the best point so far, bounded, until the
// budget of trials is spent or the step falls below 1e-3 of the box. A trial already evaluated
// is not run again.
#pragma once

#include <deform/engine/plugin_loader.h>
#include <deform_harness/cases.h>
#include <deform_harness/progress.h>

#include <filesystem>
#include <functional>
#include <map>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace deform::harness {

// ------------------------------------------------------------------------ the optimiser layer

/// One calibrated dimension: a parameter between its bounds in its scale.
struct CalibDimension {
  std::string key;
  double lo = 0, hi = 1;
  bool log = false;
  /// Log of the distance to 1/2 (a Poisson ratio, lo < hi < 0.5): equal steps from 0.3 to 0.49,
  /// 0.499 and 0.4999, where the material's response changes most.
  bool logToHalf = false;

  /// Unit coordinate u in [0, 1] -> parameter value, and back (clamped to the box).
  double value(double u) const;
  double unit(double value) const;
};

/// A parameter fitted within this fraction of its range (in its own scale) of a bound is "at the
/// bound": calibration.json's `at_bound` and a warning.
inline constexpr double kAtBoundFraction = 0.01;

/// The fitted parameters at a bound: key -> "min" | "max".
std::map<std::string, std::string> fittedAtBound(const std::vector<CalibDimension>& dims,
                                                 const std::vector<double>& values);

/// A length (a parameter in m, e.g. a membrane thickness) is at most the organ's smallest
/// extent: lowers those upper bounds to `extent` (m) and returns key -> why, for the file.
std::map<std::string, std::string> limitLengthsToOrgan(std::vector<CalibDimension>& dims,
                                                       const ModelInfo& info, double extent);

/// Objective of many trials at once (parameter values, one vector per trial): one value each,
/// finite (the caller scores failures).
using BatchObjective = std::function<std::vector<double>(const std::vector<std::vector<double>>&)>;

struct OptimiserOptions {
  int budget = 40;        ///< trials at most (the start included)
  int globalPoints = -1;  ///< Halton points of the global stage; < 0: automatic
  double xtol = 1e-3;     ///< local stage stops when its step is below this (unit box)
};

struct OptimiserResult {
  std::vector<double> best;  ///< parameter values
  double bestValue = 0;
  int evaluations = 0;  ///< distinct trials run
  int globalPoints = 0;
  std::string localMethod;  ///< "bobyqa", "cobyla" or "" when no budget was left
};

/// Minimises `objective` over the box of `dims` from `start` (parameter values, clamped into the
/// box): start, then a batch of Halton points, then a local NLopt stage from the best. onTrial
/// (may be empty) is called after every trial with its values and objective.
OptimiserResult minimiseInBox(
    const std::vector<CalibDimension>& dims, const std::vector<double>& start,
    const BatchObjective& objective, const OptimiserOptions& options,
    const std::function<void(const std::vector<double>&, double)>& onTrial = {});

/// The i-th point (i >= 1) of the Halton sequence in [0, 1)^n (bases 2, 3, 5, ...).
std::vector<double> haltonPoint(long long i, int n);

// ------------------------------------------------------------------------ the command

/// rmse_all, rmse_50, loss_ratio: against the scene's reference. marker_rms: the markers' RMS
/// distance to the scene's measured positions (markers.measured) after removing the
/// least-squares rigid translation at each measured instant, averaged over those instants
/// (results.json's rms_error_translation_m): against a physical measurement, no reference.
enum class CalibMetric { RmseAll, Rmse50, LossRatio, MarkerRms };

/// "rmse_all" | "rmse_50" | "loss_ratio" | "marker_rms"; false on anything else.
bool calibMetricFromName(const std::string& name, CalibMetric& out);
const char* calibMetricName(CalibMetric m);

struct CalibrateOptions {
  std::vector<std::string> train, validate;  ///< scene files
  std::string plugin;                        ///< --model: a plugin name
  std::string model;                         ///< model within the plugin ("" = the plugin's)
  std::vector<std::string> params;           ///< --param: a subset of the calibratable ones
  /// --material: the organ's "young" and/or "poisson" fitted too (marker_rms only: fitting the
  /// material to a reference made of it would be circular). Bounds: E / 10 .. 10 E (log) around
  /// the first training scene's E; nu 0.3 .. 0.4999 (logToHalf).
  std::vector<std::string> material;
  /// --truth-cube LEVEL (1-based; 0: none): train on that compression level of the Truth Cube
  /// (truthCubeLevelScene() of tables.h, written to DIR/scenes/), validate on every other level,
  /// metric marker_rms. calibration.json keeps {"level", "strain", "contact", "data"} as
  /// "truth_cube".
  int truthCubeLevel = 0;
  std::string truthCubeData;                ///< the bead file ("": the shipped data)
  std::string truthCubeContact = "bonded";  ///< the plate: "bonded" or "sliding"
  std::filesystem::path outDir;
  CalibMetric metric = CalibMetric::RmseAll;
  int budget = 40;
  std::string label;  ///< free text copied to calibration.json
  /// Cache folder, child options (required: trials always run in children) and dispatcher.
  CaseOptions cases;
};

/// Checks the input (throws InputError, one line): the plugin loads and has calibratable
/// parameters (or the --param keys are among them), budget >= 1, every scene parses and has a
/// reference (marker_rms: measured marker positions instead), rmse_50 needs nearest 50 in every
/// scene. Then runs the calibration, writes
/// DIR/calibration.json (format deformbench-calibration/1) and DIR/trials.csv (one row per
/// trial) and returns the calibration.json document. progress may be null.
nlohmann::ordered_json runCalibration(PluginLoader& loader, const CalibrateOptions& options,
                                      Progress* progress);

/// Reads a calibration.json (--calibration FILE): throws InputError naming the file and the
/// problem.
CalibrationParams readCalibrationFile(const std::string& file);

/// Applies calibrations to the models of a scene (JSON) for the long commands (tables, sweep):
/// each model whose plugin (and model) a calibration names gets a twin labelled "LABEL+cal"
/// (LABEL: its label, or its plugin name) holding the calibrated values under its own written
/// params. Returns the labels added as (original label, calibrated label).
std::vector<std::pair<std::string, std::string>> addCalibratedTwins(
    nlohmann::ordered_json& scene, const std::vector<CalibrationParams>& calibrations);

}  // namespace deform::harness
