// deformbench stability: every model over stiff and extreme cases, each in its own process.
#include "cli.h"

#include <deform/engine/plugin_loader.h>
#include <deform_harness/progress.h>
#include <deform_harness/stability.h>

#include <iomanip>
#include <iostream>
#include <map>

namespace deform::harness::cli {

namespace {

struct StabilityArgs {
  CommonArgs common;
  bool resume = false, retryFailed = false;
  std::vector<std::string> models, cases;
  double timeout = 0;
  DispatchArgs dispatch;
  bool noPlot = false;

  void declare(CLI::App* stability) {
    stability->add_option("--out", common.out, "output folder")->required();
    stability->add_flag("--resume", resume,
                        "skip the cases already finished in --out (with the same scenes)");
    stability->add_flag("--retry-failed", retryFailed,
                        "with --resume (implied): run the cases that failed again");
    stability->add_option("--model", models, "plugin to test (repeatable; default: all found)");
    stability->add_option("--case", cases, "case id to run (repeatable; default: the set)");
    stability->add_option("--timeout", timeout, "seconds per case (default 120, 60 with --quick)")
        ->check(positiveValue(false));
    addDispatch(stability, dispatch);
    stability->add_flag("--no-plot", noPlot, "write the data only");
    addCommon(stability, common, true);
  }
};

int cmdStability(const StabilityArgs& a) {
  for (const std::string& m : a.models) requirePluginName("--model", m);
  PluginLoader loader(searchPath(a.common.pluginDirs));
  StabilityOptions o;
  o.quick = a.common.quick;
  o.resume = a.resume || a.retryFailed;
  o.retryFailed = a.retryFailed;
  o.outDir = makeOutDir(a.common.out);
  o.models = a.models;
  o.cases = a.cases;
  o.timeoutS = a.timeout;
  o.jobs = a.dispatch.jobs;
  const std::unique_ptr<Dispatcher> dispatcher = makeDispatcher(a.dispatch);
  o.dispatcher = dispatcher.get();
  o.pluginDirs = a.common.pluginDirs;
  if (a.common.noCache) {
    // The child runs use their own cache; --no-cache keeps them out of the user's.
    o.cacheDir = (o.outDir / "cache").string();
  } else {
    o.cacheDir = a.common.cacheDir;
  }
  std::vector<StabilityRecord> records;
  {
    Progress progress(0, "stability");
    records = runStability(loader, o, &progress);
  }
  // Verdicts, never "stable" alone: a run that reached its end may still have collapsed.
  std::map<std::string, std::map<std::string, int>> summary;
  for (const auto& r : records) ++summary[r.model][r.verdict];
  std::cout << "\n";
  for (const auto& [model, counts] : summary) {
    std::cout << std::left << std::setw(18) << model;
    for (const char* s : kStabilityVerdicts)
      std::cout << " " << s << "=" << (counts.count(s) ? counts.at(s) : 0);
    std::cout << "\n";
  }
  if (!a.noPlot)
    plot("plot_stability.py", {(o.outDir / "stability.json").string(), o.outDir.string()});
  std::cout << "stability: " << (o.outDir / "stability.md").string() << "\n";
  return 0;
}

}  // namespace

Verb addStability(CLI::App& app) {
  return makeVerb<StabilityArgs>(
      app, "stability", "every model over stiff and extreme cases, each in its own process",
      cmdStability);
}

}  // namespace deform::harness::cli
