// deformbench harness: the record of one model's run (status, timings, surfaces, validity,
// errors), filled by the runner and written by the results writer.
#pragma once

#include <deform/sdk/cache.h>
#include <deform/sdk/model.h>
#include <deform_harness/metrics.h>

#include <nlohmann/json.hpp>

#include <map>
#include <optional>
#include <string>
#include <vector>

namespace deform::harness {

enum class RunStatus { Ok, Diverged, Unsupported, Failed };
/// "ok" | "diverged" | "unsupported" | "failed" (as in results.json).
const char* statusName(RunStatus s);

/// A surface kept at some instant of a run.
struct SurfaceSnapshot {
  int step = 0;   ///< steps completed
  Real time = 0;  ///< s
  MatX3 positions;
  /// Compared instants only (else empty): the force (N) the tissue exerts on each plate of the
  /// scene, in scene order, when the model reports grasp forces (reaction_force).
  std::vector<Vec3> plateForces;
  /// Compared instants only, when the run's markers are bound (RunRecord::markerStatus "ok"):
  /// the markers' positions (#markers by 3, m).
  MatX3 markers;
  /// With measured marker positions at this instant: RMS and largest distance (m) of the
  /// model's markers to them; -1 otherwise.
  double markerRms = -1, markerMax = -1;
  /// The same RMS after the least-squares rigid translation between the model's markers and the
  /// measured ones is removed (their mean difference): the registration of scans that were not
  /// registered to one another; -1 without measured positions.
  double markerRmsTranslation = -1;
};

/// The surface at an instant, with nothing else measured yet.
inline SurfaceSnapshot snapshotAt(int step, Real time, const MatX3& positions) {
  SurfaceSnapshot s;
  s.step = step;
  s.time = time;
  s.positions = positions;
  return s;
}

/// A snapshot in the byte records of run isolation and the solve cache (all its fields).
void putSnapshotExtras(ByteWriter& w, const SurfaceSnapshot& s);
SurfaceSnapshot getSnapshotExtras(ByteReader& r);

/// One grasp reaction force reported by a model.
struct GraspForceSample {
  int step = 0;  ///< steps completed
  int tool = 0;
  Vec3 force = Vec3::Zero();  ///< N
};

/// The force the hand exerts on a dynamic instrument over one step (virtual coupling).
struct HandForceSample {
  int step = 0;                  ///< steps completed
  int instrument = 0;            ///< index into RunRecord::instruments
  Vec3 force = Vec3::Zero();     ///< N
  Vec3 position = Vec3::Zero();  ///< m, the instrument at the end of the step
};

struct RunRecord {
  std::string plugin;  ///< plugin file name
  std::string model;   ///< model name within the plugin
  std::string label;   ///< unique within a scene run
  std::string jsonPath;
  bool isReference = false;
  nlohmann::json params = nlohmann::json::object();  ///< resolved

  RunStatus status = RunStatus::Ok;
  std::string message;
  std::vector<std::string> notes;  ///< warnings that do not change the status
  std::string calibration;         ///< the calibration file of its parameters ("" when none)

  Counts counts;
  double precomputeS = 0;  ///< wall time of init(), s
  int steps = 0;           ///< steps completed (the step that diverged included)
  int plannedSteps = 0;
  int solvedSteps = -1;  ///< quasi-static at compared instants: step() calls made; -1 otherwise
  std::vector<double> stepMs;  ///< wall time of every step() call, ms
  StepStats stepStats;
  std::map<std::string, double> phaseMs;  ///< median per phase over the steps after warm-up
  NumericCounters numeric;
  int fixedNodes = 0;  ///< model nodes pinned by the fixed region (fixed_nodes in results.json)
  bool fixedRegion = false;  ///< the organ is clamped (fixed boxes or vertices; set by simulate())
  std::vector<int> emptyGrasps;
  /// RMS distance (m) of the grasped surface points to their targets over every step with a
  /// grasp in force (at the end of each step); -1 when no grasp was in force.
  double graspResidual = -1;
  /// Largest tool travel while grasping (m): the scale of the residual validity test.
  double graspTravel = 0;
  /// "compare_at": "equilibrium": when the model settled (s); nullopt when it did not (by the
  /// cap) or the scene does not ask. Quasi-static models are at equilibrium at every solve.
  std::optional<double> settledAt;
  bool equilibrium = false;  ///< the scene compared at equilibrium (settledAt is meaningful)
  /// Validity (DESIGN "Metrics"): false with a reason when the run did not do what the scene
  /// asked: its grasp held nothing, its grasp residual exceeds 10% of the tool's travel, it did
  /// not settle, it did not move although the scene loads the organ, its solver gave up on a
  /// solve (numeric unconverged_steps), it inverted over 0.5% of its tets (numeric inverted_tets
  /// against counts elements), its support held none of its nodes or let the clamped surface
  /// move over 5% of the largest displacement (supportProblem()), or it diverged (an object or
  /// instrument included) / failed / was unsupported. Set by assessValidity(); runModel() sets it
  /// on every path, its early returns included.
  bool valid = true;
  std::string invalidReason;
  /// Whether the errors of this (model) run are against a valid reference: nullopt when the
  /// scene run had no reference; false (with referenceInvalidReason) when the reference is
  /// invalid, failed, diverged or unsupported. Set by computeRunErrors().
  std::optional<bool> referenceValid;
  std::string referenceInvalidReason;
  /// Largest surface displacement from rest (m) at the compared instants and the end; -1 when not
  /// measured. A run whose scene loads the organ (gravity, a load, a moving grasp) and that moves
  /// less than motionFloor is invalid ("did not move": a frozen solver).
  double peakDisplacement = -1;
  double motionFloor = 0;  ///< m, 1e-6 of the organ's bounding-box diagonal; 0: nothing asked
  /// m, largest displacement of the organ's surface vertices inside the fixed region over the
  /// final and compared surfaces (0 when it stays below 1e-6 of the diagonal or nothing is
  /// fixed). More than 5% of peakDisplacement adds a note ("the fixed region did not hold") and
  /// makes the run invalid.
  double fixedDrift = 0;
  /// The largest motion the scene prescribes (m): the grasps' travel, a pin_head's pin travel.
  /// 0 when none. See outrunNote().
  double prescribedMotion = 0;
  std::vector<Cache::Event> cacheEvents;

  MatX3 finalSurface;                     ///< after the last completed step
  MatX3i finalFaces;                      ///< the organ's faces unless the model cut them
  std::vector<SurfaceSnapshot> compared;  ///< at the scene's compared instants, in order
  std::vector<SurfaceSnapshot> series;    ///< every N steps ("output": "every:N")
  std::vector<GraspForceSample> graspForces;
  /// The scene's markers for this run: "" (the scene has none), "ok" (bound: positions in
  /// compared[].markers) or "unsupported" (markerReason says why; the run itself goes on).
  std::string markerStatus;
  std::string markerReason;
  std::vector<std::string> worlds;       ///< Bullet / ODE worlds the run created (--explain)
  std::vector<std::string> instruments;  ///< dynamic instruments ("tools/0"), hand force order
  std::vector<HandForceSample> handForces;
  Real dt = 0;                     ///< s, the scene's step (hand force times)
  std::vector<Vec3> objectsFinal;  ///< m, rigid objects at the end of the run
  long long contactPairs = -1;     ///< broadphase pairs tested (-1: no contact world)
  long long contacts = -1;         ///< penetrating proxies found

  std::optional<ErrorMetrics> error;
  std::string referenceModel;  ///< model name of the reference the error is against

  std::string finalSurfaceFile;  ///< relative to the output folder; empty if not written
  std::string seriesFile;        ///< .pvd relative to the output folder
  std::string graspForceFile;    ///< .csv relative to the output folder
};

}  // namespace deform::harness
