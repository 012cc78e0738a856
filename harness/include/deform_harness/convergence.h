// deformbench harness: is the scene's reference converged? The reference plugin is run (through
// the loader and the runner, like any model) on three meshes refined by size: target interior
// edge lengths r_0 h, r_1 h, r_2 h (by default h, h/1.4, h/2; a check of the reference itself
// 2h, 1.4h, h, so the finest level is the reference as the scene runs it), given to the plugin
// as its `edge_length` parameter (Gmsh's size field; a plugin without one gets `elements`
// scaled by r^-3). The surface displacement at the last compared instant is extrapolated
// (Richardson). With h_k = (organ volume / #elements_k)^(1/3) of the mesh actually made,
// d_01 = max_i |u_0,i - u_1,i| and d_12 likewise, and the ansatz u_k = u + C h_k^p, the observed
// order p solves
//   (h_0^p - h_1^p) / (h_1^p - h_2^p) = d_01 / d_12
// and the finest level's error is e_2 = d_12 h_2^p / (h_1^p - h_2^p) (Roache 1997,
// doi:10.1146/annurev.fluid.29.1.123; the same analysis as plugins/reference_fem/convergence.h,
// here on runs of the plugin rather than on its kernels). Vertices within `excludeRadius` of a
// point load (singular in 3D elasticity) or of where a grasp closes (the attached node set
// depends on the mesh) are left out. The same analysis runs on the RMS level differences
// (rms_order, rms_relative_error): the tables' error columns are RMS figures.
//
// Where Richardson does not apply the study says why (ConvergenceResult::reason, message):
// levels that failed, levels that do not refine or are too close in h (ratio below
// kMinLevelRatio: the organ's surface vertices, all nodes, bound the coarse levels' size),
// answers that coincide, differences that do not shrink (d_12 >= d_01: not monotone), an order
// below 0.5 (not in the asymptotic range). Above order 4 the finest pair is extrapolated at
// order 2 instead (an upper estimate). Without an estimate, the largest level difference
// is given as a bound (Roache's oscillatory case: the spread of the levels' answers). A check of
// the reference whose coarse levels the surface bounds runs a fourth level, finer than the
// reference, and estimates the reference's own error from the last three
// (ConvergeOptions::finerWhenBound).
//
// The study is deterministic, so its result is kept in the precomputation cache (kind
// "harness.convergence"), keyed by the scene as run (organ, loads, tools, times, the reference
// and its params), the levels, the excluded radius and the SHA-256 of the reference plugin's
// shared object (and of the organ's mesh file): a rebuilt plugin or a changed scene recomputes.
#pragma once

#include <deform/engine/plugin_loader.h>
#include <deform_harness/cases.h>
#include <deform_harness/progress.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace deform::harness {

struct ConvergenceLevelResult {
  long long targetElements = 0, elements = 0;
  double h = 0;                 ///< m, (organ volume / elements)^(1/3) of the mesh made
  double peakDisplacement = 0;  ///< m
  std::string status;
  double solveS = 0;   ///< precompute + steps, s
  double targetH = 0;  ///< m, the edge length the level asked for (0: by elements)
};

struct ConvergenceResult {
  std::vector<ConvergenceLevelResult> levels;
  double d01 = 0, d12 = 0;  ///< m
  /// m: root mean square over the same vertices of the level differences |u_0 - u_1|,
  /// |u_1 - u_2| (the scale of the reference's error in the tables' RMS columns, where d01,
  /// d12 give it in the max norm); NaN without three levels.
  double rms01 = NAN, rms12 = NAN;
  double order = NAN;  ///< observed p
  double errorEstimate = NAN, relativeError = NAN;
  bool asymptotic = false;  ///< 0.5 <= p <= 4
  /// relativeError <= 1%, with asymptotic or with the upper estimate (p > 4, elementOrder)
  bool converged = false;
  /// Why Richardson does not apply (or its estimate is unreliable), "" when it does:
  /// "levels_failed", "not_refining", "levels_too_close", "coincide", "not_monotone",
  /// "not_asymptotic".
  std::string reason;
  std::string message;  ///< the reason in words, if there is one
  /// Without an estimate (or with an unreliable one): max(d01, d12) / peak, the spread of the
  /// levels' answers, which bounds the error when the levels oscillate about the answer.
  double boundRelative = NAN;
  /// The same Richardson analysis on the RMS differences rms01, rms12 (relative to the peak).
  double rmsOrder = NAN, rmsRelativeError = NAN;
  bool rmsConverged = false;  ///< the RMS analysis is asymptotic and within 1%
  bool cached = false;        ///< read from the precomputation cache, not recomputed
  /// A level finer than the reference was added (ConvergeOptions::finerWhenBound): the
  /// estimate comes from the last three levels and is the error of the one before the last.
  bool finerLevelAdded = false;
  /// The reference's mesh is graded toward a point (focus_radius > 0): each level's h is its
  /// size field's scale, the target edge length, which scales the mesh near the interaction by
  /// the level ratios; (V / tets)^(1/3) would not, since the far field stays as coarse as the
  /// organ's surface.
  bool graded = false;
  /// Index into `levels` of the level whose error errorEstimate is (-1: not set).
  int estimatedLevel = -1;
  /// The reference's element order (its `element_order` param; 2 for a plugin without one).
  /// Where the levels allow only an upper estimate (two levels, or an observed order above 4),
  /// the finest pair is extrapolated at this order, the lower of its elements' rates (the
  /// energy norm's): 1 for linear tets, 2 for quadratic ones.
  int elementOrder = 2;
  /// estimatedLevel where it is set, else the last level (a result built by hand).
  size_t estimatedIndex() const {
    return estimatedLevel >= 0 ? size_t(estimatedLevel) : levels.size() - 1;
  }
};

/// Smallest ratio h_k / h_{k+1} of consecutive levels' measured sizes for which the study
/// extrapolates: closer levels differ mostly by mesh noise (Roache's minimum refinement ratio).
inline constexpr double kMinLevelRatio = 1.1;

/// Which level's error a three-level analysis estimates: the finest (level 2), or the middle one
/// (level 1, a reference checked between a coarser and a finer level): its error is the finest
/// pair's difference plus the finest level's error, d12 h1^p / (h1^p - h2^p) where the finest
/// level's is d12 h2^p / (h1^p - h2^p).
enum class EstimateOf { Finest, Middle };

/// Richardson analysis of three levels (h0 > h1 > h2, differences d01, d12): fills order,
/// errorEstimate, relativeError (errorEstimate / peak), asymptotic, converged, and reason,
/// message and boundRelative where it does not apply.
void richardsonEstimate(double h0, double h1, double h2, double d01, double d12, double peak,
                        ConvergenceResult& out, EstimateOf of = EstimateOf::Finest);

/// The same on the RMS differences: fills rmsOrder, rmsRelativeError, rmsConverged only.
void richardsonRms(double h0, double h1, double h2, double rms01, double rms12, double peak,
                   ConvergenceResult& out, EstimateOf of = EstimateOf::Finest);

/// The smallest error relative to the peak that a level finer than a study's three could
/// estimate for the middle one of the last three (ConvergeOptions::finerWhenBound): its finest
/// pair h1 > h2 differs by d12, and a finer level converging from there at the highest order the
/// analysis credits (4) gives d12 / ((h1 / h2)^4 - 1). 0 where h1 / h2 is below kMinLevelRatio
/// (the pair bounds nothing) or peak is not positive.
double finerLevelBestRelativeError(double h1, double h2, double d12, double peak);

/// Level sizes of `converge`: h, h/1.4, h/2 from the reference's own h.
inline const std::vector<double> kRefineRatios = {1.0, 1.0 / 1.4, 0.5};

/// The levels of a check of the reference itself: 2h, 1.4h and h, so that the finest level is
/// the reference as the scene runs it and the estimate is its error (what the tables check, and
/// `converge --of-reference`).
inline const std::vector<double> kReferenceCheckRatios = {2.0, 1.4, 1.0};

/// The size step of the finer level a reference check adds when the surface bounds its coarse
/// levels (ConvergeOptions::finerWhenBound): h / 1.4.
inline constexpr double kFinerLevelStep = 1.4;

struct ConvergeOptions {
  /// h: > 0 this edge length (m); else from baseElements N (the interior edge length that gives
  /// about N tets in the organ, edgeLengthForElements); else the reference's own `edge_length`,
  /// or its own `elements` (the plugin's default when the scene sets none).
  double baseEdgeLength = 0;
  long long baseElements = 0;
  /// Level k's target edge length is hRatios[k] * h: three, decreasing. A ratio of exactly 1
  /// leaves the reference's params as they are (the same mesh and answer as the scene's).
  std::vector<double> hRatios = kRefineRatios;
  std::filesystem::path outDir;
  std::optional<std::filesystem::path> cacheDir;
  double excludeRadius = -1;  ///< m; < 0: 10% of the organ's bounding-box diagonal
  /// Set: each level is a `deformbench run` child (cases.h) handed to `dispatcher` (dispatch.h;
  /// nullptr: one at a time here), its surface read back exactly (`run --write-compared`);
  /// the study is the same as in this process. nullopt: the levels run in this process.
  std::optional<ChildCaseOptions> child;
  Dispatcher* dispatcher = nullptr;  ///< not owned
  /// Levels read from and stored in the cache's shared solves (runner.h, reuseModelSolves): the
  /// finest level of a reference check is the reference the table's case already solved.
  bool reuseSolves = false;
  /// When the two coarse levels are less than kMinLevelRatio apart (all of the organ's surface
  /// vertices are nodes, so a fine surface bounds the coarse levels) and the estimate is not
  /// converged: run a fourth level at hRatios.back() / kFinerLevelStep and estimate the error of
  /// the third level (the reference, in a check of it) from the last three levels
  /// (EstimateOf::Middle). The reference itself is not changed. No level is added where even
  /// that could not show 1% (finerLevelBestRelativeError above it): the message says so.
  bool finerWhenBound = false;
};

/// The options of a check of the scene's reference itself: levels 2h, 1.4h, h of its own size,
/// and a finer level where the surface bounds the coarse ones (what the tables, `converge
/// --of-reference` and `run`'s note use).
ConvergeOptions referenceCheckOptions();

/// The cached check of the scene's reference (kReferenceCheckRatios, its own size), if a
/// study of exactly that scene and plugin build is in the cache; nothing is run. cacheDir set and
/// empty (--no-cache): nothing is read, nullopt.
std::optional<ConvergenceResult> cachedReferenceCheck(
    const std::string& sceneFile, PluginLoader& loader,
    const std::optional<std::filesystem::path>& cacheDir);

/// Runs the study on the scene file (writes options.outDir/convergence.json and level_k/).
ConvergenceResult runConvergence(const std::string& sceneFile, PluginLoader& loader,
                                 const ConvergeOptions& options, Progress* progress);

/// The same on a scene given as JSON; a relative organ mesh path is resolved against the folder
/// of `sceneFile` (which names the scene in messages and need not exist).
ConvergenceResult runConvergence(const nlohmann::ordered_json& scene, const std::string& sceneFile,
                                 PluginLoader& loader, const ConvergeOptions& options,
                                 Progress* progress);

/// One study of runConvergences: the scene, its file (as runConvergence's) and its options.
struct ConvergenceStudyInput {
  nlohmann::ordered_json scene;
  std::string sceneFile;
  ConvergeOptions options;
};

/// runConvergence for several studies at once, each with its own outDir: the first three levels
/// of every study go to the dispatcher together, then the finer levels the estimates ask for, so
/// the studies' levels run side by side (the first study's `child` and `dispatcher` serve all).
/// Each result is its study's runConvergence; a study whose scene cannot be prepared gets
/// `message` instead of a throw.
std::vector<ConvergenceResult> runConvergences(const std::vector<ConvergenceStudyInput>& studies,
                                               PluginLoader& loader, Progress* progress);

/// One line: "estimated discretisation error X% of the peak (levels a / b / c tets, h ..., p =
/// q)", or why there is no estimate and the bound.
std::string convergenceSummary(const ConvergenceResult& r);

/// The warning the study calls for ("" when the reference is converged to 1%).
std::string convergenceWarning(const ConvergenceResult& r);

}  // namespace deform::harness
