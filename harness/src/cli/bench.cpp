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
};

int cmdBench(const BenchArgs& a);

}  // namespace

Verb addBench(CLI::App& app) {
  auto args = std::make_shared<BenchArgs>();
  BenchArgs& ba = *args;
  CLI::App* bench = app.add_subcommand(
      "bench", "time a fixed set of model x scene cases, or compare two such files");
  bench->add_option("--out", ba.common.out, "bench file to write (JSON)");
  bench->add_option("--compare", ba.compare, "OLD.json NEW.json: print ratios, exit 1 on slowdown")
      ->expected(2);
  bench->add_option("--threshold", ba.threshold, "slowdown flagged above this fraction (0.25)")
      ->check(CLI::NonNegativeNumber);
  bench->add_option("--repeat", ba.repeat, "runs per case (median taken)")
      ->check(positiveValue(true));
  bench->add_option("--steps", ba.steps, "steps per run")->check(positiveValue(true));
  bench->add_option("--only", ba.only, "case id or plugin (repeatable)");
  addCommon(bench, ba.common, false);
  return {bench, [args](const std::vector<std::string>& pluginDirs) {
            args->common.pluginDirs = pluginDirs;
            return cmdBench(*args);
          }};
}

namespace {

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

}  // namespace deform::harness::cli
