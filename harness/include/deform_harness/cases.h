// deformbench harness: running generated scenes as "cases" of the long commands (tables, sweep,
// bench) through the plugin loader and the runner, and writing tables as Markdown, CSV and JSON.
//
// A case is a scene (JSON) written into the output folder, so that any row can be rerun with
// `deformbench run SCENE`. Plugins the scene names that cannot be loaded are left out of the run
// (the rest still runs) and reported by name, so a table whose plugin is missing says so in its
// rows instead of failing.
#pragma once

#include <deform/engine/plugin_loader.h>
#include <deform_harness/runner.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace deform::harness {

class Dispatcher;

/// Running a case in a child process: `deformbench run` on the case's scene with a wall-clock
/// limit (child_process.h), so a crash or a hang of any run becomes a failed row and the command
/// goes on. When the child fails (signal, timeout, non-zero exit) and the scene has a reference,
/// the models are run once more alone (--no-reference) in a second child: the reference is then
/// recorded failed with the reason and the models keep their rows (without error columns).
struct ChildCaseOptions {
  std::string executable;               ///< the deformbench program
  std::vector<std::string> pluginArgs;  ///< e.g. pluginDirArgs(loader.searchPath())
  double timeoutS = 900;                ///< per child
  /// Reuse a case finished by an earlier command in the same outDir (its outDir/case.json exists
  /// and the scene it ran is unchanged) instead of running it again.
  bool resume = false;
  /// With resume: a finished case with a failed run (a crash, a timeout, an exception) runs
  /// again instead (`--retry-failed`); ok, diverged and unsupported runs stay as they were.
  bool retryFailed = false;
  /// More arguments of the `deformbench run` child (calibration: --reuse-reference).
  std::vector<std::string> runArgs;
};

struct CaseOptions {
  /// Cache folder: nullopt = Cache::defaultDir(); an empty path disables caching.
  std::optional<std::filesystem::path> cacheDir;
  RunOptions run;  ///< in a child only maxSteps is passed on (as --steps)
  std::function<void(const std::string&)> explain;   ///< --explain lines (may be empty)
  std::function<void(const std::string&)> progress;  ///< the runner's per-run lines (in-process)
  /// Set: run the case in a child process; nullopt: in this process (no time limit).
  std::optional<ChildCaseOptions> child;
  /// Where the child cases run (dispatch.h): nullptr = here, one at a time. Not owned.
  Dispatcher* dispatcher = nullptr;
  /// The case's dispatch stage (dispatch.h): a child case of stage S starts only after every
  /// case of an earlier stage ended.
  int stage = 0;
  /// BenchmarkOptions::reuseReference and reuseModelSolves (in a child: `run --reuse-reference`,
  /// `--reuse-model-solves`): the tables share their reference solves through the cache.
  bool reuseReference = false, reuseModelSolves = false;
};

struct CaseResult {
  std::filesystem::path sceneFile;  ///< the complete scene as written (rerunnable)
  std::filesystem::path outDir;     ///< results.json and surfaces of the runs
  std::optional<BenchmarkResult> result;
  /// plugin name -> why it could not be loaded ("not found in ...", "ABI mismatch ...").
  std::map<std::string, std::string> missing;
  std::string error;  ///< the case could not run at all (bad scene, every plugin missing)
  int organVertices = -1, organFaces = -1;  ///< the organ surface as loaded (-1: unknown)
  double wallS = 0;                         ///< wall time of the case (children included), s
  bool resumed = false;  ///< read back from an earlier command (ChildCaseOptions::resume)

  /// The run with this label (models carry explicit labels in generated scenes), or nullptr.
  const RunRecord* run(const std::string& label) const;
};

/// Writes `scene` to sceneFile, leaves out the models (and reference) whose plugin does not
/// load, runs the rest with runBenchmark into outDir (in this process, or in a child when
/// options.child is set; then `result` holds the runs read back from outDir/results.json, with
/// failed records for the runs a failed child took down, and no scene or organ), and never throws
/// for a model's or plugin's trouble (InputError of the scene itself is caught into `error` too).
CaseResult runSceneCase(const nlohmann::ordered_json& scene, const std::filesystem::path& sceneFile,
                        const std::filesystem::path& outDir, PluginLoader& loader,
                        const CaseOptions& options);

/// A case to run: what runSceneCase takes.
struct SceneCase {
  nlohmann::ordered_json scene;
  std::filesystem::path sceneFile, outDir;
  CaseOptions options;
};

/// runSceneCase for many cases: each is prepared here (scene written, plugins checked, an
/// earlier result resumed), then the child cases go to `dispatcher` (nullptr: here, one at a
/// time; in-process cases always run here, in order). onStart(i) when case i starts, onDone(i,
/// result) when it ended, both in the calling thread; a resumed case gets both at once.
void runSceneCases(const std::vector<SceneCase>& cases, PluginLoader& loader,
                   Dispatcher* dispatcher, const std::function<void(size_t)>& onStart,
                   const std::function<void(size_t, CaseResult&&)>& onDone);

/// Executes a case task (dispatch.h, kind "case"): the `deformbench run` child, and when it
/// fails and the scene has a reference, the models once more without it; writes and returns
/// the case.json document.
nlohmann::ordered_json runCaseTask(const nlohmann::ordered_json& task);

/// The case.json document of a case task no worker could finish: every run failed, `message`.
nlohmann::ordered_json lostCaseDoc(const nlohmann::ordered_json& task, const std::string& message);

/// Why a plugin cannot be loaded ("" when it loads).
std::string pluginProblem(PluginLoader& loader, const std::string& plugin);

struct TableColumn {
  std::string key;     ///< key in each row
  std::string header;  ///< Markdown / CSV header
};

/// A table as the long commands write it: DIR/<name>.md, .csv and .json.
struct Table {
  std::string name;    ///< "bem-timing"
  std::string title;   ///< one line
  std::string source;  ///< what the paper columns come from
  std::vector<std::string> notes;
  std::vector<TableColumn> columns;
  std::vector<nlohmann::ordered_json> rows;  ///< column key -> number, string or null
};

/// Writes DIR/<name>.md, DIR/<name>.csv and DIR/<name>.json (format "deformbench-table/1")
/// atomically. Numbers are printed with 4 significant digits in Markdown, full precision in CSV
/// and JSON; null prints as "-" in Markdown and empty in CSV.
void writeTable(const Table& table, const std::filesystem::path& dir);

/// The cell text of a value for Markdown ("-" for null).
std::string cellText(const nlohmann::ordered_json& v);

/// Number or null (JSON has no NaN/Inf).
nlohmann::ordered_json numberOrNull(double v);

}  // namespace deform::harness
