// deformbench harness: is the scene's reference converged? The reference plugin is run (through
// the loader and the runner, like any model) at three element counts N, 2.8 N, 8 N (interior
// edge-length ratio ~1.41), and the surface displacement at the last compared instant is
// extrapolated (Richardson). With h_k = (organ volume / #elements_k)^(1/3), d_01 = max_i
// |u_0,i - u_1,i| and d_12 likewise, and the ansatz u_k = u + C h_k^p, the observed order p solves
//   (h_0^p - h_1^p) / (h_1^p - h_2^p) = d_01 / d_12
// and the finest level's error is e_2 = d_12 h_2^p / (h_1^p - h_2^p) (Roache 1997,
// doi:10.1146/annurev.fluid.29.1.123; the same analysis as plugins/reference_fem/convergence.h,
// here on runs of the plugin rather than on its kernels). Vertices within `excludeRadius` of a
// point load (singular in 3D elasticity) or of where a grasp closes (the attached node set
// depends on the mesh) are left out.
//
// The study is deterministic, so its result is kept in the precomputation cache (kind
// "harness.convergence"), keyed by the scene as run (organ, loads, tools, times, the reference
// and its params), the levels, the excluded radius and the SHA-256 of the reference plugin's
// shared object (and of the organ's mesh file): a rebuilt plugin or a changed scene recomputes.
#pragma once

#include <deform/plugin_loader.h>
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
  double h = 0;                 ///< m
  double peakDisplacement = 0;  ///< m
  std::string status;
  double solveS = 0;  ///< precompute + steps, s
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
  bool converged = false;   ///< asymptotic && relativeError <= 1%
  std::string message;      ///< why there is no estimate, if there is none
  bool cached = false;      ///< read from the precomputation cache, not recomputed
};

/// Richardson analysis of three levels (h0 > h1 > h2, differences d01, d12): fills order,
/// errorEstimate, asymptotic. relativeError needs the peak displacement: errorEstimate / peak.
void richardsonEstimate(double h0, double h1, double h2, double d01, double d12, double peak,
                        ConvergenceResult& out);

struct ConvergeOptions {
  long long baseElements = 0;  ///< N; 0: the scene reference's own "elements" (else 5000)
  /// Level k targets llround(factors[k] * N) elements: three, increasing. {1/8, 1/2.8, 1} makes
  /// the finest level the reference at N itself (what the tables check).
  std::vector<double> factors = {1.0, 2.8, 8.0};
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
};

/// The levels of a check of the reference itself: 1/8, 1/2.8 and 1 times its own elements, so
/// that the finest level is the reference as the scene runs it and the estimate is its error
/// (what the tables check, and `converge --of-reference`).
inline const std::vector<double> kReferenceCheckFactors = {1.0 / 8.0, 1.0 / 2.8, 1.0};

/// The cached check of the scene's reference (kReferenceCheckFactors, its own elements), if a
/// study of exactly that scene and plugin build is in the cache; nothing is run.
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

/// One line: "estimated discretisation error X% of the peak (levels a / b / c tets, p = q)", or
/// why there is no estimate.
std::string convergenceSummary(const ConvergenceResult& r);

/// The warning the study calls for ("" when the reference is converged to 1%).
std::string convergenceWarning(const ConvergenceResult& r);

}  // namespace deform::harness
