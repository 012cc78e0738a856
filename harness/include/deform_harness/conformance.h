// deformbench harness: the conformance suite (`deformbench conformance`), the checks every model
// must pass whether its plugin is built in this tree or out of it. Each check runs on a small
// phantom scene built in memory and ends as passed, failed (with the reason) or skipped (the
// model's capabilities say it does not apply). docs/writing-a-plugin.md lists the checks.
#pragma once

#include <deform/engine/plugin_loader.h>
#include <deform/sdk/cache.h>

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace deform::harness {

enum class CheckOutcome { Passed, Failed, Skipped, ExpectedFailure, UnexpectedPass };
/// "pass" | "FAIL" | "skip" | "xfail" | "XPASS"
const char* checkOutcomeName(CheckOutcome o);

struct CheckResult {
  std::string plugin;  ///< plugin name (deform_NAME.so)
  std::string model;   ///< model name ("" for the plugin-level load check)
  std::string check;   ///< "load", "init", "rest", "sag", "grasp", ...
  CheckOutcome outcome = CheckOutcome::Passed;
  std::string detail;  ///< why it failed or was skipped; a measured value when it passed
  double seconds = 0;
};

struct ConformanceOptions {
  /// Plugin names to check (as the loader finds them); empty: every plugin in the search path.
  std::vector<std::string> plugins;
  /// Model names to check; empty: every model of each plugin.
  std::vector<std::string> models;
  /// Check names to run; empty: all of them (conformanceCheckNames()).
  std::vector<std::string> checks;
  /// Check names not to run, even where `checks` names them.
  std::vector<std::string> skipChecks;
  /// "PLUGIN/CHECK" or "PLUGIN/MODEL/CHECK" entries known to fail: such a failure is reported
  /// "xfail" and does not fail the run; such a check passing is "XPASS" and does (so that the
  /// entry gets removed).
  std::vector<std::string> expectedFailures;
  /// Folder of shipped scenes for the "scenes" check; empty: no such check (skipped).
  std::filesystem::path scenesDir;
  /// Called once per finished check (for printing as the suite goes).
  std::function<void(const CheckResult&)> report;
};

/// Every check in the order it runs.
const std::vector<std::string>& conformanceCheckNames();

/// The folder of shipped scenes a deformbench finds by itself: PREFIX/share/deformbench/scenes
/// beside the running program, else the source tree's scenes/ (a build tree); empty if neither.
std::filesystem::path defaultConformanceScenesDir();

/// Runs the suite. Throws PluginError / InputError only for bad arguments (a named plugin or
/// model that does not exist, an unknown check name); a plugin that does not load is a failed
/// "load" check.
std::vector<CheckResult> runConformance(PluginLoader& loader, Cache& cache,
                                        const ConformanceOptions& options);

/// Grasp tolerance of the "grasp" check: every grasped surface vertex within this of its target.
inline constexpr Real kConformanceGraspTolerance = 0.5e-3;  // m

}  // namespace deform::harness
