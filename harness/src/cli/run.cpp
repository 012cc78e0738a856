// deformbench run: every model of a scene, results.json and a table on stdout.
#include "cli.h"

#include <deform/engine/plugin_loader.h>
#include <deform_harness/runner.h>

#include <algorithm>
#include <iostream>
#include <optional>

namespace deform::harness::cli {

namespace {

struct RunArgs {
  std::string scene;
  std::string out;
  bool explain = false;
  std::vector<std::string> only;
  bool noReference = false;
  std::string cacheDir;
  bool noCache = false;
  int steps = -1;
  bool strict = false;
  std::vector<std::string> pluginDirs;
  std::vector<std::string> calibrations;
  bool calibratedTwins = false;
  bool reuseReference = false;
  bool reuseModelSolves = false;
  bool writeCompared = false;
  bool inProcess = false;

  void declare(CLI::App* run) {
    run->add_option("scene", scene, "scene file (JSON)")->required();
    run->add_option("--out", out, "output folder")->required();
    run->add_flag(
        "--explain", explain,
        "say which plugins were loaded, which models built, cache use and what was skipped");
    run->add_option("--only", only,
                    "run only this model (label, model or plugin name; repeatable)");
    run->add_flag("--no-reference", noReference, "do not run the scene's reference");
    auto* cacheOpt = run->add_option("--cache-dir", cacheDir, "precomputation cache folder");
    auto* noCacheOpt = run->add_flag("--no-cache", noCache, "do not read or write the cache");
    cacheOpt->excludes(noCacheOpt);
    run->add_option("--steps", steps, "stop every run after this many steps (quick tries)")
        ->check(positiveValue(true));
    run->add_option("--calibration", calibrations,
                    "calibration.json of `deformbench calibrate`: its model takes those parameters "
                    "where the scene writes none (repeatable, one file per model and organ; "
                    "'shipped': the project's own, for the scene's organ)")
        ->allow_extra_args(false);
    run->add_flag("--calibrated-twins", calibratedTwins,
                  "with --calibration: each calibrated model runs at the scene's parameters and "
                  "calibrated (LABEL+cal), side by side");
    run->add_flag("--reuse-reference", reuseReference,
                  "read the reference from the cache when an earlier run with this flag solved "
                  "the same problem (calibration trials, the tables; its timings are that run's)")
        ->group("");
    run->add_flag("--reuse-model-solves", reuseModelSolves,
                  "with --reuse-reference: quasi-static models too (the tables' reference checks)")
        ->group("");
    run->add_flag("--write-compared", writeCompared,
                  "also write each run's surface at its last compared instant (converge's levels)")
        ->group("");
    run->add_flag("--in-process", inProcess,
                  "run the models in this process (a crash of one ends the command; debuggers)")
        ->group("");
    run->add_flag("--strict", strict,
                  "exit 1 when a model failed (one stderr line each; results.json still written)");
  }
};

void printTable(const BenchmarkResult& r) {
  const bool anyError = std::any_of(r.runs.begin(), r.runs.end(),
                                    [](const RunRecord& run) { return run.error.has_value(); });
  std::vector<std::string> header = {"label",  "status",       "ms/step",
                                     "p95 ms", "precompute s", "counts"};
  if (anyError) {
    for (int k : r.scene.nearest) header.push_back("rmse_" + std::to_string(k) + " mm");
    for (const char* h : {"rmse_all mm", "max mm", "loss_ratio"}) header.push_back(h);
  }
  std::vector<std::vector<std::string>> rows;
  for (const RunRecord& run : r.runs) {
    std::vector<std::string> row;
    row.push_back(run.label + (run.isReference ? " [ref]" : ""));
    row.push_back(run.status == RunStatus::Ok && !run.valid ? std::string("invalid")
                                                            : std::string(statusName(run.status)));
    const bool timed = run.stepStats.samples > 0;
    row.push_back(timed ? fmt(run.stepStats.median) : "-");
    row.push_back(timed ? fmt(run.stepStats.p95) : "-");
    row.push_back(run.status == RunStatus::Unsupported ? "-" : fmt(run.precomputeS));
    std::string counts;
    for (const auto& [k, v] : run.counts)
      counts += (counts.empty() ? "" : " ") + k + "=" + std::to_string(v);
    row.push_back(counts.empty() ? "-" : counts);
    if (anyError) {
      if (run.error) {
        // "*": against an invalid reference (the line under the table says which and why).
        const std::string mark = run.referenceValid.value_or(true) ? "" : "*";
        for (const auto& kv : run.error->rmseNearest) row.push_back(fmt(1e3 * kv.second) + mark);
        row.push_back(fmt(1e3 * run.error->rmseAll) + mark);
        row.push_back(fmt(1e3 * run.error->max) + mark);
        row.push_back(fmt(run.error->lossRatio) + mark);
      } else {
        for (size_t i = 0; i < r.scene.nearest.size() + 3; ++i) row.push_back("-");
      }
    }
    rows.push_back(row);
  }
  std::vector<size_t> width(header.size());
  for (size_t c = 0; c < header.size(); ++c) {
    width[c] = header[c].size();
    for (const auto& row : rows) width[c] = std::max(width[c], row[c].size());
  }
  const auto printRow = [&](const std::vector<std::string>& row) {
    std::string line;
    for (size_t c = 0; c < row.size(); ++c) {
      std::string cell = row[c];
      cell.resize(width[c], ' ');
      line += (c ? "  " : "") + cell;
    }
    while (!line.empty() && line.back() == ' ') line.pop_back();
    std::cout << line << "\n";
  };
  printRow(header);
  for (const auto& row : rows) printRow(row);
  {
    const auto against = std::find_if(r.runs.begin(), r.runs.end(), [](const RunRecord& run) {
      return !run.referenceValid.value_or(true);
    });
    const bool marked = std::any_of(r.runs.begin(), r.runs.end(), [](const RunRecord& run) {
      return run.error && !run.referenceValid.value_or(true);
    });
    if (against != r.runs.end())
      std::cout << (marked ? "*: errors against an invalid reference: " : "no errors: ")
                << against->referenceInvalidReason << "\n";
  }
  for (const RunRecord& run : r.runs) {
    if (run.error && run.error->excludedGrasped > 0) {
      std::cout << "rmse_k: the k surface vertices nearest the grasp that no grasp holds ("
                << run.error->excludedGrasped << " grasped vertices left out)\n";
      break;
    }
  }
  for (const RunRecord& run : r.runs) {
    if (!run.message.empty()) std::cout << run.label << ": " << run.message << "\n";
    for (const auto& n : run.notes) std::cout << run.label << ": note: " << n << "\n";
  }
}

/// Validity (DESIGN "Metrics") of each run that did not do what the scene asked, and the
/// reference's estimated discretisation error when a check of it is in the cache.
void printReferenceCheck(const std::string& sceneFile, const BenchmarkResult& result,
                         PluginLoader& loader, const std::optional<fs::path>& cacheDir) {
  for (const RunRecord& run : result.runs)
    if (run.status == RunStatus::Ok && !run.valid)
      std::cout << "invalid: " << run.label << ": " << run.invalidReason << "\n";
  const auto ref = std::find_if(result.runs.begin(), result.runs.end(),
                                [](const RunRecord& r) { return r.isReference; });
  if (ref == result.runs.end() || ref->status != RunStatus::Ok) return;
  printReferenceCheckLine(ref->label, sceneFile, cachedReferenceCheck(sceneFile, loader, cacheDir),
                          cacheDir);
}

int cmdRun(const RunArgs& a) {
  PluginLoader loader(searchPath(a.pluginDirs));
  BenchmarkOptions options;
  options.only = a.only;
  options.noReference = a.noReference;
  if (a.noCache) {
    options.cacheDir = fs::path();
  } else if (!a.cacheDir.empty()) {
    options.cacheDir = fs::path(a.cacheDir);
  }
  options.outDir = a.out;
  options.run.maxSteps = a.steps;
  options.calibrations = readCalibrations(a.calibrations);
  options.calibratedTwins = a.calibratedTwins;
  if (a.calibratedTwins && a.calibrations.empty())
    throw InputError("--calibrated-twins", "",
                     "needs --calibration FILE (or --calibration shipped): the twins' parameters");
  options.reuseReference = a.reuseReference || a.reuseModelSolves;
  options.reuseModelSolves = a.reuseModelSolves;
  options.writeComparedSurface = a.writeCompared;
  options.isolateRuns = !a.inProcess;
  if (a.explain)
    options.explain = [](const std::string& s) { std::cout << "explain: " << s << "\n"; };
  options.progress = [](const std::string& s) { std::cout << s << "\n" << std::flush; };
  const BenchmarkResult result = runBenchmark(a.scene, loader, options);
  // What "repair" changed in the organ is part of the result (--explain said it already).
  if (!a.explain)
    for (const auto& line : result.organLog) std::cout << "organ: " << line << "\n";
  std::cout << "\n";
  printTable(result);
  printReferenceCheck(a.scene, result, loader, options.cacheDir);
  std::cout << "results: " << result.resultsPath.string() << "\n";
  if (!a.strict) return 0;
  // A model that failed (bad input it alone refuses, such as a self-intersecting surface for a
  // tet mesher, or an exception) is a row of the table; in strict mode it also fails the
  // command, one line per failed run, for pipelines that must notice it.
  int failed = 0;
  for (const RunRecord& run : result.runs) {
    if (run.status != RunStatus::Failed) continue;
    std::cerr << "deformbench: " << a.scene << ": " << run.label << ": " << oneLine(run.message)
              << "\n";
    ++failed;
  }
  return failed ? kExitModelFailed : 0;
}

}  // namespace

Verb addRun(CLI::App& app) {
  return makeVerb<RunArgs>(app, "run", "run every model of a scene and write results.json", cmdRun);
}

}  // namespace deform::harness::cli
