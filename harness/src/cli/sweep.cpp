// deformbench sweep: error against run time, each model over its two cost axes.
#include "cli.h"

#include <deform/engine/plugin_loader.h>
#include <deform_harness/calibration.h>
#include <deform_harness/child_process.h>
#include <deform_harness/progress.h>
#include <deform_harness/sweep.h>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <set>

namespace deform::harness::cli {

namespace {

struct SweepArgs {
  std::string scene;
  CommonArgs common;
  bool noPlot = false;
  std::vector<std::string> calibrations;
  bool calibrate = false;
  int calibrateBudget = 12;
  std::string calibrateMetric = "rmse_50";
  ChildArgs child;

  void declare(CLI::App* sweep) {
    sweep->add_option("scene", scene, "scene file with a reference")->required();
    sweep->add_option("--out", common.out, "output folder")->required();
    sweep->add_flag("--no-plot", noPlot, "write the data only");
    sweep
        ->add_option("--calibration", calibrations,
                     "calibration.json: its model is swept at its defaults and calibrated "
                     "(repeatable)")
        ->allow_extra_args(false);
    sweep->add_flag("--calibrate", calibrate,
                    "fit every point's calibratable parameters on the scene and run each point "
                    "once more at its fit (+cal)");
    sweep->add_option("--calibrate-budget", calibrateBudget,
                      "--calibrate: trials per point (default 12)");
    sweep->add_option("--calibrate-metric", calibrateMetric,
                      "--calibrate: rmse_50 (default, the front's), rmse_all or loss_ratio");
    sweep->add_flag("--explain", common.explain, "say what was loaded, built, cached, skipped");
    addCommon(sweep, common, true);
    addChildArgs(sweep, child, "point");
  }
};

int cmdSweep(SweepArgs& args, const CLI::App& cmd) {
  args.child.given = childArgsGiven(cmd);
  const CommonArgs& a = args.common;
  const ChildArgs& ch = args.child;
  const std::string& scene = args.scene;
  PluginLoader loader(searchPath(a.pluginDirs));
  SweepOptions o;
  if (args.calibrate && !args.calibrations.empty())
    throw InputError("--calibrate", "",
                     "fits every point itself: give it or --calibration FILE, not both");
  if (args.calibrateBudget < 1) throw InputError("--calibrate-budget", "", "must be at least 1");
  if (!calibMetricFromName(args.calibrateMetric, o.calibrateMetric))
    throw InputError(
        "--calibrate-metric", "",
        "unknown metric '" + args.calibrateMetric + "' (rmse_50, rmse_all or loss_ratio)");
  if (args.calibrate && !ch.dispatch.slurm.empty())
    throw InputError("--slurm", "",
                     "--calibrate chooses its trials as results come: use --jobs or --mpi");
  o.calibrate = args.calibrate;
  o.calibrateBudget = args.calibrateBudget;
  o.calibrations = readCalibrations(args.calibrations);
  o.quick = a.quick;
  o.outDir = makeOutDir(a.out);
  o.cases = caseOptions(a);
  const std::unique_ptr<Dispatcher> dispatcher = makeDispatcher(ch.dispatch);
  o.cases.dispatcher = dispatcher.get();
  o.cases.child = childOptions(ch, loader, 900);
  if (o.calibrate) {  // the trials always run in children, like calibrate's
    ChildCaseOptions trial;
    trial.executable = selfExecutable();
    trial.pluginArgs = pluginDirArgs(loader.searchPath());
    trial.runArgs = {"--reuse-reference"};
    o.calibrateChild = trial;
  }
  std::vector<SweepPoint> points;
  std::optional<ConvergenceResult> referenceCheck;
  {
    Progress progress(0, "sweep");
    points = runSweep(scene, loader, o, &progress, &referenceCheck);
  }
  size_t w = 6;
  for (const SweepPoint& p : points) w = std::max(w, p.label.size() + 2);
  std::cout << "\n";
  std::cout << std::left << std::setw(int(w)) << "point" << std::setw(12) << "status"
            << std::setw(10) << "ms/step" << std::setw(14) << "rmse_50 mm" << std::setw(14)
            << "rmse_all mm"
            << "pareto\n";
  for (const SweepPoint& p : points) {
    const std::string status = p.status == "ok" && !p.valid ? "invalid" : p.status;
    std::cout << std::left << std::setw(int(w)) << p.label << std::setw(12)
              << (status.size() > 11 ? status.substr(0, 11) : status) << std::setw(10)
              << fmt(p.msMedian) << std::setw(14) << fmt(1e3 * p.rmseNearest) << std::setw(14)
              << fmt(1e3 * p.rmseAll) << (p.pareto ? "*" : "") << "\n";
  }
  // Each model's curve: its slopes along the axes and where its error stops falling.
  std::cout << "\nper model (rmse_50; slopes are d ln(error) / d ln(ms per step)):\n";
  for (const SweepModelSummary& m : summariseSweep(points)) {
    std::cout << "  " << m.model << (m.calibrated ? " calibrated" : "") << ": ";
    const auto slope = [](const std::string& param, double v) {
      return param.empty() || !std::isfinite(v) ? std::string()
                                                : "slope along " + param + " " + fmt(v) + "; ";
    };
    std::cout << slope(m.resolutionParam, m.rmse50.slopeResolution)
              << slope(m.effortParam, m.rmse50.slopeEffort) << m.rmse50.floor.text << "\n";
    // The resolution axis' descent on both errors: rmse_50 is the tissue at the tool, rmse_all
    // the whole organ, where a discretisation's convergence shows first.
    for (const auto& [name, s] :
         {std::pair{"rmse_50", &m.rmse50}, std::pair{"rmse_all", &m.rmseAll}})
      if (!s->descent.text.empty())
        std::cout << "    along " << m.resolutionParam << ", " << name << ": " << s->descent.text
                  << "\n";
  }
  // The yardstick's own uncertainty, beside the floors above (sweep.json reference_check).
  if (!points.empty()) printReferenceCheckLine("", scene, referenceCheck, o.cases.cacheDir);
  std::set<std::string> notes;  // the calibrated points' (the same for most of them)
  for (const SweepPoint& p : points)
    if (!p.note.empty() && notes.insert(p.note).second) std::cout << "note: " << p.note << "\n";
  if (!args.noPlot)
    plot("plot_sweep.py", {(o.outDir / "sweep.json").string(), (o.outDir / "sweep.png").string()});
  std::cout << "sweep: " << (o.outDir / "sweep.json").string() << "\n";
  return 0;
}

}  // namespace

Verb addSweep(CLI::App& app) {
  return makeVerb<SweepArgs>(
      app, "sweep",
      "error against run time: each model over its resolution and solver effort, with a plot",
      cmdSweep);
}

}  // namespace deform::harness::cli
