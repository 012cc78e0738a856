// deformbench harness: running generated scenes as "cases" of the long commands (tables, sweep,
// bench) through the plugin loader and the runner, and writing tables as Markdown, CSV and JSON.
//
// A case is a scene (JSON) written into the output folder, so that any row can be rerun with
// `deformbench run SCENE`. Plugins the scene names that cannot be loaded are left out of the run
// (the rest still runs) and reported by name, so a table whose plugin is missing says so in its
// rows instead of failing.
#pragma once

#include <deform/plugin_loader.h>
#include <deform_harness/runner.h>

#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace deform::harness {

struct CaseOptions {
  /// Cache folder: nullopt = Cache::defaultDir(); an empty path disables caching.
  std::optional<std::filesystem::path> cacheDir;
  RunOptions run;
  std::function<void(const std::string&)> explain;   ///< --explain lines (may be empty)
  std::function<void(const std::string&)> progress;  ///< the runner's per-run lines
};

struct CaseResult {
  std::filesystem::path sceneFile;  ///< the complete scene as written (rerunnable)
  std::filesystem::path outDir;     ///< results.json and surfaces of the runs
  std::optional<BenchmarkResult> result;
  /// plugin name -> why it could not be loaded ("not found in ...", "ABI mismatch ...").
  std::map<std::string, std::string> missing;
  std::string error;  ///< the case could not run at all (bad scene, every plugin missing)

  /// The run with this label (models carry explicit labels in generated scenes), or nullptr.
  const RunRecord* run(const std::string& label) const;
};

/// Writes `scene` to sceneFile, leaves out the models (and reference) whose plugin does not
/// load, runs the rest with runBenchmark into outDir, and never throws for a model's or plugin's
/// trouble (InputError of the scene itself is caught into `error` too).
CaseResult runSceneCase(const nlohmann::ordered_json& scene, const std::filesystem::path& sceneFile,
                        const std::filesystem::path& outDir, PluginLoader& loader,
                        const CaseOptions& options);

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
