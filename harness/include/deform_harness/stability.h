// deformbench harness: the stiff and extreme sweep. Every model runs over a fixed set of cases
// (Young's modulus 1 kPa to 10 MPa against time steps 1 ms to 1/30 s, Poisson ratio up to 0.499,
// point forces up to 200 N, a grasp pulled three organ-lengths away, a region pushed through the
// organ (inverted) and one pressed flat). Each (model, case) runs in its own child process
// (fork + exec of `deformbench run` on a generated scene) with a wall-clock limit, so a crash or a
// hang is recorded and the sweep goes on. Classification:
//   stable       the run reached its end (status ok)
//   diverged     NaN/Inf, left the divergence box, or the model reported divergence (with step)
//   failed       the model threw, the child died from a signal, or hit the time limit
//   unsupported  the case needs a capability the model lacks
// and a verdict beside it: every case with a quasi-static answer (all but pull, invert and
// flatten) gets a reference (reference_fem at its defaults, quadratic tets, on the same scene,
// solved once per case as a child process with 5x the case's time limit and kept in the cache,
// with a coarser quadratic solve for its error estimate), and the model's final surface is
// compared with it:
//   accurate     error_ratio = rmse_all / (the reference's RMS displacement) <= the threshold
//                (20% by default)
//   inaccurate   above it, with a reason: frozen (the model's RMS displacement is below 10% of the
//                reference's), too_soft (above twice it) or wrong_shape; scale_dependent (scale
//                group: the model's relative displacements at 1 cm, 10 cm and 1 m differ by over
//                10%)
//   collapsed    the model moved through its support or by more than its size while the
//                reference moves it by under 10% of its size (collapseProblem)
//   diverged, failed   as the status
//   unchecked    no reference (none for the case, it failed, or it does not move), unsupported,
//                the reference itself, or "reference not converged" (the reference's error, from
//                beam theory where there is one, else its estimate, is above the threshold)
// Each finished case is written atomically to DIR/cases/<model>/<case>.json with the hash of its
// scenes, so --resume skips it while the case is unchanged (--retry-failed reruns failed ones).
// Output: DIR/stability.{md,csv,json} and DIR/stability_<model>.png (plot_stability.py).
#pragma once

#include <deform/engine/plugin_loader.h>
#include <deform/sdk/mesh.h>
#include <deform_harness/analytic.h>  // cantileverSag
#include <deform_harness/cases.h>
#include <deform_harness/progress.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace deform::harness {

class Dispatcher;

struct StabilityCase {
  std::string id;     ///< "E1e+06_dt0.0333"
  std::string group;  ///< "stiffness_dt" (the map), "poisson", "force", "cantilever", "scale",
                      ///< "slivers", "pull", "invert", "flatten"
  double young = 5500, poisson = 0.3, dt = 1e-3;
  double force = 0;   ///< N, downward point force at the top (0: none)
  std::string extra;  ///< "pull", "invert", "flatten" or ""
  std::string description;
  std::string organ = "cube";  ///< "cube" (phantom), "beam" (the cantilever), "slivers"
  double scale = 1;            ///< lengths x scale, force x scale^2, density / scale^2, no gravity
  double density = 1000;       ///< kg/m^3 before scaling
  bool gravity = true;
  bool reference = true;  ///< has a quasi-static answer: compared with reference_fem
  double beamTheory = 0;  ///< m, cantilever tip sag by beam theory (0: not a cantilever)
  double duration = 0;    ///< s; 0: the sweep's default
};

/// The organ of the "slivers" case: the liver phantom at the resolution with every fourth edge
/// split at 2% of its length, so that each split leaves two needle triangles (about 1.1 degrees at
/// the tip) beside two ordinary ones. Same geometry as the phantom; closed and manifold.
SurfaceMesh sliverMesh(double resolution);

/// The case set; quick: a subset (the corners of the map and one of each extreme).
std::vector<StabilityCase> stabilityCases(bool quick);

struct StabilityOptions {
  bool quick = false;
  bool resume = false;
  bool retryFailed = false;  ///< with resume: run the cases that failed again
  std::filesystem::path outDir;
  std::vector<std::string> models;      ///< plugin names; empty: every plugin found
  std::vector<std::string> cases;       ///< case ids to run; empty: all of the set
  double timeoutS = 0;                  ///< per case; 0: 120 s (60 s with quick)
  std::string executable;               ///< deformbench to exec; "": /proc/self/exe
  std::vector<std::string> pluginDirs;  ///< passed on as --plugin-dir
  std::string cacheDir;                 ///< passed on as --cache-dir ("" = default)
  int jobs = 1;                         ///< children at once (when dispatcher is null)
  /// Where the (model, case) children run (dispatch.h); nullptr: here, `jobs` at once.
  Dispatcher* dispatcher = nullptr;
  double accuracyThreshold = 0.2;  ///< accurate: error_ratio at most this
};

/// Every verdict, in the order the summaries count them.
inline constexpr const char* kStabilityVerdicts[] = {"accurate", "inaccurate", "collapsed",
                                                     "diverged", "failed",     "unchecked"};

struct StabilityRecord {
  std::string model, caseId, group;
  std::string status;  ///< stable | diverged | failed | unsupported
  int step = -1;       ///< diverged: the step
  std::string message;
  double wallS = 0;
  bool resumed = false;  ///< read back from a previous run
  /// accurate | inaccurate | collapsed | diverged | failed | unchecked ("" until judged)
  std::string verdict;
  /// inaccurate: frozen | too_soft | wrong_shape | scale_dependent; collapsed: what moved;
  /// unchecked: why ("reference not converged", "the reference itself", ...)
  std::string reason;
  double errorRatio = -1;            ///< rmse_all / reference RMS displacement; < 0: none
  double displacementRatio = -1;     ///< model / reference RMS displacement; < 0: none
  double relativeDisplacement = -1;  ///< model RMS displacement / organ size; < 0: none
  double tipSag = -1;                ///< m, cantilever: mean downward displacement of the tip face
  /// The reference's own relative error: against beam theory (cantilever), else the estimate
  /// from a coarser solve; < 0: none.
  double referenceError = -1;
  std::string referenceSource;  ///< "beam theory" | "coarser solve" ("" when none)
  std::string reference;        ///< which reference: "reference_fem P2, 1000 target tets (N tets)"
  std::string sceneHash;        ///< sha256 of the case's scenes (--resume reuses a matching one)
};

/// Why a model's final surface `moved` is a collapse, "" when it is none: more than 10% of the
/// free surface vertices went through the support (beyond the plane, normal to the direction
/// from the held vertices' centre to the organ's, past the held vertex farthest back, by over 5%
/// of the organ's size), or the RMS displacement exceeds the organ's size (its bounding box's
/// largest side). held: the surface vertices in the fixed region (empty: the size test alone).
/// The caller judges it only where the reference moves the organ by under 10% of its size.
std::string collapseProblem(const MatX3& rest, const MatX3& moved, const std::vector<int>& held);

/// Relative displacement: RMS displacement from rest over the largest side of rest's bounding
/// box; -1 when the sizes differ or rest is empty.
double relativeDisplacement(const MatX3& rest, const MatX3& moved);

/// The verdict of one finished case. model: its final surface (nullptr if none); reference: the
/// reference's final surface at the same instant (nullptr: no reference); rest: the rest surface;
/// held: the surface vertices in the fixed region (collapseProblem); r.referenceError (if >= 0)
/// above the threshold makes the verdict "unchecked", reason "reference not converged". Fills
/// verdict, reason, errorRatio and displacementRatio of a copy of r.
StabilityRecord judgeStability(StabilityRecord r, const MatX3* model, const MatX3* reference,
                               const MatX3& rest, double threshold = 0.2,
                               const std::vector<int>& held = {});

/// The scale group's check (in place): for each model whose relative displacements at the three
/// scale cases are all known and whose largest exceeds its smallest by over 10%, every scale row
/// judged accurate, inaccurate or unchecked becomes inaccurate with reason scale_dependent (the
/// model's own numbers: no reference needed). Returns one line
/// per such model ("pbd: 0.17 (scale_0.01m) 0.23 (scale_0.1m) 1.8 (scale_1m)").
std::vector<std::string> markScaleDependent(std::vector<StabilityRecord>& records);

/// Runs the sweep; writes every output file. Returns every record (resumed ones included).
std::vector<StabilityRecord> runStability(PluginLoader& loader, const StabilityOptions& options,
                                          Progress* progress);

/// The scene of one (model, case) as JSON. params: the model's params object.
nlohmann::ordered_json stabilityScene(const StabilityCase& c, const std::string& plugin,
                                      const nlohmann::ordered_json& params, bool quick);

/// Classifies a finished child from its exit (waitpid status), its results.json (may be absent)
/// and whether it was killed at the time limit.
StabilityRecord classifyStabilityRun(int waitStatus, bool timedOut, double timeoutS,
                                     const std::filesystem::path& resultsJson,
                                     const std::string& stderrTail);

}  // namespace deform::harness
