// deformbench bench: a fixed set of timed cases, or two such files compared.
#include "cli.h"

#include <deform/engine/plugin_loader.h>
#include <deform_harness/bench.h>
#include <deform_harness/progress.h>

#include <iostream>

namespace deform::harness::cli {

namespace {

struct BenchArgs {
  CommonArgs common;
  std::vector<std::string> compare;
  double threshold = 0.25;
  int repeat = 3;
  int steps = 100;
  std::vector<std::string> only;

  void declare(CLI::App* bench) {
    bench->add_option("--out", common.out, "bench file to write (JSON)");
    bench->add_option("--compare", compare, "OLD.json NEW.json: print ratios, exit 1 on slowdown")
        ->expected(2);
    bench->add_option("--threshold", threshold, "slowdown flagged above this fraction (0.25)")
        ->check(CLI::NonNegativeNumber);
    bench->add_option("--repeat", repeat, "runs per case (median taken)")
        ->check(positiveValue(true));
    bench->add_option("--steps", steps, "steps per run")->check(positiveValue(true));
    bench->add_option("--only", only, "case id or plugin (repeatable)");
    addCommon(bench, common, false);
  }
};

int cmdBench(const BenchArgs& a) {
  if (!a.compare.empty()) {
    if (a.compare.size() != 2) throw InputError("--compare", "", "give OLD.json NEW.json");
    const auto oldDoc = readBenchFile(a.compare[0]);
    const auto newDoc = readBenchFile(a.compare[1]);
    const BenchComparison c = compareBench(oldDoc, newDoc, a.threshold);
    printBenchComparison(c, a.threshold, std::cout);
    return c.regressions > 0 ? 1 : 0;
  }
  if (a.common.out.empty()) throw InputError("bench", "", "--out FILE.json or --compare OLD NEW");
  PluginLoader loader(searchPath(a.common.pluginDirs));
  BenchOptions o;
  o.out = a.common.out;
  if (o.out.has_parent_path()) fs::create_directories(o.out.parent_path());
  o.repeat = a.repeat;
  o.steps = a.steps;
  o.only = a.only;
  o.cases = caseOptions(a.common);
  {
    Progress progress(0, "bench");
    runBench(loader, o, &progress);
  }
  std::cout << "bench: " << o.out.string() << "\n";
  return 0;
}

}  // namespace

Verb addBench(CLI::App& app) {
  return makeVerb<BenchArgs>(
      app, "bench", "time a fixed set of model x scene cases, or compare two such files", cmdBench);
}

}  // namespace deform::harness::cli
