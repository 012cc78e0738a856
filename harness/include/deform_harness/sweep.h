// deformbench harness: error against run time. Each model of a scene is swept over its accuracy
// knob (a table of plugin name -> parameter and values, as data; a plugin without an entry gives
// the one point of its scene parameters), every point runs through the loader and the runner
// against the scene's reference, and the points with their Pareto front (no other point is both
// faster and more accurate in rmse_50) are written as DIR/sweep.json and DIR/sweep.csv; the plot
// (harness/scripts/plot_sweep.py) is DIR/sweep.png.
#pragma once

#include <deform/sdk/registry.h>
#include <deform_harness/cases.h>
#include <deform_harness/progress.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace deform::harness {

/// An accuracy knob: the parameter and the values swept.
struct SweepKnob {
  std::string param;
  std::vector<nlohmann::json> values;
};

/// The knob a model declares (ModelInfo::knob; "" param when it has none). quick: its quick
/// values.
SweepKnob sweepKnob(const ModelInfo& info, bool quick);

struct SweepPoint {
  std::string model, plugin, label, param;
  nlohmann::json value;
  std::string status;
  double msMedian = NAN, msP95 = NAN;
  double rmseNearest = NAN;  ///< rmse_50 (or the scene's last nearest k), m
  double rmseAll = NAN, max = NAN, lossRatio = NAN;
  bool valid = true;          ///< the run did what the scene asked (DESIGN "Metrics")
  std::string invalidReason;  ///< when !valid
  bool pareto = false;
  bool calibrated = false;  ///< run at a --calibration file's parameters (its own front)
  /// Calibrated points: calibrationDifferenceNote() (the knob apart), "" when none.
  std::string note;
};

/// Marks the points on the Pareto front of (msMedian, rmseNearest): ok, valid points with an
/// error. Invalid points are listed, never ranked. Calibrated and default points form separate
/// fronts.
void markPareto(std::vector<SweepPoint>& points);

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
};

/// Runs the sweep of a scene; writes sweep.json and sweep.csv (and the scene it ran into
/// DIR/sweep_scene.json). Throws InputError for a bad scene.
std::vector<SweepPoint> runSweep(const std::string& sceneFile, PluginLoader& loader,
                                 const SweepOptions& options, Progress* progress);

}  // namespace deform::harness
