// The reference's mesh convergence from three runs of the reference plugin (see convergence.h).
#include <deform/engine/interaction.h>
#include <deform/geometry/organ_tets.h>
#include <deform/geometry/tet_mesher.h>
#include <deform/internal/atomic_file.h>
#include <deform/sdk/cache.h>
#include <deform_harness/cases.h>
#include <deform_harness/convergence.h>
#include <deform_harness/json_file.h>
#include <deform_harness/runner.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <fstream>

namespace deform::harness {

namespace fs = std::filesystem;
using ojson = nlohmann::ordered_json;

namespace {

std::string fixedDigits(double v, int digits) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

std::string mm(double m) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g mm", 1e3 * m);
  return buf;
}

/// The observed order p of differences d01, d12 on levels h0 > h1 > h2: the root of
/// (h0^p - h1^p) / (h1^p - h2^p) = d01 / d12, which grows monotonically in p (bisection on
/// [1e-3, 20]). -1: the ratio is below the root's range (the differences shrink more slowly
/// than any positive order: not monotone); +inf: above it.
double observedOrder(double h0, double h1, double h2, double d01, double d12) {
  const auto f = [&](double p) {
    return (std::pow(h0, p) - std::pow(h1, p)) / (std::pow(h1, p) - std::pow(h2, p));
  };
  const double target = d01 / d12;
  double lo = 1e-3, hi = 20;
  if (target <= f(lo)) return -1;
  if (target >= f(hi)) return INFINITY;
  for (int i = 0; i < 200; ++i) {
    const double mid = 0.5 * (lo + hi);
    (f(mid) < target ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

/// Why three levels cannot be extrapolated by size alone ("" when they can): reason and message.
std::pair<std::string, std::string> levelsProblem(double h0, double h1, double h2) {
  if (!(h0 > 0 && h1 > 0 && h2 > 0) || !(h0 > h1 && h1 > h2))
    return {"not_refining", "the levels do not refine (h " + mm(h0) + ", " + mm(h1) + ", " +
                                mm(h2) + " from their tet counts)"};
  if (h0 / h1 < kMinLevelRatio || h1 / h2 < kMinLevelRatio)
    return {"levels_too_close",
            "the levels are too close in size to extrapolate (h ratios " + fixedDigits(h0 / h1, 2) +
                " and " + fixedDigits(h1 / h2, 2) + ", below " + fixedDigits(kMinLevelRatio, 1) +
                ": all of the organ's surface vertices are nodes, so a fine surface bounds the "
                "coarse levels' size; refine from a smaller h)"};
  return {};
}

/// The error of the estimated level from the finest pair's difference d12 at order q: the finest
/// level's d12 h2^q / (h1^q - h2^q), or the middle one's d12 h1^q / (h1^q - h2^q).
double extrapolatedError(double h1, double h2, double d12, double q, EstimateOf of) {
  const double denominator = std::pow(h1, q) - std::pow(h2, q);
  return d12 * std::pow(of == EstimateOf::Middle ? h1 : h2, q) / denominator;
}

}  // namespace

void richardsonEstimate(double h0, double h1, double h2, double d01, double d12, double peak,
                        ConvergenceResult& out, EstimateOf of) {
  out.d01 = d01;
  out.d12 = d12;
  out.reason.clear();
  out.message.clear();
  // The order of the upper estimates: the lower of the elements' rates (energy norm 1 and
  // displacements 2 for linear tets; 2 and 3 for quadratic ones). Linear tets' displacements
  // reach order 2 only in the asymptotic range, which a mesh bounded by the organ's surface
  // rarely does.
  const int upperOrder = out.elementOrder <= 1 ? 1 : 2;
  const auto noEstimate = [&](const std::string& reason, const std::string& message) {
    out.reason = reason;
    out.message = "no Richardson estimate: " + message;
    out.boundRelative = peak > 0 ? std::max(d01, d12) / peak : NAN;
  };
  if (const auto [reason, message] = levelsProblem(h0, h1, h2); !reason.empty()) {
    noEstimate(reason, message);
    // Only the coarse pair too close (the surface bounds the coarsest level) and the finest pair
    // apart: a two-level estimate at the elements' lower rate with Roache's safety factor 3 for
    // two grids (Roache 1994, J. Fluids Eng. 116:405).
    if (reason == "levels_too_close" && h1 / h2 >= kMinLevelRatio && d12 > 0) {
      constexpr double kTwoLevelSafety = 3;
      out.errorEstimate = kTwoLevelSafety * extrapolatedError(h1, h2, d12, upperOrder, of);
      out.relativeError = peak > 0 ? out.errorEstimate / peak : NAN;
      out.converged = out.relativeError <= 0.01;
      out.message += "; the finest pair (h ratio " + fixedDigits(h1 / h2, 2) +
                     ") extrapolated at order " + std::to_string(upperOrder) +
                     " with Roache's two-grid safety factor 3, an upper estimate";
    }
    return;
  }
  if (!(d12 > 0) || !(d01 > 0)) {
    noEstimate("coincide", "the levels' answers coincide (differences " + mm(d01) + " then " +
                               mm(d12) + "): nothing to extrapolate");
    return;
  }
  const double p = observedOrder(h0, h1, h2, d01, d12);
  if (p < 0) {
    noEstimate("not_monotone", "the differences do not shrink monotonically with h (" + mm(d01) +
                                   " then " + mm(d12) + ", d01/d12 = " + fixedDigits(d01 / d12, 2) +
                                   ")");
    return;
  }
  // Differences that shrink faster than order 4 (the coarse level is the one out of the
  // asymptotic range): the finest pair is extrapolated at the elements' lower rate instead,
  // which overstates the error while the levels converge at least that fast (a conservative
  // two-level estimate in the manner of Roache's grid convergence index).
  if (!std::isfinite(p) || p > 4) {
    out.order = std::isfinite(p) ? p : NAN;
    out.errorEstimate = extrapolatedError(h1, h2, d12, upperOrder, of);
    out.relativeError = peak > 0 ? out.errorEstimate / peak : NAN;
    out.asymptotic = false;
    out.converged = out.relativeError <= 0.01;
    out.reason = "not_asymptotic";
    out.message = (std::isfinite(p) ? "the observed order p = " + fixedDigits(p, 2) + " is above 4"
                                    : std::string("the differences shrink faster than any order "
                                                  "up to 20")) +
                  " (" + mm(d01) + " then " + mm(d12) +
                  "): the finest pair extrapolated at order " + std::to_string(upperOrder) +
                  " instead, an upper estimate";
    out.boundRelative = peak > 0 ? std::max(d01, d12) / peak : NAN;
    return;
  }
  out.order = p;
  out.errorEstimate = extrapolatedError(h1, h2, d12, p, of);
  out.relativeError = peak > 0 ? out.errorEstimate / peak : NAN;
  out.asymptotic = p >= 0.5;
  out.converged = out.asymptotic && out.relativeError <= 0.01;
  if (!out.asymptotic) {
    out.reason = "not_asymptotic";
    out.message = "the observed order p = " + fixedDigits(p, 2) +
                  " is below 0.5: the levels are not in the asymptotic range";
    out.boundRelative = peak > 0 ? std::max(d01, d12) / peak : NAN;
  }
}

double finerLevelBestRelativeError(double h1, double h2, double d12, double peak) {
  if (!(h2 > 0) || !(h1 / h2 >= kMinLevelRatio) || !(peak > 0)) return 0;
  return d12 / (std::pow(h1 / h2, 4) - 1) / peak;
}

void richardsonRms(double h0, double h1, double h2, double rms01, double rms12, double peak,
                   ConvergenceResult& out, EstimateOf of) {
  out.rmsOrder = out.rmsRelativeError = NAN;
  out.rmsConverged = false;
  if (!levelsProblem(h0, h1, h2).first.empty() || !(rms01 > 0) || !(rms12 > 0) || !(peak > 0))
    return;
  const double p = observedOrder(h0, h1, h2, rms01, rms12);
  if (!(p > 0) || !std::isfinite(p)) return;
  out.rmsOrder = p;
  out.rmsRelativeError = extrapolatedError(h1, h2, rms12, p, of) / peak;
  out.rmsConverged = p >= 0.5 && p <= 4 && out.rmsRelativeError <= 0.01;
}

namespace {

constexpr const char* kCacheKind = "harness.convergence";
// 2: RMS differences; 3: levels by edge length, reasons, RMS orders; 4: order-2 upper estimate
// 5: a finer level where the surface bounds the coarse ones (finer_level_added, estimated_level)
// 6: a level whose surface passes through itself is invalid (and the message names the level)
// 7: upper estimates at the reference's element order (element_order)
constexpr const char* kCacheVersion = "harness.convergence/7";

ojson toJson(const ConvergenceResult& r, const std::string& sceneFile) {
  ojson doc;
  doc["format"] = "deformbench-convergence/1";
  doc["scene"] = sceneFile;
  doc["levels"] = ojson::array();
  for (const auto& l : r.levels)
    doc["levels"].push_back({{"target_elements", l.targetElements},
                             {"elements", l.elements},
                             {"target_h_m", l.targetH},
                             {"h_m", l.h},
                             {"peak_displacement_m", l.peakDisplacement},
                             {"status", l.status},
                             {"wall_s", l.solveS}});
  doc["d01_m"] = r.d01;
  doc["d12_m"] = r.d12;
  doc["rms_d01_m"] = numberOrNull(r.rms01);
  doc["rms_d12_m"] = numberOrNull(r.rms12);
  doc["order"] = numberOrNull(r.order);
  doc["error_estimate_m"] = numberOrNull(r.errorEstimate);
  doc["relative_error"] = numberOrNull(r.relativeError);
  doc["asymptotic"] = r.asymptotic;
  doc["converged"] = r.converged;
  doc["richardson_applies"] = r.reason.empty() || r.reason == "not_asymptotic";
  doc["reason"] = r.reason.empty() ? ojson(nullptr) : ojson(r.reason);
  doc["message"] = r.message;
  doc["bound_relative"] = numberOrNull(r.boundRelative);
  doc["rms_order"] = numberOrNull(r.rmsOrder);
  doc["rms_relative_error"] = numberOrNull(r.rmsRelativeError);
  doc["rms_converged"] = r.rmsConverged;
  doc["cached"] = r.cached;
  doc["finer_level_added"] = r.finerLevelAdded;
  doc["graded"] = r.graded;
  doc["estimated_level"] = r.estimatedLevel;
  doc["element_order"] = r.elementOrder;
  return doc;
}

double numberOrNaN(const ojson& j, const char* key) {
  return j.contains(key) && j[key].is_number() ? j[key].get<double>() : NAN;
}

ConvergenceResult fromJson(const ojson& doc) {
  ConvergenceResult r;
  for (const auto& l : doc.at("levels")) {
    ConvergenceLevelResult level;
    level.targetElements = l.at("target_elements").get<long long>();
    level.elements = l.at("elements").get<long long>();
    level.targetH = l.at("target_h_m").get<double>();
    level.h = l.at("h_m").get<double>();
    level.peakDisplacement = l.at("peak_displacement_m").get<double>();
    level.status = l.at("status").get<std::string>();
    level.solveS = l.at("wall_s").get<double>();
    r.levels.push_back(level);
  }
  r.d01 = doc.at("d01_m").get<double>();
  r.d12 = doc.at("d12_m").get<double>();
  r.rms01 = numberOrNaN(doc, "rms_d01_m");
  r.rms12 = numberOrNaN(doc, "rms_d12_m");
  r.order = numberOrNaN(doc, "order");
  r.errorEstimate = numberOrNaN(doc, "error_estimate_m");
  r.relativeError = numberOrNaN(doc, "relative_error");
  r.asymptotic = doc.at("asymptotic").get<bool>();
  r.converged = doc.at("converged").get<bool>();
  r.message = doc.at("message").get<std::string>();
  r.reason = doc.at("reason").is_string() ? doc.at("reason").get<std::string>() : "";
  r.boundRelative = numberOrNaN(doc, "bound_relative");
  r.rmsOrder = numberOrNaN(doc, "rms_order");
  r.rmsRelativeError = numberOrNaN(doc, "rms_relative_error");
  r.rmsConverged = doc.at("rms_converged").get<bool>();
  r.finerLevelAdded = doc.value("finer_level_added", false);
  r.graded = doc.value("graded", false);
  r.estimatedLevel = doc.value("estimated_level", int(r.levels.size()) - 1);
  r.elementOrder = doc.value("element_order", 2);
  return r;
}

std::string percent(double fraction) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g%%", 100 * fraction);
  return buf;
}

std::string fixed(double v, int digits) {
  return fixedDigits(v, digits);
}

}  // namespace

std::string convergenceSummary(const ConvergenceResult& r) {
  std::string levels, sizes;
  for (const auto& l : r.levels) {
    levels += (levels.empty() ? "" : " / ") +
              std::to_string(l.elements > 0 ? l.elements : l.targetElements);
    if (l.h > 0) sizes += (sizes.empty() ? "" : " / ") + fixed(1e3 * l.h, 2);
  }
  levels += " tets";
  if (!sizes.empty()) levels += ", h " + sizes + " mm";
  std::string rms;
  // The peak of the level the estimate is for (the last, unless a finer one was added).
  const size_t of = r.estimatedIndex();
  const double peak = of < r.levels.size() ? r.levels[of].peakDisplacement : 0;
  if (std::isfinite(r.rms12) && r.levels.size() >= 3 && peak > 0) {
    rms = "; RMS level differences " + percent(r.rms01 / peak) + " then " + percent(r.rms12 / peak);
    if (std::isfinite(r.rmsRelativeError))
      rms +=
          ", RMS estimate " + percent(r.rmsRelativeError) + " (p = " + fixed(r.rmsOrder, 2) + ")";
  }
  if (std::isnan(r.relativeError)) {
    std::string bound;
    if (std::isfinite(r.boundRelative))
      bound = "; the levels differ by up to " + percent(r.boundRelative) + " of the peak";
    return "no discretisation error estimate (" +
           (r.message.empty() ? std::string("no levels ran") : r.message) + bound + "; levels " +
           levels + rms + ")";
  }
  // With a finer level added, the error is that of the level before the last (the reference).
  const std::string whose =
      r.finerLevelAdded && r.estimatedLevel >= 0
          ? " of level " + std::to_string(r.estimatedLevel) +
                " (the reference; the last level, finer, was added because the surface bounds "
                "the coarse ones)"
          : "";
  if (!r.asymptotic && !(r.order < 0.5))  // faster than order 4: the upper estimate
    return "estimated discretisation error" + whose + " at most " + percent(r.relativeError) +
           " of the peak (levels " + levels + "; " + r.message + rms + ")";
  return "estimated discretisation error" + whose + " " + percent(r.relativeError) +
         " of the peak (levels " + levels + ", p = " + fixed(r.order, 2) + rms + ")";
}

std::string convergenceWarning(const ConvergenceResult& r) {
  if (r.converged) return "";
  if (std::isnan(r.relativeError)) {
    std::string w = "the reference's convergence is unknown (" +
                    (r.message.empty() ? std::string("no estimate") : r.message) + ")";
    if (std::isfinite(r.boundRelative))
      w += ": read its errors as bounded by the levels' spread, " + percent(r.boundRelative) +
           " of the peak";
    return w;
  }
  std::string w;
  if (r.relativeError > 0.01) w = "the reference is not converged to 1% of the peak";
  if (!r.asymptotic && r.order < 0.5)
    w +=
        std::string(w.empty() ? "the estimate is unreliable" : ", and the estimate is unreliable") +
        ": the levels are not in the asymptotic range (p = " + fixed(r.order, 2) + ")";
  else if (!r.asymptotic)
    w += " (" + r.message + ")";
  const double bound =
      std::isfinite(r.boundRelative) ? std::max(r.boundRelative, r.relativeError) : r.relativeError;
  return w + ": read its errors as bounds of " + percent(bound) + " of the peak or more";
}

ConvergenceResult runConvergence(const std::string& sceneFile, PluginLoader& loader,
                                 const ConvergeOptions& options, Progress* progress) {
  const ojson scene = readJsonFile(sceneFile, "scene");
  return runConvergence(scene, sceneFile, loader, options, progress);
}

namespace {

/// A study's inputs resolved from its scene: the scene with absolute mesh path, parsed, the
/// reference, its size h (and the tets it stands for), the organ, the excluded radius and the
/// cache key (none when the plugin or the mesh cannot be hashed).
struct PreparedStudy {
  ojson base, ref;
  Scene parsed;
  double h = 0;               ///< m, the size the ratios scale
  long long n = 0;            ///< the tets h stands for (levels of a plugin without `edge_length`)
  bool byEdgeLength = false;  ///< the plugin takes `edge_length`
  /// h is the reference's own: a level at ratio 1 keeps the reference's params unchanged.
  bool ownSize = false;
  /// The reference's params grade its mesh toward a point (ConvergenceResult::graded).
  bool graded = false;
  int elementOrder = 2;  ///< ConvergenceResult::elementOrder
  Organ organ;
  double volume = 0, exclude = 0;
  std::optional<CacheKey> key;
};

PreparedStudy prepareStudy(const ojson& scene, const std::string& sceneFile, PluginLoader& loader,
                           const ConvergeOptions& options) {
  PreparedStudy p;
  p.base = scene;
  ojson& base = p.base;
  if (base.contains("organ") && base["organ"].contains("mesh")) {
    const std::string mesh = base["organ"]["mesh"];
    if (mesh.rfind("phantom:", 0) != 0 && !fs::path(mesh).is_absolute())
      base["organ"]["mesh"] =
          fs::absolute(fs::path(sceneFile).parent_path() / mesh).lexically_normal().string();
  }
  p.parsed = parseScene(nlohmann::json::parse(base.dump()), sceneFile);
  if (!p.parsed.reference)
    throw InputError(sceneFile, "/reference", "the scene has no reference to check");
  const std::vector<double>& r = options.hRatios;
  if (r.size() != 3 || !(r[2] > 0) || !(r[0] > r[1] && r[1] > r[2]))
    throw InputError(sceneFile, "convergence levels",
                     "need three decreasing positive edge-length ratios");
  p.ref = base["reference"];
  const ojson& ref = p.ref;
  p.organ = loadOrgan(p.parsed);
  p.volume = std::fabs(signedVolume(p.organ.surface.V, p.organ.surface.F));
  // The reference's own size: its params, else the plugin's defaults.
  double ownH = 0;
  long long ownN = 0;
  if (ref.contains("params")) {
    const ojson& params = ref["params"];
    if (params.contains("edge_length") && params["edge_length"].is_number())
      ownH = params["edge_length"].get<double>();
    if (params.contains("elements") && params["elements"].is_number_integer())
      ownN = params["elements"].get<long long>();
  }
  try {
    const ModelInfo& info = loader.load(ref.value("plugin", ""));
    const std::vector<ParamSpec>& specs = info.params;
    // Graded as the plugin meshes it: its resolved params' grading (organ_tets.h), where it
    // takes the organ's tet mesh parameters; and its element order, where it has one.
    const bool tetMesh = info.param("focus_radius") != nullptr;
    const bool ordered = info.param("element_order") != nullptr;
    if (tetMesh || ordered) {
      const ParamValues values =
          resolveParams(specs, nlohmann::json::parse(ref.value("params", ojson::object()).dump()),
                        sceneFile, "/reference/params");
      if (tetMesh) p.graded = organTetOptions(values).grading.active();
      if (ordered) p.elementOrder = int(values.integer("element_order"));
    }
    for (const ParamSpec& spec : specs) {
      if (spec.key == "edge_length") {
        p.byEdgeLength = true;
        if (ownH <= 0 && std::holds_alternative<double>(spec.defaultValue))
          ownH = std::get<double>(spec.defaultValue);
      }
      if (spec.key == "elements" && ownN <= 0 &&
          std::holds_alternative<long long>(spec.defaultValue))
        ownN = std::get<long long>(spec.defaultValue);
    }
  } catch (const std::exception&) {
    // no such plugin, or params it refuses: the levels report it
  }
  if (ownN <= 0) ownN = 5000;
  if (options.baseEdgeLength > 0) {
    p.h = options.baseEdgeLength;
  } else if (options.baseElements > 0) {
    p.h = edgeLengthForElements(p.volume, options.baseElements);
  } else {
    p.ownSize = true;
    p.h = ownH > 0 ? ownH : edgeLengthForElements(p.volume, ownN);
  }
  p.n = p.ownSize && ownH <= 0
            ? ownN
            : std::max<long long>(
                  1, std::llround(std::pow(edgeLengthForElements(p.volume, 1) / p.h, 3)));
  p.exclude = options.excludeRadius >= 0 ? options.excludeRadius
                                         : 0.1 * boundingBox(p.organ.surface.V).diagonal();
  // The cache key: everything the levels' answers depend on. The models are not run.
  const std::string plugin = ref.value("plugin", "");
  try {
    CacheKey k;
    k.add(kCacheVersion);
    ojson what = base;
    what.erase("models");
    what.erase("name");
    what.erase("description");
    k.add(what.dump());
    k.add(p.h).add(p.exclude).add((long long)p.ownSize);
    for (double f : options.hRatios) k.add(f);
    k.add((long long)options.finerWhenBound);
    k.add(sha256File(loader.locate(plugin)));
    const std::string mesh = base["organ"].value("mesh", "");
    if (mesh.rfind("phantom:", 0) != 0) k.add(sha256File(mesh));
    p.key = k;
  } catch (const std::exception&) {
    // No plugin file to hash (the levels will report it missing) or an unreadable mesh: the
    // study runs uncached.
  }
  return p;
}

}  // namespace

std::optional<ConvergenceResult> cachedReferenceCheck(const std::string& sceneFile,
                                                      PluginLoader& loader,
                                                      const std::optional<fs::path>& cacheDir) {
  if (cacheDir && cacheDir->empty()) return std::nullopt;  // --no-cache
  try {
    std::ifstream in(sceneFile);
    const ojson scene = ojson::parse(in);
    const PreparedStudy p = prepareStudy(scene, sceneFile, loader, referenceCheckOptions());
    if (!p.key) return std::nullopt;
    Cache cache(cacheDir ? *cacheDir : Cache::defaultDir());
    const auto hit = cache.get(kCacheKind, *p.key);
    if (!hit) return std::nullopt;
    ByteReader r(*hit);
    ConvergenceResult out = fromJson(ojson::parse(r.string()));
    out.cached = true;
    return out;
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

/// The surface vertices the study compares (1) and leaves out (0): those within `exclude` of a
/// point load (singular) or of where a grasp closes (the nodes a grasp attaches are those of each
/// mesh within its radius, so the boundary condition itself changes with the mesh there).
std::vector<char> comparedVertices(const Scene& parsed, const Organ& organ, double exclude) {
  const Interaction interaction(parsed, organ.surface);
  std::vector<Vec3> centres;
  for (int v : interaction.loadVertices()) centres.push_back(organ.surface.V.row(v).transpose());
  for (const ToolSpec& tool : parsed.tools)
    for (const KeyFrame& k : tool.trajectory)
      if (k.jawClosed) {
        centres.push_back(k.pos);
        break;
      }
  std::vector<char> include(size_t(organ.surface.numVertices()), 1);
  for (const Vec3& c : centres)
    for (int i = 0; i < organ.surface.numVertices(); ++i)
      if ((organ.surface.V.row(i).transpose() - c).norm() < exclude) include[size_t(i)] = 0;
  return include;
}

/// The level cases, one per ratio (ids level_{firstIndex + k}); out gets a level each.
std::vector<SceneCase> levelCases(const PreparedStudy& prepared, const ConvergeOptions& options,
                                  const std::vector<double>& ratios, size_t firstIndex,
                                  ConvergenceResult& out, std::vector<std::string>& ids) {
  const ojson& base = prepared.base;
  const ojson& ref = prepared.ref;
  std::vector<SceneCase> cases;
  // The level scenes: the reference plugin alone, as a model, at the level's size: its
  // `edge_length` (Gmsh's size field), or for a plugin without one `elements` scaled by r^-3. A
  // level at ratio 1 of the reference's own size is the reference as the scene runs it.
  for (size_t k = 0; k < ratios.size(); ++k) {
    ConvergenceLevelResult level;
    const double ratio = ratios[k];
    level.targetElements =
        std::max<long long>(1, std::llround(double(prepared.n) / (ratio * ratio * ratio)));
    ojson j = base;
    j["models"] = ojson::array();
    ojson r = ref;
    if (!r.contains("params")) r["params"] = ojson::object();
    if (prepared.byEdgeLength) level.targetH = ratio * prepared.h;
    if (!(ratio == 1.0 && prepared.ownSize)) {
      if (prepared.byEdgeLength) {
        r["params"]["edge_length"] = level.targetH;
      } else {
        r["params"]["elements"] = level.targetElements;
      }
    }
    const std::string id = "level_" + std::to_string(firstIndex + k);
    r["label"] = id;
    j["models"].push_back(r);
    j.erase("reference");
    SceneCase c;
    c.scene = j;
    c.sceneFile = options.outDir / (id + ".json");
    c.outDir = options.outDir / id;
    c.options.cacheDir = options.cacheDir;
    c.options.reuseModelSolves = options.reuseSolves;
    if (options.child) {
      c.options.child = options.child;
      c.options.child->runArgs.push_back("--write-compared");
    }
    cases.push_back(std::move(c));
    ids.push_back(id);
    out.levels.push_back(level);
  }
  return cases;
}

/// The Richardson estimates from the last three levels' displacements, over the compared
/// vertices: the error of the finest, or with a finer level added, of the one before it.
void estimateFromLevels(const std::vector<MatX3>& displacement, const std::vector<char>& include,
                        ConvergenceResult& out) {
  const auto maxDiff = [&](const MatX3& a, const MatX3& b) {
    double m = 0;
    for (Eigen::Index i = 0; i < a.rows(); ++i)
      if (include[size_t(i)]) m = std::max(m, (a.row(i) - b.row(i)).norm());
    return m;
  };
  const auto rmsDiff = [&](const MatX3& a, const MatX3& b) {
    double sum = 0;
    long long counted = 0;
    for (Eigen::Index i = 0; i < a.rows(); ++i)
      if (include[size_t(i)]) {
        sum += (a.row(i) - b.row(i)).squaredNorm();
        ++counted;
      }
    return counted > 0 ? std::sqrt(sum / double(counted)) : NAN;
  };
  const size_t n = displacement.size(), a = n - 3, b = n - 2, c = n - 1;
  const EstimateOf of = out.finerLevelAdded ? EstimateOf::Middle : EstimateOf::Finest;
  out.estimatedLevel = int(of == EstimateOf::Middle ? b : c);
  const double h0 = out.levels[a].h, h1 = out.levels[b].h, h2 = out.levels[c].h;
  const double peak = out.levels[size_t(out.estimatedLevel)].peakDisplacement;
  richardsonEstimate(h0, h1, h2, maxDiff(displacement[a], displacement[b]),
                     maxDiff(displacement[b], displacement[c]), peak, out, of);
  out.rms01 = rmsDiff(displacement[a], displacement[b]);
  out.rms12 = rmsDiff(displacement[b], displacement[c]);
  richardsonRms(h0, h1, h2, out.rms01, out.rms12, peak, out, of);
}

namespace {

/// One study in flight (runConvergences): its inputs, the levels so far and the batch of level
/// cases it has out.
struct Study {
  const ConvergenceStudyInput* input = nullptr;
  PreparedStudy prepared;
  std::vector<char> include;
  ConvergenceResult out;
  std::vector<MatX3> displacement;
  bool done = false;         ///< cached, or could not be prepared
  std::exception_ptr error;  ///< why it could not be prepared (runConvergence rethrows it)
  size_t expected = 3;
  std::optional<ConvergenceResult> threeLevels;  ///< before a finer level was added
  // The batch: its cases (ids[k] is level first + k of out.levels) and their surfaces.
  std::vector<SceneCase> cases;
  std::vector<std::string> ids;
  size_t first = 0;
  std::vector<std::optional<MatX3>> surfaces;
};

/// Runs every study's batch of level cases, together (to the first study's dispatcher, when its
/// levels are child processes), and appends each level's surface displacement to its study where
/// it ran to its compared instant.
void runLevelBatches(std::vector<Study*>& studies, PluginLoader& loader, Progress* progress) {
  std::vector<std::pair<Study*, size_t>> at;  // (study, k) of each case of the batch
  std::vector<SceneCase> all;
  for (Study* st : studies) {
    st->surfaces.assign(st->cases.size(), std::nullopt);
    for (size_t k = 0; k < st->cases.size(); ++k) {
      at.emplace_back(st, k);
      all.push_back(st->cases[k]);
    }
  }
  if (all.empty()) return;
  if (progress) progress->addTotal(int(all.size()));
  const auto started = [&](size_t i) {
    const auto& [st, k] = at[i];
    const ConvergenceLevelResult& level = st->out.levels[st->first + k];
    if (progress)
      progress->start(st->ids[k] +
                      (level.targetH > 0
                           ? " (h " + fixed(1e3 * level.targetH, 2) + " mm)"
                           : " (" + std::to_string(level.targetElements) + " elements)"));
  };
  // A level's outcome: its status, elements and surface at the last compared instant.
  const auto finished = [&](size_t i, const CaseResult& c, double wallS) {
    const auto& [st, k] = at[i];
    ConvergenceLevelResult& level = st->out.levels[st->first + k];
    const std::string& id = st->ids[k];
    level.solveS = wallS;
    const RunRecord* run = c.run(id);
    if (!c.missing.empty()) {
      level.status = "missing plugin: " + c.missing.begin()->second;
    } else if (!run) {
      level.status = "not run: " + c.error;
    } else {
      level.status = run->status == RunStatus::Ok && !run->valid
                         ? "invalid (" + run->invalidReason + ")"
                         : std::string(statusName(run->status));
      if (run->counts.count("elements")) level.elements = run->counts.at("elements");
    }
    if (run && run->status == RunStatus::Ok && run->valid && level.elements > 0) {
      MatX3 x;
      if (!run->compared.empty()) {
        st->surfaces[k] = run->compared.back().positions;
      } else if (st->input->options.child &&
                 readComparedSurface(comparedSurfaceFile(c.outDir, id), x)) {
        st->surfaces[k] = std::move(x);
      }
    }
    // A level whose surface passes through itself away from the held vertices is no state of
    // the solid (as a reference that does is invalid: computeRunErrors).
    if (st->surfaces[k]) {
      const long long pairs =
          SelfIntersectionCheck(st->prepared.parsed, st->prepared.organ)(*st->surfaces[k]).free;
      if (pairs > 0) {
        level.status = "invalid (its surface passes through itself (" + std::to_string(pairs) +
                       (pairs == 1 ? " pair" : " pairs") + " of triangles))";
        st->surfaces[k].reset();
      }
    }
    if (progress) progress->finish(id, level.status);
  };
  const ConvergeOptions& shared = studies.front()->input->options;
  if (shared.child) {
    runSceneCases(all, loader, shared.dispatcher, started,
                  [&](size_t i, CaseResult&& c) { finished(i, c, c.wallS); });
  } else {
    for (size_t i = 0; i < all.size(); ++i) {
      started(i);
      const auto t0 = std::chrono::steady_clock::now();
      const CaseResult c =
          runSceneCase(all[i].scene, all[i].sceneFile, all[i].outDir, loader, all[i].options);
      finished(i, c, std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    }
  }
  for (Study* st : studies) {
    const Organ& organ = st->prepared.organ;
    for (size_t k = 0; k < st->cases.size(); ++k) {
      ConvergenceLevelResult& level = st->out.levels[st->first + k];
      const std::optional<MatX3>& surface = st->surfaces[k];
      if (!surface || surface->rows() < organ.surface.numVertices()) continue;
      const MatX3 u = surface->topRows(organ.surface.numVertices()) - organ.surface.V;
      st->displacement.push_back(u);
      level.h = st->out.graded && level.targetH > 0
                    ? level.targetH
                    : std::cbrt(st->prepared.volume / double(level.elements));
      level.peakDisplacement = u.rowwise().norm().maxCoeff();
    }
    st->cases.clear();
    st->ids.clear();
  }
}

/// Prepares a study: its cached result (done), or its first three levels as its batch.
void startStudy(Study& st, PluginLoader& loader) {
  const ConvergenceStudyInput& in = *st.input;
  const ConvergeOptions& options = in.options;
  try {
    st.prepared = prepareStudy(in.scene, in.sceneFile, loader, options);
  } catch (const std::exception& e) {
    st.out.message = e.what();
    st.error = std::current_exception();
    st.done = true;
    return;
  }
  const std::optional<CacheKey>& key = st.prepared.key;
  if (key) {
    Cache cache(options.cacheDir ? *options.cacheDir : Cache::defaultDir());
    if (auto hit = cache.get(kCacheKind, *key)) {
      try {
        ByteReader r(*hit);
        st.out = fromJson(ojson::parse(r.string()));
        st.out.cached = true;
        fs::create_directories(options.outDir);
        writeFileAtomic(options.outDir / "convergence.json",
                        toJson(st.out, in.sceneFile).dump(2) + "\n");
        st.done = true;
        return;
      } catch (const std::exception&) {
        // An entry of another layout: recompute and overwrite it.
        st.out = ConvergenceResult();
      }
    }
  }
  st.include = comparedVertices(st.prepared.parsed, st.prepared.organ, st.prepared.exclude);
  st.out.graded = st.prepared.graded;
  st.out.elementOrder = st.prepared.elementOrder;
  st.first = 0;
  st.cases = levelCases(st.prepared, options, options.hRatios, 0, st.out, st.ids);
}

/// After the first three levels: the estimate, and where the surface bounds the coarse pair and
/// the estimate is not converged, one level finer than the last as the study's next batch.
void estimateOrRefine(Study& st) {
  if (st.done) return;
  if (st.displacement.size() != 3) {
    st.out.reason = "levels_failed";
    st.out.message = "no estimate: not every level ran to its compared instant";
    // Say which level and why (an invalid level carries its reason in its status).
    for (size_t i = 0; i < st.out.levels.size(); ++i) {
      const ConvergenceLevelResult& l = st.out.levels[i];
      if (l.status == "ok") continue;
      st.out.message = "no estimate: level " + std::to_string(i) + " (" +
                       std::to_string(l.elements) + " tets) is " + l.status;
      break;
    }
    return;
  }
  estimateFromLevels(st.displacement, st.include, st.out);
  const ConvergeOptions& options = st.input->options;
  if (options.finerWhenBound && !st.out.converged &&
      st.out.levels[0].h / st.out.levels[1].h < kMinLevelRatio) {
    // A finer level costs about three times the reference's solve: not run where its estimate
    // could not reach 1% even at order 4 (the differences of a diverging or folding load).
    const double peak = st.out.levels[2].peakDisplacement;
    const double best =
        finerLevelBestRelativeError(st.out.levels[1].h, st.out.levels[2].h, st.out.d12, peak);
    if (best > 0.01) {
      st.out.message += "; no finer level added: the finest pair differs by " +
                        fixedDigits(100 * st.out.d12 / peak, 2) +
                        "% of the peak, so a finer level converging at order 4 from there would "
                        "still estimate " +
                        fixedDigits(100 * best, 2) + "%, above 1%";
      return;
    }
    st.threeLevels = st.out;
    st.first = 3;
    st.cases = levelCases(st.prepared, options, {options.hRatios.back() / kFinerLevelStep}, 3,
                          st.out, st.ids);
    st.expected = 4;
  }
}

/// After the finer level: the estimate from the last three levels; writes convergence.json and
/// keeps a study whose every level ran in the cache.
void finishStudy(Study& st) {
  if (st.done) return;
  if (st.threeLevels) {
    if (st.displacement.size() == 4) {
      st.out.finerLevelAdded = true;
      st.out.reason.clear();
      st.out.message.clear();
      st.out.boundRelative = NAN;
      estimateFromLevels(st.displacement, st.include, st.out);
    } else {
      std::vector<ConvergenceLevelResult> levels = st.out.levels;
      st.out = *st.threeLevels;
      st.out.levels = levels;
      st.out.message += "; the finer level added did not run to its compared instant";
    }
  }
  const ConvergenceStudyInput& in = *st.input;
  const ojson doc = toJson(st.out, in.sceneFile);
  writeFileAtomic(in.options.outDir / "convergence.json", doc.dump(2) + "\n");
  // Only a study whose every level ran is kept: a missing plugin or a failed level may not
  // recur.
  if (st.prepared.key && st.displacement.size() == st.expected) {
    Cache cache(in.options.cacheDir ? *in.options.cacheDir : Cache::defaultDir());
    ByteWriter w;
    w.string(doc.dump());
    cache.put(kCacheKind, *st.prepared.key, w.bytes());
  }
}

/// The studies of runConvergences, run together.
std::vector<Study> runStudies(const std::vector<ConvergenceStudyInput>& inputs,
                              PluginLoader& loader, Progress* progress) {
  std::vector<Study> studies(inputs.size());
  for (size_t i = 0; i < inputs.size(); ++i) {
    studies[i].input = &inputs[i];
    startStudy(studies[i], loader);
  }
  std::vector<Study*> open;
  for (Study& st : studies)
    if (!st.done) open.push_back(&st);
  if (!open.empty()) {
    runLevelBatches(open, loader, progress);
    for (Study* st : open) estimateOrRefine(*st);
    runLevelBatches(open, loader, progress);  // the finer levels, where asked for
    for (Study* st : open) finishStudy(*st);
  }
  return studies;
}

}  // namespace

std::vector<ConvergenceResult> runConvergences(const std::vector<ConvergenceStudyInput>& inputs,
                                               PluginLoader& loader, Progress* progress) {
  std::vector<ConvergenceResult> out;
  for (Study& st : runStudies(inputs, loader, progress)) out.push_back(std::move(st.out));
  return out;
}

ConvergenceResult runConvergence(const ojson& scene, const std::string& sceneFile,
                                 PluginLoader& loader, const ConvergeOptions& options,
                                 Progress* progress) {
  // The single study throws what the batch records: a scene that cannot be prepared.
  const std::vector<ConvergenceStudyInput> input = {{scene, sceneFile, options}};
  std::vector<Study> studies = runStudies(input, loader, progress);
  if (studies.front().error) std::rethrow_exception(studies.front().error);
  return std::move(studies.front().out);
}

ConvergeOptions referenceCheckOptions() {
  ConvergeOptions o;
  o.hRatios = kReferenceCheckRatios;
  o.finerWhenBound = true;
  return o;
}

}  // namespace deform::harness
