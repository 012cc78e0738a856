// deformbench command line: what the verbs share. Each verb (one file in this folder) declares
// its CLI11 options beside its *Args struct and returns a Verb; main.cpp parses and runs the one
// given. Bad input throws InputError (main prints it, exit 2).
#pragma once

#include <deform/engine/plugin_loader.h>
#include <deform_harness/cases.h>
#include <deform_harness/convergence.h>
#include <deform_harness/dispatch.h>
#include <deform_harness/runner.h>

#include <CLI/CLI.hpp>
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

namespace deform::harness::cli {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr int kExitBadInput = 2;
constexpr int kExitInternal = 3;
constexpr int kExitModelFailed = 1;

/// A verb of the command line: its subcommand, options declared, and what runs it once parsed
/// (given the global --plugin-dir folders).
struct Verb {
  CLI::App* cmd = nullptr;
  std::function<int(const std::vector<std::string>& pluginDirs)> run;
};

// The verbs, in the order `deformbench --help` lists them.
Verb addPlugins(CLI::App& app);
Verb addRun(CLI::App& app);
Verb addPhantom(CLI::App& app);
Verb addTables(CLI::App& app);
Verb addSweep(CLI::App& app);
Verb addCalibrate(CLI::App& app);
Verb addStability(CLI::App& app);
Verb addReport(CLI::App& app);
Verb addBench(CLI::App& app);
Verb addConverge(CLI::App& app);
Verb addVerify(CLI::App& app);
Verb addWork(CLI::App& app);
Verb addConformance(CLI::App& app);

/// The verb `name` of the command line. Args holds its arguments and declares its options beside
/// them (`void declare(CLI::App*)`); once parsed, Args receives the --plugin-dir folders (in
/// `common.pluginDirs` or `pluginDirs`, where it has one) and run(args) runs the verb.
/// A run that needs the parsed subcommand (which options were given) takes (Args&, const
/// CLI::App&).
template <class Args, class Run>
Verb makeVerb(CLI::App& app, const std::string& name, const std::string& help, Run run) {
  auto args = std::make_shared<Args>();
  CLI::App* cmd = app.add_subcommand(name, help);
  args->declare(cmd);
  return {cmd, [args, cmd, run](const std::vector<std::string>& pluginDirs) {
            if constexpr (requires { args->common.pluginDirs; })
              args->common.pluginDirs = pluginDirs;
            else if constexpr (requires { args->pluginDirs; })
              args->pluginDirs = pluginDirs;
            if constexpr (std::is_invocable_v<Run, Args&, const CLI::App&>)
              return run(*args, *cmd);
            else
              return run(*args);
          }};
}

/// The command line as given, for the Slurm collect step (set in main()).
extern std::vector<std::string> g_commandLine;

/// The text on one line (newlines become spaces).
std::string oneLine(std::string s);

/// The --plugin-dir folders, then the default search path.
std::vector<std::string> searchPath(const std::vector<std::string>& extraDirs);

/// A check for a positive option value that says so in words (CLI11's PositiveNumber prints its
/// range with the largest double written out in 309 digits).
CLI::Validator positiveValue(bool whole);

/// Plugin names are file names (deform_NAME.so) without folders: a name that is a path would
/// put the stability outputs outside --out.
void requirePluginName(const std::string& option, const std::string& name);

/// A number for a table on stdout ("-" when not finite).
std::string fmt(double v, int precision = 3);

/// The --calibration files, read and checked (InputError names the file); two files for one
/// model and organ are refused. "shipped" stands for every shipped calibration
/// (shippedCalibrationsDir()), each applied on its own organ's scenes only.
std::vector<CalibrationParams> readCalibrations(const std::vector<std::string>& files);

/// The options of tables, sweep, stability, calibrate, bench, converge and verify.
struct CommonArgs {
  std::string out;
  bool quick = false;
  bool explain = false;
  std::string cacheDir;
  bool noCache = false;
  std::vector<std::string> pluginDirs;
};

/// --quick (when asked), --cache-dir and --no-cache.
void addCommon(CLI::App* cmd, CommonArgs& c, bool quick);

std::optional<fs::path> cacheChoice(const CommonArgs& a);
CaseOptions caseOptions(const CommonArgs& a);

/// The --out folder, created; InputError when it cannot be.
fs::path makeOutDir(const std::string& out);

// --jobs, --mpi, --slurm DIR (dispatch.h): where the cases of a long command run.
struct DispatchArgs {
  int jobs = 1;
  bool mpi = false;
  std::string slurm;
};

std::unique_ptr<Dispatcher> makeDispatcher(const DispatchArgs& d);
void addDispatch(CLI::App* cmd, DispatchArgs& d);

/// Runs a plotting script; one line when matplotlib (or Python) is missing. Returns true on
/// success.
bool plot(const std::string& script, const std::vector<std::string>& args);

/// sweep and converge: their cases run in this process unless a dispatch option, --resume or
/// --timeout is given; then each is a `deformbench run` child handed to the dispatcher.
struct ChildArgs {
  bool given = false;  ///< --jobs, --mpi, --slurm, --resume or --timeout on the command line
  bool resume = false;
  bool retryFailed = false;
  double timeout = 0;
  DispatchArgs dispatch;
};

void addChildArgs(CLI::App* cmd, ChildArgs& c, const std::string& what);
bool childArgsGiven(const CLI::App& cmd);

/// run and sweep: one line on the scene's reference `label`, its cached check's estimate (or why
/// there is none) or, with no check cached, how to get one; nothing with --no-cache (cacheDir
/// set and empty).
void printReferenceCheckLine(const std::string& label, const std::string& sceneFile,
                             const std::optional<ConvergenceResult>& check,
                             const std::optional<fs::path>& cacheDir);

/// The child-process options (nullopt: in this process) and the dispatcher of sweep / converge.
std::optional<ChildCaseOptions> childOptions(const ChildArgs& c, PluginLoader& loader,
                                             double defaultTimeoutS);

}  // namespace deform::harness::cli
