// Reading a results.json run back into a RunRecord (see results.h), for the long commands that
// run their cases in child processes and build their rows from what the child wrote.
#include <deform_harness/results.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace deform::harness {

using json = nlohmann::json;

namespace {

double numberOrNaN(const json& j, const char* key) {
  if (!j.contains(key) || !j[key].is_number()) return std::numeric_limits<double>::quiet_NaN();
  return j[key].get<double>();
}

/// j[key] as a T, or `fallback` when it is absent or null.
/// j[key] when it is an object, else an empty object (a copy: safe to iterate).
json objectAt(const json& j, const char* key) {
  return j.contains(key) && j[key].is_object() ? j[key] : json::object();
}

template <class T>
T valueOr(const json& j, const char* key, T fallback) {
  if (!j.contains(key) || j[key].is_null()) return fallback;
  return j[key].get<T>();
}

RunStatus parseStatus(const std::string& s) {
  for (RunStatus st :
       {RunStatus::Ok, RunStatus::Diverged, RunStatus::Unsupported, RunStatus::Failed})
    if (s == statusName(st)) return st;
  throw std::runtime_error("unknown run status '" + s + "'");
}

}  // namespace

RunRecord runFromJson(const json& j) {
  RunRecord r;
  r.model = j.at("model").get<std::string>();
  r.plugin = j.value("plugin", "");
  r.label = j.at("label").get<std::string>();
  r.isReference = j.value("role", "model") == "reference";
  r.params = j.value("params", json::object());
  r.status = parseStatus(j.at("status").get<std::string>());
  r.message = j.value("message", "");
  r.notes = j.value("notes", std::vector<std::string>());
  r.calibration = j.value("calibration", "");
  const json counts = objectAt(j, "counts");
  for (const auto& [k, v] : counts.items())
    if (v.is_number()) r.counts[k] = v.get<long long>();
  r.precomputeS = valueOr(j, "precompute_s", 0.0);
  r.steps = valueOr(j, "steps", 0);
  r.plannedSteps = valueOr(j, "planned_steps", 0);
  r.solvedSteps = valueOr(j, "solved_steps", -1);
  if (j.contains("step_ms") && j["step_ms"].is_object()) {
    const json& s = j["step_ms"];
    r.stepStats.median = numberOrNaN(s, "median");
    r.stepStats.p95 = numberOrNaN(s, "p95");
    r.stepStats.max = numberOrNaN(s, "max");
    r.stepStats.mean = numberOrNaN(s, "mean");
    r.stepStats.samples = valueOr(s, "samples", 0);
  }
  const json phases = objectAt(j, "phase_ms");
  for (const auto& [k, v] : phases.items())
    r.phaseMs[k] = v.is_number() ? v.get<double>() : std::nan("");
  const json numeric = objectAt(j, "numeric");
  for (const auto& [k, v] : numeric.items())
    if (v.is_number()) r.numeric[k] = v.get<long long>();
  r.fixedNodes = valueOr(j, "fixed_nodes", 0);
  if (j.contains("error") && j["error"].is_object()) {
    const json& e = j["error"];
    ErrorMetrics m;
    // "<prefix><k>" keys, k all digits: rmse_k and reference_displacement_k.
    const auto perK = [&e](const std::string& prefix) {
      std::vector<std::pair<int, double>> out;
      for (const auto& [k, v] : e.items()) {
        const std::string digits = k.rfind(prefix, 0) == 0 ? k.substr(prefix.size()) : "";
        if (!digits.empty() && std::all_of(digits.begin(), digits.end(),
                                           [](unsigned char c) { return std::isdigit(c); }))
          out.emplace_back(std::stoi(digits), numberOrNaN(e, k.c_str()));
      }
      std::sort(out.begin(), out.end());
      return out;
    };
    m.rmseNearest = perK("rmse_");
    m.referenceNearest = perK("reference_displacement_");
    m.rmseAll = numberOrNaN(e, "rmse_all");
    m.max = numberOrNaN(e, "max");
    m.lossRatio = numberOrNaN(e, "loss_ratio");
    m.instants = valueOr(e, "instants", 0);
    m.nearestSamples = e.value("rmse_k_samples", std::string("nearest"));
    m.excludedGrasped = valueOr(e, "rmse_k_excluded_grasped", 0);
    r.error = m;
    r.referenceModel = e.value("reference", "");
  }
  r.emptyGrasps = j.value("empty_grasps", std::vector<int>());
  r.graspResidual = valueOr(j, "grasp_residual_m", -1.0);
  r.equilibrium = j.contains("settled_at_s");
  if (j.contains("settled_at_s") && j["settled_at_s"].is_number())
    r.settledAt = j["settled_at_s"].get<double>();
  // Results written before validity existed: a run is valid unless its status says otherwise.
  r.valid = j.value("valid", r.status == RunStatus::Ok) && r.status == RunStatus::Ok;
  r.invalidReason = j.value("invalid_reason", r.valid ? "" : statusName(r.status));
  if (j.contains("reference_valid") && j["reference_valid"].is_boolean()) {
    r.referenceValid = j["reference_valid"].get<bool>();
    r.referenceInvalidReason = j.value("reference_invalid_reason", "");
  }
  r.finalSurfaceFile = j.value("final_surface", "");
  r.seriesFile = j.value("surface_series", "");
  r.graspForceFile = j.value("grasp_forces", "");
  return r;
}

}  // namespace deform::harness
