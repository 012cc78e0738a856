// deformbench verify: the scene's reference solved by reference_fem and by CalculiX.
#include "cli.h"

#include <deform/engine/plugin_loader.h>
#include <deform_harness/verify.h>

#include <cmath>
#include <iostream>

namespace deform::harness::cli {

namespace {

struct VerifyArgs {
  std::string scene;
  CommonArgs common;
  int steps = -1;
};

int cmdVerify(const std::string& scene, const CommonArgs& a, int steps);

}  // namespace

Verb addVerify(CLI::App& app) {
  auto args = std::make_shared<VerifyArgs>();
  CLI::App* verify = app.add_subcommand(
      "verify", "the scene's reference solved by reference_fem and by CalculiX (ccx) on one mesh");
  verify->add_option("scene", args->scene, "scene file with a reference")->required();
  verify->add_option("--out", args->common.out, "output folder (verify.json)")->required();
  verify->add_option("--steps", args->steps, "stop after this many steps")
      ->check(CLI::PositiveNumber);
  addCommon(verify, args->common, false);
  return {verify, [args](const std::vector<std::string>& pluginDirs) {
            args->common.pluginDirs = pluginDirs;
            return cmdVerify(args->scene, args->common, args->steps);
          }};
}

namespace {

int cmdVerify(const std::string& scene, const CommonArgs& a, int steps) {
  PluginLoader loader(searchPath(a.pluginDirs));
  VerifyOptions o;
  o.outDir = makeOutDir(a.out);
  o.cacheDir = cacheChoice(a);
  o.maxSteps = steps;
  const VerifyResult r = runVerify(scene, loader, o);
  const auto times = [](const VerifySolverTimes& t) {
    return fmt(t.wallS) + " s wall, " + fmt(t.cpuS) + " s CPU";
  };
  for (const VerifyInstant& in : r.instants)
    std::cout << "t = " << fmt(in.time) << " s: calculix differs from reference_fem by "
              << fmt(100 * in.rmsRelative) << "% RMS, " << fmt(100 * in.maxRelative)
              << "% max of the RMS displacement " << fmt(1e3 * in.referenceRms) << " mm ("
              << in.vertices << " vertices); reference_fem " << times(in.reference) << ", calculix "
              << times(in.calculix)
              << (std::isnan(in.formulationRmsRelative)
                      ? std::string()
                      : "; the scene's mean-dilatation reference differs from reference_fem by " +
                            fmt(100 * in.formulationRmsRelative) + "% RMS, " +
                            fmt(100 * in.formulationMaxRelative) + "% max")
              << "\n";
  for (const std::string& note : r.notes) std::cout << "note: " << note << "\n";
  if (!r.message.empty())
    std::cout << "warning: " << r.message << "\n";
  else if (!r.agrees)
    std::cout << "warning: the solvers differ by more than " << fmt(100 * kVerifyGoal)
              << "% RMS at some instant\n";
  std::cout << "wrote " << r.jsonPath.string() << "\n";
  return 0;
}

}  // namespace

}  // namespace deform::harness::cli
