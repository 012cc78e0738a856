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
// Each finished case is written atomically to DIR/cases/<model>/<case>.json, so --resume skips
// it. Output: DIR/stability.{md,csv,json} and DIR/stability_<model>.png (plot_stability.py).
#pragma once

#include <deform/plugin_loader.h>
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
  std::string group;  ///< "stiffness_dt" (the map), "poisson", "force", "pull", "invert", ...
  double young = 5500, poisson = 0.3, dt = 1e-3;
  double force = 0;   ///< N, downward point force at the top (0: none)
  std::string extra;  ///< "pull", "invert", "flatten" or ""
  std::string description;
};

/// The case set; quick: a subset (the corners of the map and one of each extreme).
std::vector<StabilityCase> stabilityCases(bool quick);

struct StabilityOptions {
  bool quick = false;
  bool resume = false;
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
};

struct StabilityRecord {
  std::string model, caseId, group;
  std::string status;  ///< stable | diverged | failed | unsupported
  int step = -1;       ///< diverged: the step
  std::string message;
  double wallS = 0;
  bool resumed = false;  ///< read back from a previous run
};

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
