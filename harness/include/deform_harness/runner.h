// deformbench harness: running models on a scene. runModel() runs one model (resolve, create,
// init, step with timing and divergence checks) and never throws for the model's own trouble:
// the record's status says what happened. planRuns() / runBenchmark() drive a whole scene: every
// plugin is loaded and every parameter validated BEFORE anything runs, so bad input ends the
// program before any output exists.
#pragma once

#include <deform/engine/plugin_loader.h>
#include <deform/engine/scene.h>
#include <deform/geometry/mesh_check.h>
#include <deform/sdk/cache.h>
#include <deform_harness/metrics.h>
#include <deform_harness/run_record.h>

#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <vector>

namespace deform::harness {

struct RunOptions {
  int maxSteps = -1;             ///< < 0: scene.numSteps()
  double warmupFraction = 0.05;  ///< steps excluded from the statistics (still simulated)
  bool keepSeries = true;        ///< honour "every:N"
  bool recordGraspForces = true;
  /// Quasi-static stepping (docs/scene-format.md: a quasi-static reference is solved only at the
  /// compared instants). true: the interaction is prepared every step (so grasps attach when the
  /// jaws close) but model.step() is called only at the steps that end at a compared instant and
  /// at the steps that end just before a grasper's jaws close (so the attachment sees the solved
  /// state at that moment). false: step() every step. nullopt: runModel() decides with
  /// solveOnlyAtComparedInstants(); simulate() alone treats nullopt as false.
  std::optional<bool> quasiStaticAtComparedInstants;
  /// Called by simulate() every 4096 steps with (steps done, steps planned): progress of long
  /// runs (runBenchmark() prints it when a run takes long). May be empty.
  std::function<void(int, int)> onStep;
};

/// Whether runModel() solves a model only at the compared instants: it has the quasi_static
/// capability, and (a convention for plugins that offer both) its resolved parameters do not
/// include a choice "solve" set to anything other than "quasi_static".
bool solveOnlyAtComparedInstants(const ModelInfo& info, const ParamValues& params);

/// Steps (counts of completed steps, ascending) after which a quasi-static model is solved:
/// the compared steps, and for each grasper whose jaws close at the start of step k > 0 the
/// step k (the state the attachment is taken from); every step when the scene has dynamics
/// (Scene::needsDynamics(): its ODE bodies take the tissue's reaction each step). lastStep as in
/// comparedSteps().
std::vector<int> quasiStaticSolveSteps(const Scene& scene, int lastStep = -1);

/// Steps (counts of completed steps) at which the scene compares surfaces: round(t / dt) for
/// each compare_at instant up to lastStep, else lastStep itself. lastStep < 0: the scene's last.
std::vector<int> comparedSteps(const Scene& scene, int lastStep = -1);

/// Why a model cannot run this scene ("" when it can): a grasper without the grasp capability,
/// a probe or a rigid object without contact, a rigid object without contact_reaction, a grasper
/// with dynamics without reaction_force, a load without point_force.
std::string unsupportedReason(const ModelInfo& info, const Scene& scene);

/// A record of the model's run before it starts: names, resolved params, planned steps.
RunRecord newRunRecord(const ModelInfo& info, const ParamValues& params, const Scene& scene,
                       const RunOptions& options);

/// Runs one model from creation to the end of the scene. Fills every field but the output files
/// and the error. Model exceptions become status Failed; NaN/Inf or a surface leaving the
/// divergence box becomes Diverged (the run stops at that step).
RunRecord runModel(const ModelInfo& info, const ParamValues& params, const Scene& scene,
                   const Organ& organ, Cache& cache, const RunOptions& options = {});

/// The stepping part alone, on a model already initialised (or reset): from t = 0 for
/// options.maxSteps steps (or the scene's). Fills steps, timings, surfaces, status.
void simulate(Model& model, const Scene& scene, const Organ& organ, const RunOptions& options,
              RunRecord& record);

/// A run the scene asks for, resolved against its plugin.
struct PlannedRun {
  ModelSpec spec;
  const ModelInfo* info = nullptr;
  ParamValues params;
  std::string label;
  bool isReference = false;
  /// calibratedRunNote() of the --calibration it takes ("" when none or it says nothing): added
  /// to the run's notes.
  std::string calibrationNote;
  /// The calibration file whose parameters it runs with ("" when none): results.json
  /// "calibration".
  std::string calibrationFile;
};

/// The calibrated parameters of one model (DIR/calibration.json of `deformbench calibrate`).
struct CalibrationParams {
  std::string file;    ///< where they came from (--explain)
  std::string plugin;  ///< plugin name as in scenes
  std::string model;   ///< model name within the plugin
  nlohmann::json params = nlohmann::json::object();
  /// The organs of its training scenes (calibrationOrgan()); a calibration applies to scenes
  /// of these organs only. Empty (a file written before they were recorded): to any organ.
  std::vector<std::string> organs;
  /// The model's other parameters as the training scenes ran them (resolved: written or
  /// default), where every training scene had the same value, e.g. {"network": "surface"}. A
  /// run of the calibrated model with other values gets a note (calibrationDifferences()).
  /// Empty: a file written before they were recorded.
  nlohmann::json held = nlohmann::json::object();
  /// One of the project's shipped calibrations (`--calibration shipped`): on a scene of an organ
  /// it was not fitted on it is passed over in silence, where a file given by name is refused.
  bool shipped = false;
  /// The organ's material fitted with it (calibrate --material), e.g. {"poisson": 0.4993}: it
  /// applies to a whole scene, so no calibrated twin holds it (calibrationFor() passes it over);
  /// `tables truth-cube` runs it in a case of its own. Empty: the model's parameters only.
  nlohmann::json material = nlohmann::json::object();
  /// calibrate --truth-cube: {"level": 1-based level trained on, "strain", "contact"}; else
  /// empty.
  nlohmann::json truthCube = nlohmann::json::object();
  /// calibration.json "at_bound": each fitted parameter that ended at a bound of its search
  /// range, "min" or "max" ({"thickness": "max"}; the organ's material as "material.poisson").
  /// Empty: none, or a file written before it was recorded.
  nlohmann::json atBound = nlohmann::json::object();
};

/// The parameters in which a run of c's model (its resolved params, as in results.json) differs
/// from what c was fitted with (c.held), one text each: `network = "volume" (fitted with
/// "surface")`. `except`: parameters not to compare (a sweep's axes; "" entries are ignored).
std::vector<std::string> calibrationDifferences(const CalibrationParams& c,
                                                const nlohmann::json& resolved,
                                                const std::vector<std::string>& except = {});
/// The note a run gets when calibrationDifferences() is not empty ("" when it is): `calibration
/// FILE was fitted with other parameters: network = "volume" (fitted with "surface")`.
std::string calibrationDifferenceNote(const CalibrationParams& c, const nlohmann::json& resolved,
                                      const std::vector<std::string>& except = {});
/// The note a calibrated run gets when c fitted a parameter at a bound of its search ("" when
/// none): `calibration FILE: thickness fitted at its upper bound (the best fit may lie beyond the
/// searched range)`.
std::string calibrationBoundNote(const CalibrationParams& c);
/// What a run at c's parameters says of them: calibrationDifferenceNote() and
/// calibrationBoundNote(), "; "-joined ("" when neither says anything).
std::string calibratedRunNote(const CalibrationParams& c, const nlohmann::json& resolved,
                              const std::vector<std::string>& except = {});
/// "at its upper bound" / "at its lower bound" for a fitted parameter (`material.poisson` for the
/// organ's material) that c.atBound names, else "".
std::string boundWords(const CalibrationParams& c, const std::string& key);

/// The organ a calibration is fitted on, as written in calibration.json "organs": the mesh
/// ("phantom:NAME" or the file's absolute path) with its resolution (phantoms) or scale (files),
/// e.g. "phantom:cube, resolution 1". The fixed region, material and loads are not part of it.
std::string calibrationOrgan(const std::string& mesh, double resolution, double scale);
/// Whether c applies to a scene of that organ (calibrationOrgan(); "" for a scene without a
/// mesh, which any calibration applies to).
bool calibrationApplies(const CalibrationParams& c, const std::string& organ);
/// calibrationOrgan() of a scene's "organ" object as written (mesh, resolution, scale).
std::string calibrationOrgan(const nlohmann::ordered_json& organ);
/// The calibration of plugin/model that applies to a scene of `organ` (calibrationOrgan()),
/// or null when none names the model. When some name it but all were fitted on other organs:
/// null with skipOtherOrgans (the tables, whose cases span several phantoms), else an
/// InputError naming the first such file and its organ (run and sweep refuse the scene).
const CalibrationParams* calibrationFor(const std::vector<CalibrationParams>& calibrations,
                                        const std::string& plugin, const std::string& model,
                                        const std::string& organ, bool skipOtherOrgans);

struct BenchmarkOptions {
  std::vector<std::string> only;  ///< run only models whose label, model or plugin matches
  bool noReference = false;
  /// Cache folder: nullopt = Cache::defaultDir(); an empty path disables caching.
  std::optional<std::filesystem::path> cacheDir;
  std::filesystem::path outDir;  ///< where results.json and surfaces go
  RunOptions run;
  std::function<void(const std::string&)> explain;   ///< --explain lines (may be empty)
  std::function<void(const std::string&)> progress;  ///< one line per run started/finished
  /// Shared reference solves (calibration trials, the tables): the reference's run is read from
  /// the cache (kind "harness.reference_run") when an earlier run with this option solved the
  /// same problem, and stored there after a solve. The key is the scene without its models,
  /// reference, name, description and output, the organ, the plugin file (SHA-256), model and
  /// resolved parameters, and the step limit; not the run's label. A run read back keeps the
  /// surfaces, counts and timings of the run that solved it (a note says so). Off by default:
  /// sweeps time their references.
  bool reuseReference = false;
  /// With reuseReference: model runs that solve only at the compared instants (quasi-static
  /// plugins) are shared too, so a convergence level at the reference's own parameters reads the
  /// reference's solve (the tables' reference checks; `run --reuse-model-solves`, internal).
  bool reuseModelSolves = false;
  /// Calibrations whose parameters a model (same plugin and model) takes where the scene writes
  /// none; the first file naming a model wins.
  std::vector<CalibrationParams> calibrations;
  /// With calibrations: a model one of them calibrates runs twice, at the scene's parameters and
  /// calibrated (its twin, label "LABEL+cal"), side by side (`run --calibrated-twins`).
  bool calibratedTwins = false;
  /// Also write, per ok run with a compared instant, its surface at the last compared instant,
  /// exactly (binary, comparedSurfaceFile()): `converge` reads its levels from child processes
  /// this way (`run --write-compared`, internal).
  bool writeComparedSurface = false;
  /// Each run in a forked child process (run_isolation.h): a plugin that crashes in init() or
  /// step() fails its own run only. false: in this process (`run --in-process`, a debugger).
  bool isolateRuns = true;
};

/// outDir/<label>.compared.bin (sanitized label): the run's surface at its last compared instant
/// (BenchmarkOptions::writeComparedSurface); readComparedSurface() reads it back (false when the
/// file is absent or unreadable).
std::filesystem::path comparedSurfaceFile(const std::filesystem::path& outDir,
                                          const std::string& label);
bool readComparedSurface(const std::filesystem::path& file, MatX3& positions);

/// Loads the plugins the scene names and resolves every run's parameters. Throws InputError or
/// PluginError; runs nothing.
std::vector<PlannedRun> planRuns(const Scene& scene, PluginLoader& loader,
                                 const BenchmarkOptions& options);

/// Fills record.valid / invalidReason from its status, grasps, residual, settling, solver
/// counters and support (DESIGN "Metrics", docs/results-format.md "Validity").
void assessValidity(const Scene& scene, RunRecord& record);

/// Why a run's support did not hold ("" when it did or nothing is fixed): the organ has a fixed
/// region (record.fixedRegion) but the model holds none of its nodes there (record.fixedNodes ==
/// 0), or the organ's surface inside the region moved more than 5% of the run's largest surface
/// displacement (record.fixedDrift against record.peakDisplacement).
std::string supportProblem(const Scene& scene, const RunRecord& record);

/// Why a run that stopped before stepping, or whose stepping threw, is invalid: its status and
/// message ("failed (init: ...)", "unsupported (...)"); "" for an ok run.
std::string notRunReason(const RunRecord& record);
/// A run whose status is not ok is invalid (valid false, invalidReason notRunReason() unless a
/// reason is already there). runModel() applies it on every path; a record made elsewhere (a
/// crashed child, a failed case) must too.
void invalidateIfNotOk(RunRecord& record);

/// The note a run gets when its surface outran the tool ("" otherwise): in a scene driven by
/// prescribed motion alone (grasps or pin heads, no point force), surface points that moved
/// more than 1.5x the largest prescribed motion (record.peakDisplacement against
/// record.prescribedMotion), with the ratio.
std::string outrunNote(const Scene& scene, const RunRecord& record);

/// Judges moved copies of the organ's surface for triangles that pass through each other: the
/// intersecting pairs, split into those with a vertex the scene holds (grasped or fixed) or next
/// to it (a fold at the edge of a clamp or a grasp, rigid regions the scene gives no contact) and
/// the others. The rest surface is checked and the held region's edge marked once, here; a rest
/// surface that self-intersects itself gives nothing to judge (both counts 0).
class SelfIntersectionCheck {
 public:
  SelfIntersectionCheck(const Scene& scene, const Organ& organ);
  /// positions: at least #V rows, the first #V the organ's surface vertices moved.
  SelfIntersectionCount operator()(const MatX3& positions) const;

 private:
  const SurfaceMesh& m_rest;
  bool m_judged = false;       ///< the rest surface is free of self-intersections
  std::vector<char> m_atEdge;  ///< per vertex: held, or a neighbour of a held vertex
};

/// Errors of every ok model run against the reference run (if there is one and it is ok), and
/// each model run's referenceValid: false when the reference is invalid, failed, diverged or
/// unsupported (the errors, where there are any, are then against an invalid reference). A
/// reference whose surface passes through itself at a compared instant away from the held
/// vertices (fixed or grasped) is invalid first (no state of a solid); a fold at a held region's
/// edge, and a model's run that passes through itself, get a note.
void computeRunErrors(const Scene& scene, const Organ& organ, std::vector<RunRecord>& runs);

struct BenchmarkResult {
  Scene scene;
  Organ organ;
  std::vector<std::string> organLog;  ///< what loadOrgan dropped or repaired
  std::vector<RunRecord> runs;
  std::filesystem::path resultsPath;
};

/// The `deformbench run` pipeline: parse, load the organ, plan, run, compare, write surfaces and
/// then results.json (atomically, last). Throws InputError / PluginError for bad input before
/// anything is written.
BenchmarkResult runBenchmark(const std::string& sceneFile, PluginLoader& loader,
                             const BenchmarkOptions& options);

/// Limits BLAS/OpenMP to one thread (environment for libraries loaded later, and the runtime
/// calls of those already loaded). Call first thing in main() and again after loading plugins.
void forceSingleThreadedNumerics();

}  // namespace deform::harness
