// Planning a scene's runs: every plugin loaded and every parameter validated before anything runs.
#include <deform/engine/interaction.h>
#include <deform/internal/atomic_file.h>
#include <deform/sdk/contact.h>
#include <deform_harness/results.h>
#include <deform_harness/run_isolation.h>
#include <deform_harness/runner.h>
#include <deform_harness/stability.h>

#include <algorithm>
#include <set>
#include <sstream>

namespace deform::harness {

namespace {

bool matchesOnly(const BenchmarkOptions& options, const PlannedRun& run) {
  if (options.only.empty()) return true;
  for (const std::string& o : options.only) {
    if (o == run.label || o == run.spec.model || o == run.spec.plugin) return true;
  }
  return false;
}

}  // namespace

std::vector<PlannedRun> planRuns(const Scene& scene, PluginLoader& loader,
                                 const BenchmarkOptions& options) {
  const auto explain = [&](const std::string& s) {
    if (options.explain) options.explain(s);
  };
  std::vector<const ModelSpec*> specs;
  for (const ModelSpec& m : scene.models) specs.push_back(&m);
  if (scene.reference) {
    if (options.noReference) {
      explain("skipped the reference " + scene.reference->model + ": --no-reference");
    } else {
      specs.push_back(&*scene.reference);
    }
  }
  std::vector<PlannedRun> planned;
  std::set<std::string> labels;
  const std::string organ =
      calibrationOrgan(scene.organ.mesh, scene.organ.resolution, scene.organ.scale);
  // Each model once, or with calibratedTwins and a calibration twice: as written, then its twin.
  std::vector<std::pair<const ModelSpec*, bool>> runs;
  for (const ModelSpec* spec : specs) {
    const bool isReference = scene.reference && spec == &*scene.reference;
    const ModelInfo& info = loader.load(spec->plugin, spec->model);
    const bool calibrated = !isReference && calibrationFor(options.calibrations, spec->plugin,
                                                           info.name, organ, false) != nullptr;
    if (options.calibratedTwins && calibrated) runs.emplace_back(spec, false);
    runs.emplace_back(spec, calibrated);
  }
  for (const auto& [spec, calibrated] : runs) {
    PlannedRun run;
    run.spec = *spec;
    run.isReference = scene.reference && spec == &*scene.reference;
    run.info = &loader.load(spec->plugin, spec->model);
    nlohmann::json given = spec->params;
    const CalibrationParams* calibration =
        calibrated
            ? calibrationFor(options.calibrations, spec->plugin, run.info->name, organ, false)
            : nullptr;
    if (calibration) {
      nlohmann::json merged = calibration->params;
      for (const auto& [k, v] : spec->params.items()) merged[k] = v;
      given = merged;
    }
    run.params = resolveParams(run.info->params, given, scene.file, spec->jsonPath + "/params");
    if (calibration) {
      run.calibrationNote = calibratedRunNote(*calibration, paramsToJson(run.params));
      run.calibrationFile = calibration->file;
    }
    if (options.explain) {
      // Where each parameter came from: the scene, a calibration file, or the default.
      std::string from;
      for (const ParamSpec& ps : run.info->params) {
        std::string source = "default";
        if (spec->params.contains(ps.key)) {
          source = "scene";
          if (calibration && calibration->params.contains(ps.key))
            source += ", over calibration " + calibration->file;
        } else if (calibration && calibration->params.contains(ps.key)) {
          source = "calibration " + calibration->file;
        }
        if (source == "default") continue;
        from += (from.empty() ? "" : "; ") + ps.key + " from " + source;
      }
      explain("params of " + spec->plugin + "/" + run.info->name + " at " + spec->jsonPath + ": " +
              (from.empty() ? std::string("all defaults") : from + "; the rest defaults"));
    }
    const std::string twin = options.calibratedTwins && calibration ? "+cal" : "";
    if (!spec->label.empty()) {
      run.label = spec->label + twin;
    } else if (!twin.empty()) {
      // The label of the model it is the twin of (the calibration's values are not defaults).
      const ParamValues own =
          resolveParams(run.info->params, spec->params, scene.file, spec->jsonPath + "/params");
      const std::string nd = formatNonDefault(own, run.info->params);
      run.label = (nd.empty() ? spec->model : spec->model + "(" + nd + ")") + twin;
    } else {
      const std::string nd = formatNonDefault(run.params, run.info->params);
      run.label = nd.empty() ? spec->model : spec->model + "(" + nd + ")";
      if (labels.count(run.label)) {
        int i = 2;
        while (labels.count(run.label + " #" + std::to_string(i))) ++i;
        run.label += " #" + std::to_string(i);
      }
    }
    labels.insert(run.label);
    planned.push_back(std::move(run));
  }
  std::vector<PlannedRun> kept;
  for (PlannedRun& run : planned) {
    if (!matchesOnly(options, run) && !run.isReference) {
      explain("skipped " + run.label + ": not selected by --only");
      continue;
    }
    kept.push_back(std::move(run));
  }
  if (!options.only.empty()) {
    const bool any =
        std::any_of(kept.begin(), kept.end(), [](const PlannedRun& r) { return !r.isReference; });
    if (!any) {
      std::string names;
      for (const PlannedRun& r : planned) names += (names.empty() ? "" : ", ") + r.label;
      std::string given;
      for (const auto& o : options.only) given += (given.empty() ? "" : ", ") + o;
      throw InputError(
          "--only", "",
          "no model of the scene matches '" + given + "' (the scene has: " + names + ")");
    }
  }
  for (const std::string& f : loader.loadedFiles()) explain("loaded plugin " + f);
  for (const PlannedRun& r : kept) {
    explain(std::string("built ") + (r.isReference ? "reference " : "model ") + r.label + " = " +
            r.spec.plugin + "/" + r.info->name + " " + paramsToJson(r.params).dump());
  }
  return kept;
}

}  // namespace deform::harness
