// deformbench calibrate: a model's calibratable parameters fitted to training scenes.
#include "cli.h"

#include <deform/engine/plugin_loader.h>
#include <deform_harness/calibration.h>
#include <deform_harness/child_process.h>
#include <deform_harness/progress.h>
#include <deform_harness/tables.h>

#include <iomanip>
#include <iostream>

namespace deform::harness::cli {

namespace {

struct CalibrateArgs {
  CommonArgs common;
  std::vector<std::string> train, validate, params, material;
  std::string model, metric, label;
  int budget = 40;
  int truthCubeLevel = 0;  ///< --truth-cube (1-based); 0: none
  std::string truthCubeData, contact = "bonded";
  double timeout = 0;
  DispatchArgs dispatch;

  void declare(CLI::App* calibrate) {
    calibrate->add_option("scenes", train,
                          "training scene files (with a reference, or measured marker positions)");
    calibrate->add_option("--model", model, "plugin to calibrate")->required();
    calibrate->add_option("--out", common.out, "output folder (calibration.json)")->required();
    calibrate->add_option("--validate", validate, "held-out scene (repeatable)")
        ->allow_extra_args(false);
    calibrate->add_option(
        "--metric", metric,
        "rmse_all (default), rmse_50, loss_ratio, or marker_rms (against measured "
        "markers; the default with --truth-cube)");
    calibrate->add_option("--truth-cube", truthCubeLevel,
                          "train on this compression level of the Truth Cube (1-based), validate "
                          "on the others; metric marker_rms");
    calibrate->add_option("--truth-cube-data", truthCubeData,
                          "the bead file (default: data/truth-cube/uniaxial_positions.csv)");
    calibrate->add_option("--contact", contact,
                          "the Truth Cube's plate: bonded (default) or sliding");
    calibrate
        ->add_option("--material", material,
                     "fit the organ's young or poisson too (repeatable; marker_rms only)")
        ->allow_extra_args(false);
    calibrate->add_option("--budget", budget, "trials at most (default 40)");
    calibrate->add_option("--label", label, "free text kept in calibration.json");
    calibrate
        ->add_option("--param", params, "calibrate only this calibratable parameter (repeatable)")
        ->allow_extra_args(false);
    calibrate
        ->add_option("--timeout", timeout,
                     "seconds per model run, each in its own process "
                     "(default 900)")
        ->check(positiveValue(false));
    addDispatch(calibrate, dispatch);
    addCommon(calibrate, common, false);
  }
};

int cmdCalibrate(const CalibrateArgs& a) {
  PluginLoader loader(searchPath(a.common.pluginDirs));
  CalibrateOptions o;
  o.train = a.train;
  o.validate = a.validate;
  o.plugin = a.model;
  o.params = a.params;
  o.material = a.material;
  o.label = a.label;
  o.budget = a.budget;
  const std::string metric = !a.metric.empty()      ? a.metric
                             : a.truthCubeLevel > 0 ? "marker_rms"
                                                    : "rmse_all";
  if (!calibMetricFromName(metric, o.metric))
    throw InputError(
        "--metric", "",
        "unknown metric '" + metric + "' (rmse_all, rmse_50, loss_ratio or marker_rms)");
  if (a.budget < 1) throw InputError("--budget", "", "must be at least 1 (trials)");
  if (a.model.empty()) throw InputError("--model", "", "name the plugin to calibrate");
  o.outDir = makeOutDir(a.common.out);
  o.truthCubeLevel = a.truthCubeLevel;
  o.truthCubeData = a.truthCubeData;
  o.truthCubeContact = a.contact;
  o.cases = caseOptions(a.common);
  if (!a.dispatch.slurm.empty())
    throw InputError("--slurm", "",
                     "calibrate chooses its trials as results come: use --jobs "
                     "or --mpi");
  const std::unique_ptr<Dispatcher> dispatcher = makeDispatcher(a.dispatch);
  o.cases.dispatcher = dispatcher.get();
  ChildCaseOptions child;
  child.executable = selfExecutable();
  child.pluginArgs = pluginDirArgs(loader.searchPath());
  child.runArgs = {"--reuse-reference"};
  if (a.timeout > 0) child.timeoutS = a.timeout;
  o.cases.child = child;
  nlohmann::ordered_json doc;
  {
    Progress progress(a.budget, "calibrate");
    doc = runCalibration(loader, o, &progress);
  }
  const auto mm = [&](const nlohmann::ordered_json& v) {
    if (!v.is_number()) return std::string("-");
    return doc["metric"] == "loss_ratio" ? fmt(v.get<double>(), 4)
                                         : fmt(1e3 * v.get<double>(), 4) + " mm";
  };
  std::cout << "\n"
            << doc["plugin"].get<std::string>() << " calibrated on "
            << doc["train"]["per_scene"].size() << " scene(s), " << doc["evaluations"].get<int>()
            << " trials, " << fmt(doc["wall_s"].get<double>(), 3) << " s; metric "
            << doc["metric"].get<std::string>() << "\n";
  for (const auto& [k, v] : doc["params"].items())
    std::cout << "  " << k << " = " << fmt(v.get<double>(), 5) << " (default "
              << fmt(doc["defaults"][k].get<double>(), 5) << ")\n";
  const nlohmann::ordered_json material = doc.value("material", nlohmann::ordered_json::object());
  for (const auto& [k, v] : material.items())
    std::cout << "  organ " << k << " = " << fmt(v.get<double>(), 5) << " (default "
              << fmt(doc["defaults"]["material." + k].get<double>(), 5) << ")\n";
  for (const auto& w : doc["warnings"]) std::cout << "warning: " << w.get<std::string>() << "\n";
  for (const char* set : {"train", "validation"}) {
    for (const auto& p : doc[set]["per_scene"])
      std::cout << "  " << std::left << std::setw(11) << set << std::setw(48)
                << fs::path(p["scene"].get<std::string>()).filename().string() << " before "
                << std::setw(12) << mm(p["before"]) << " after " << mm(p["after"]) << "\n";
    if (!doc[set]["per_scene"].empty())
      std::cout << "  " << std::left << std::setw(11) << set << std::setw(48) << "mean"
                << " before " << std::setw(12) << mm(doc[set]["before"]) << " after "
                << mm(doc[set]["after"]) << "\n";
  }
  std::cout << "calibration: " << (o.outDir / "calibration.json").string() << "\n";
  return 0;
}

}  // namespace

Verb addCalibrate(CLI::App& app) {
  return makeVerb<CalibrateArgs>(app, "calibrate",
                                 "fit a model's calibratable parameters to the reference of "
                                 "training scenes, or to measured markers (--truth-cube)",
                                 cmdCalibrate);
}

}  // namespace deform::harness::cli
