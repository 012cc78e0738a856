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
  bool equilibriumOnly = false;

  void declare(CLI::App* verify) {
    verify->add_option("scene", scene, "scene file with a reference")->required();
    verify->add_option("--out", common.out, "output folder (verify.json)")->required();
    verify->add_option("--steps", steps, "stop after this many steps")->check(CLI::PositiveNumber);
    verify->add_flag("--equilibrium-only", equilibriumOnly,
                     "skip CalculiX's own solve: only check reference_fem's answer with "
                     "CalculiX's elements");
    addCommon(verify, common, false);
  }
};

int cmdVerify(const VerifyArgs& v) {
  const CommonArgs& a = v.common;
  PluginLoader loader(searchPath(a.pluginDirs));
  VerifyOptions o;
  o.outDir = makeOutDir(a.out);
  o.cacheDir = cacheChoice(a);
  o.maxSteps = v.steps;
  o.equilibriumOnly = v.equilibriumOnly;
  const VerifyResult r = runVerify(v.scene, loader, o);
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
  for (const VerifyEquilibrium& e : r.equilibrium) {
    std::cout << "t = " << fmt(e.time) << " s: ";
    if (e.status != "ok") {
      std::cout << "no equilibrium check: " << e.status << "\n";
      continue;
    }
    std::cout << "calculix's elements at reference_fem's answer: residual "
              << fmt(e.residualRelative) << " (max node " << fmt(e.maxRelative) << ") of "
              << fmt(e.forceScale) << " N over " << e.freeNodes << " free nodes";
    if (!std::isnan(e.graspForceRelative))
      std::cout << ", grasp forces differ by " << fmt(e.graspForceRelative) << " of it";
    std::cout << "; calculix " << times(e.calculix) << "\n";
  }
  for (const std::string& note : r.notes) std::cout << "note: " << note << "\n";
  if (!r.message.empty())
    std::cout << "warning: " << r.message << "\n";
  else if (!r.agrees)
    std::cout << "warning: the solvers differ by more than " << fmt(100 * kVerifyGoal)
              << "% RMS at some instant\n";
  if (!r.equilibrium.empty() && !r.equilibriumAgrees)
    std::cout << "warning: the equilibrium check did not pass at every instant (goal: residual "
              << fmt(kEquilibriumGoal) << " of the force scale)\n";
  std::cout << "wrote " << r.jsonPath.string() << "\n";
  return 0;
}

}  // namespace

Verb addVerify(CLI::App& app) {
  return makeVerb<VerifyArgs>(
      app, "verify",
      "the scene's reference solved by reference_fem and by CalculiX (ccx) on one mesh", cmdVerify);
}

}  // namespace deform::harness::cli
