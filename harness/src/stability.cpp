// The stiff and extreme sweep, one child process per case (see stability.h).
#include <deform/geometry/mesh_io.h>
#include <deform/geometry/phantom.h>
#include <deform/internal/atomic_file.h>
#include <deform/sdk/cache.h>
#include <deform/sdk/mesh.h>
#include <deform_harness/child_process.h>
#include <deform_harness/dispatch.h>
#include <deform_harness/format.h>
#include <deform_harness/runner.h>
#include <deform_harness/stability.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <limits>
#include <map>
#include <optional>
#include <set>
#include <sstream>

namespace deform::harness {

namespace fs = std::filesystem;
using ojson = nlohmann::ordered_json;

namespace {

/// The first parameter set of a plugin's preset `name` (ModelInfo::presets) as scene JSON, or
/// nullopt when the plugin does not load or has no such preset.
std::optional<ojson> presetParams(PluginLoader& loader, const std::string& plugin,
                                  const std::string& name) {
  try {
    const ModelInfo& info = loader.load(plugin);
    const auto it = info.presets.find(name);
    if (it == info.presets.end() || it->second.empty()) return std::nullopt;
    ojson j = ojson::object();
    for (const auto& [k, v] : it->second.front())
      j[k] = std::visit([](const auto& x) { return ojson(x); }, v);
    return j;
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

/// Parameters the sweep gives a plugin instead of its defaults: its "stability" preset (with
/// --quick "stability_quick", smaller precomputations so that a case stays in seconds).
ojson stabilityParams(PluginLoader& loader, const std::string& plugin, bool quick) {
  return presetParams(loader, plugin, quick ? "stability_quick" : "stability")
      .value_or(ojson::object());
}

/// The sweep's reference (DESIGN: one reference everywhere): reference_fem at its defaults
/// (quadratic tets, its default element count), and for the error estimate the same order at
/// about 2.8x fewer target tets (h x 1.4).
struct ReferenceSpec {
  std::string plugin = "reference_fem";
  ojson params = ojson::object();  ///< the defaults
  ojson coarse = ojson::object();
  long long order = 2, elements = 0;  ///< of the defaults (0: not known)
  std::string problem;                ///< why there is none ("" when it loads)
};

ReferenceSpec stabilityReference(PluginLoader& loader) {
  ReferenceSpec spec;
  try {
    const ModelInfo& info = loader.load(spec.plugin);
    long long minimum = 1;
    for (const ParamSpec& p : info.params) {
      if (p.key == "elements" && std::holds_alternative<long long>(p.defaultValue)) {
        spec.elements = std::get<long long>(p.defaultValue);
        minimum = std::max<long long>(1, (long long)p.min);
      }
      if (p.key == "element_order" && std::holds_alternative<long long>(p.defaultValue))
        spec.order = std::get<long long>(p.defaultValue);
    }
    if (spec.elements > 0)
      spec.coarse = {
          {"elements", std::max(minimum, (long long)std::llround(spec.elements / 2.83))}};
  } catch (const std::exception& e) {
    spec.problem = e.what();
  }
  return spec;
}

}  // namespace

SurfaceMesh sliverMesh(double resolution) {
  SurfaceMesh m = makePhantom("liver", resolution);
  const MatX2i E = uniqueEdges(m.F);
  const MatX2i EF = edgeFaces(m.F, E);
  std::vector<char> used(size_t(m.F.rows()), 0);
  std::vector<Vec3> newV;
  std::vector<Eigen::Vector3i> faces;
  int next = m.numVertices();
  for (Eigen::Index e = 0; e < E.rows(); e += 4) {
    const int f1 = EF(e, 0), f2 = EF(e, 1);
    if (f1 < 0 || f2 < 0 || used[size_t(f1)] || used[size_t(f2)]) continue;
    const int a = E(e, 0), b = E(e, 1), p = next++;
    newV.push_back(m.V.row(a).transpose() + 0.02 * (m.V.row(b) - m.V.row(a)).transpose());
    for (int f : {f1, f2}) {
      used[size_t(f)] = 1;
      for (int k = 0; k < 3; ++k) {
        const int x = m.F(f, k), y = m.F(f, (k + 1) % 3), w = m.F(f, (k + 2) % 3);
        if ((x == a && y == b) || (x == b && y == a)) {  // the directed edge x -> y, apex w
          faces.emplace_back(x, p, w);
          faces.emplace_back(p, y, w);
        }
      }
    }
  }
  const Eigen::Index nv = m.V.rows(), nf = m.F.rows();
  MatX3 V(nv + Eigen::Index(newV.size()), 3);
  V.topRows(nv) = m.V;
  for (size_t i = 0; i < newV.size(); ++i) V.row(nv + Eigen::Index(i)) = newV[i].transpose();
  MatX3i F(nf + Eigen::Index(faces.size()) / 2, 3);
  Eigen::Index row = 0;
  for (Eigen::Index f = 0; f < nf; ++f)
    if (!used[size_t(f)]) F.row(row++) = m.F.row(f);
  for (const auto& t : faces) F.row(row++) = t.transpose();
  F.conservativeResize(row, 3);
  m.V = V;
  m.F = F;
  return m;
}

std::vector<StabilityCase> stabilityCases(bool quick) {
  std::vector<StabilityCase> cases;
  const std::vector<double> youngs =
      quick ? std::vector<double>{1e3, 1e5, 1e7} : std::vector<double>{1e3, 1e4, 1e5, 1e6, 1e7};
  const std::vector<double> dts = quick ? std::vector<double>{1e-3, 1.0 / 30}
                                        : std::vector<double>{1e-3, 1e-2, 1.0 / 60, 1.0 / 30};
  for (double e : youngs) {
    for (double dt : dts) {
      StabilityCase c;
      c.id = "E";  // piecewise: GCC 12 warns falsely (-Wrestrict) on "E" + formatG(e) + ...
      c.id += formatG(e);
      c.id += "_dt";
      c.id += formatG(std::round(dt * 1e4) / 1e4);
      c.group = "stiffness_dt";
      c.young = e;
      c.dt = dt;
      c.force = 1.0;
      c.description =
          "E = " + formatG(e) + " Pa, dt = " + formatG(dt) + " s, 1 N down at the top, gravity";
      cases.push_back(c);
    }
  }
  for (double nu : quick ? std::vector<double>{0.499} : std::vector<double>{0.45, 0.49, 0.499}) {
    StabilityCase c;
    c.id = "nu" + formatG(nu);
    c.group = "poisson";
    c.young = 1e4;
    c.poisson = nu;
    c.force = 1.0;
    c.description = "nu = " + formatG(nu) + ", E = 10 kPa, 1 N down at the top, gravity";
    cases.push_back(c);
  }
  for (double f : quick ? std::vector<double>{200} : std::vector<double>{20, 200}) {
    StabilityCase c;
    c.id = "force" + formatG(f) + "N";
    c.group = "force";
    c.force = f;
    c.description = formatG(f) + " N down at the top (E = 5.5 kPa), gravity";
    cases.push_back(c);
  }
  for (double e : quick ? std::vector<double>{1e7} : std::vector<double>{1e4, 1e6, 1e7}) {
    StabilityCase c;
    c.id = "cantilever_E" + formatG(e);
    c.group = "cantilever";
    c.organ = "beam";
    c.young = e;
    c.beamTheory = cantileverSag(e, c.poisson, c.density, 9.81, 0.1, 0.01);
    c.description =
        "cantilever 0.1 m, 10 mm square, clamped at x = 0, under gravity, E = " + formatG(e) +
        " Pa (beam theory: tip sag " + formatG(c.beamTheory) + " m)";
    cases.push_back(c);
  }
  for (double scale : {0.1, 1.0, 10.0}) {
    StabilityCase c;
    c.id = "scale_" + formatG(0.1 * scale) + "m";
    c.group = "scale";
    c.scale = scale;
    c.gravity = false;
    c.force = scale * scale;
    c.description = "the cube scaled to " + formatG(0.1 * scale) + " m, " + formatG(c.force) +
                    " N down at the top, density " + formatG(c.density / (scale * scale)) +
                    " kg/m^3, no gravity (the same problem in other units: the relative "
                    "displacement must not change)";
    cases.push_back(c);
  }
  {
    StabilityCase c;
    c.id = "slivers";
    c.group = "slivers";
    c.organ = "slivers";
    c.force = 1.0;
    c.description =
        "the liver phantom with needle triangles (every fourth edge split at 2%), "
        "1 N down at the top (E = 5.5 kPa), gravity";
    cases.push_back(c);
  }
  std::vector<std::pair<std::string, std::string>> extremes = {
      {"pull", "a grasp at the top pulled three organ-lengths up"},
      {"invert",
       "a grasp at the top pushed down through the organ to half a height below its base "
       "(inverts the region)"}};
  if (!quick)
    extremes.push_back({"flatten", "a probe pressing the top down to a tenth of the height"});
  for (const auto& [id, what] : extremes) {
    StabilityCase c;
    c.id = id;
    c.group = id;
    c.extra = id;
    c.reference = false;
    c.description = what + std::string(" (E = 5.5 kPa), gravity");
    cases.push_back(c);
  }
  return cases;
}

ojson stabilityScene(const StabilityCase& c, const std::string& plugin, const ojson& params,
                     bool quick) {
  const double resolution = quick ? 0.4 : 0.7;
  SurfaceMesh s;
  std::string mesh;
  if (c.organ == "beam") {
    s = makePhantom("beam");
    mesh = "phantom:beam";
  } else if (c.organ == "slivers") {
    s = sliverMesh(resolution);
    mesh = "../../meshes/slivers.obj";  // written by runStability beside scenes/
  } else {
    s = makePhantom("cube", resolution);
    mesh = "phantom:cube";
  }
  s.V *= c.scale;
  const Box b = boundingBox(s.V);
  const double size = b.size().maxCoeff();
  const double duration = c.duration > 0 ? c.duration : (c.reference ? 1.0 : (quick ? 0.2 : 0.5));
  const Vec3 top =
      s.V.row(nearestVertex(s.V, Vec3(b.center().x(), b.center().y(), b.hi.z()))).transpose();
  const Vec3 m = Vec3::Constant(0.05 * b.diagonal());
  ojson fixed;
  if (c.organ == "beam") {  // the root face x = 0
    fixed = {{"box",
              {vecJson(b.lo - m),
               vecJson(Vec3(b.lo.x() + 1e-3 * b.size().x(), b.hi.y() + m.y(), b.hi.z() + m.z()))}}};
  } else {  // the bottom tenth
    fixed = {{"box",
              {vecJson(b.lo - m),
               vecJson(Vec3(b.hi.x() + m.x(), b.hi.y() + m.y(), b.lo.z() + 0.1 * b.size().z()))}}};
  }
  const std::string what = c.organ == "beam" ? "beam phantom, root face fixed"
                           : c.organ == "slivers"
                               ? "liver phantom with slivers, bottom tenth fixed"
                               : "cube phantom (" + formatG(size) + " m), bottom tenth fixed";
  ojson j;
  j["name"] = "stability-" + c.id;
  j["description"] = "Stability case " + c.id + ": " + c.description + "; " + what + ".";
  ojson organ = {{"mesh", mesh}};
  if (c.organ == "cube") organ["resolution"] = resolution;
  if (c.scale != 1) organ["scale"] = c.scale;
  organ["material"] = {
      {"young", c.young}, {"poisson", c.poisson}, {"density", c.density / (c.scale * c.scale)}};
  organ["fixed"] = fixed;
  j["organ"] = organ;
  j["gravity"] = c.gravity ? ojson::array({0, 0, -9.81}) : ojson::array({0, 0, 0});
  j["dt"] = c.dt;
  j["duration"] = std::max(duration, 3 * c.dt);
  if (c.force > 0) {
    j["loads"] = ojson::array({{{"type", "point_force"},
                                {"at", vecJson(top)},
                                {"force", {0, 0, -c.force}},
                                {"radius", 0.01 * c.scale},  // the patch scales with the organ
                                {"start", 0.0},
                                {"end", 1e3}}});
  }
  const double radius = 0.2 * size;
  const Vec3 grip = top - Vec3(0, 0, 0.1 * size);
  if (c.extra == "pull" || c.extra == "invert") {
    const Vec3 to = c.extra == "pull" ? Vec3(grip + Vec3(0, 0, 3 * size))
                                      : Vec3(grip.x(), grip.y(), b.lo.z() - 0.5 * b.size().z());
    j["tools"] = ojson::array({{{"type", "grasper"},
                                {"radius", radius},
                                {"trajectory",
                                 {{{"t", 0.0}, {"pos", vecJson(grip)}, {"jaw", "closed"}},
                                  {{"t", 0.8 * duration}, {"pos", vecJson(to)}}}}}});
  } else if (c.extra == "flatten") {
    const double r = 0.6 * size;
    const Vec3 start(b.center().x(), b.center().y(), b.hi.z() + r);
    const Vec3 end(b.center().x(), b.center().y(), b.lo.z() + 0.1 * b.size().z() + r);
    j["tools"] = ojson::array({{{"type", "probe"},
                                {"radius", r},
                                {"trajectory",
                                 {{{"t", 0.0}, {"pos", vecJson(start)}},
                                  {{"t", 0.8 * duration}, {"pos", vecJson(end)}}}}}});
  }
  j["models"] = ojson::array({{{"plugin", plugin}, {"label", plugin}, {"params", params}}});
  j["samples"] = {{"nearest", {10}}};
  j["output"] = {{"surfaces", "final"}};
  return j;
}

StabilityRecord classifyStabilityRun(int waitStatus, bool timedOut, double timeoutS,
                                     const fs::path& resultsJson, const std::string& stderrTail) {
  StabilityRecord r;
  ChildOutcome outcome;
  outcome.waitStatus = waitStatus;
  outcome.timedOut = timedOut;
  std::string failure = childFailure(outcome, timeoutS, stderrTail);
  if (failure.empty() && !fs::exists(resultsJson))
    failure = "exit code 0" + (stderrTail.empty() ? "" : ": " + stderrTail);
  if (!failure.empty()) {
    r.status = "failed";
    r.message = failure;
    return r;
  }
  try {
    std::ifstream in(resultsJson);
    const ojson doc = ojson::parse(in);
    const ojson& run = doc.at("runs").at(0);
    const std::string status = run.at("status");
    r.message = run.value("message", "");
    if (status == "ok") {
      r.status = "stable";
    } else if (status == "diverged") {
      r.status = "diverged";
      r.step = run.value("steps", -1);
    } else if (status == "unsupported") {
      r.status = "unsupported";
    } else {
      r.status = "failed";
    }
  } catch (const std::exception& e) {
    r.status = "failed";
    r.message = std::string("unreadable results.json: ") + e.what();
  }
  return r;
}

double relativeDisplacement(const MatX3& rest, const MatX3& moved) {
  if (rest.rows() == 0 || moved.rows() != rest.rows()) return -1;
  const double size = boundingBox(rest).size().maxCoeff();
  if (!(size > 0)) return -1;
  return std::sqrt((moved - rest).rowwise().squaredNorm().mean()) / size;
}

std::string collapseProblem(const MatX3& rest, const MatX3& moved, const std::vector<int>& held) {
  if (rest.rows() == 0 || moved.rows() != rest.rows()) return "";
  const double size = boundingBox(rest).size().maxCoeff();
  const double rel = relativeDisplacement(rest, moved);
  if (!std::isfinite(rel)) return "";  // NaN/Inf is divergence, judged elsewhere
  if (!held.empty()) {
    std::vector<char> isHeld(size_t(rest.rows()), 0);
    Vec3 heldCentre = Vec3::Zero();
    for (int v : held) {
      if (v < 0 || v >= rest.rows()) continue;
      isHeld[size_t(v)] = 1;
      heldCentre += rest.row(v).transpose();
    }
    heldCentre /= double(held.size());
    const Vec3 centre = rest.colwise().mean().transpose();
    const Vec3 d = centre - heldCentre;
    if (d.norm() > 1e-3 * size) {  // a support on one side: the organ's back is behind it
      const Vec3 n = d.normalized();
      double back = std::numeric_limits<double>::infinity();
      for (int v : held)
        if (v >= 0 && v < rest.rows()) back = std::min(back, rest.row(v).dot(n));
      int free = 0, through = 0;
      for (Eigen::Index i = 0; i < rest.rows(); ++i) {
        if (isHeld[size_t(i)]) continue;
        ++free;
        through += moved.row(i).dot(n) < back - 0.05 * size;
      }
      if (free > 0 && through > 0.1 * free) {
        std::ostringstream m;
        m << through << " of " << free << " free surface vertices went through the support (over "
          << 0.05 * size << " m beyond it)";
        return m.str();
      }
    }
  }
  if (rel > 1) {
    std::ostringstream m;
    m << "moved by more than its size (RMS displacement " << rel << " of it)";
    return m.str();
  }
  return "";
}

StabilityRecord judgeStability(StabilityRecord r, const MatX3* model, const MatX3* reference,
                               const MatX3& rest, double threshold, const std::vector<int>& held) {
  r.reason.clear();
  r.errorRatio = r.displacementRatio = -1;
  if (r.status == "diverged" || r.status == "failed") {
    r.verdict = r.status;
    return r;
  }
  r.verdict = "unchecked";
  if (r.status != "stable" || !model || !reference || model->rows() != rest.rows() ||
      reference->rows() != rest.rows() || rest.rows() == 0)
    return r;
  const auto rms = [](const MatX3& d) { return std::sqrt(d.rowwise().squaredNorm().mean()); };
  const double refRms = rms(*reference - rest);
  const double err = rms(*model - *reference), moved = rms(*model - rest);
  if (!(refRms > 0) || !std::isfinite(refRms) || !std::isfinite(err)) return r;
  r.errorRatio = err / refRms;
  r.displacementRatio = moved / refRms;
  // A collapse (the reference moves the organ by under 10% of its size) is a verdict of its own
  // whatever the reference's precision: the difference is the size of the organ.
  if (const double refRel = relativeDisplacement(rest, *reference); refRel >= 0 && refRel < 0.1) {
    const std::string collapse = collapseProblem(rest, *model, held);
    if (!collapse.empty()) {
      r.verdict = "collapsed";
      r.reason = collapse;
      return r;
    }
  }
  if (r.referenceError > threshold) {
    r.reason = "reference not converged";
    return r;
  }
  if (r.errorRatio <= threshold) {
    r.verdict = "accurate";
  } else {
    r.verdict = "inaccurate";
    r.reason = r.displacementRatio < 0.1   ? "frozen"
               : r.displacementRatio > 2.0 ? "too_soft"
                                           : "wrong_shape";
  }
  return r;
}

std::vector<std::string> markScaleDependent(std::vector<StabilityRecord>& records) {
  std::vector<std::string> lines;
  std::map<std::string, std::vector<StabilityRecord*>> byModel;
  for (StabilityRecord& r : records)
    if (r.group == "scale") byModel[r.model].push_back(&r);
  for (auto& [model, rows] : byModel) {
    if (rows.size() < 3) continue;
    double lo = std::numeric_limits<double>::infinity(), hi = 0;
    bool known = true;
    for (const StabilityRecord* r : rows) {
      known = known && r->relativeDisplacement > 0 && std::isfinite(r->relativeDisplacement);
      lo = std::min(lo, r->relativeDisplacement);
      hi = std::max(hi, r->relativeDisplacement);
    }
    if (!known || hi <= 1.1 * lo) continue;
    std::ostringstream line;
    line << model << ":";
    for (StabilityRecord* r : rows) {
      line << " " << formatG(r->relativeDisplacement) << " (" << r->caseId << ")";
      // The model's own relative displacements, whatever the reference's precision.
      if (r->verdict == "accurate" || r->verdict == "unchecked") {
        r->verdict = "inaccurate";
        r->reason = "scale_dependent";
      } else if (r->verdict == "inaccurate" &&
                 r->reason.find("scale_dependent") == std::string::npos) {
        r->reason += ", scale_dependent";
      }
    }
    lines.push_back(line.str());
  }
  return lines;
}

namespace {

ojson ratio(double v) {
  return v < 0 ? ojson(nullptr) : ojson(v);
}

ojson recordJson(const StabilityRecord& r) {
  return {{"model", r.model},
          {"case", r.caseId},
          {"group", r.group},
          {"status", r.status},
          {"step", r.step < 0 ? ojson(nullptr) : ojson(r.step)},
          {"message", r.message},
          {"wall_s", r.wallS},
          {"verdict", r.verdict},
          {"reason", r.reason},
          {"error_ratio", ratio(r.errorRatio)},
          {"displacement_ratio", ratio(r.displacementRatio)},
          {"relative_displacement", ratio(r.relativeDisplacement)},
          {"tip_sag_m", ratio(r.tipSag)},
          {"reference_error", ratio(r.referenceError)},
          {"reference_error_source", r.referenceSource},
          {"reference", r.reference},
          {"scene_sha256", r.sceneHash}};
}

/// One reference solve: rest and final surface of reference_fem on the case's scene.
struct ReferenceSolve {
  bool ok = false;
  MatX3 rest, final;
  long long tets = -1;  ///< the mesh's tets (counts "elements"); -1: not reported
  std::string message;  ///< why there is none
};

/// The reference of a case: the solve at the defaults, the coarser one, and what they say.
struct CaseReference {
  bool ok = false;
  MatX3 rest, final;
  std::string message;       ///< why there is none
  std::string what;          ///< "reference_fem P2, 1000 target tets (1130 tets)"
  double estimate = -1;      ///< RMS(fine - coarse) / the fine's RMS displacement; -1: none
  std::string estimateNote;  ///< why there is no estimate
};

/// The reference scene of a case (at dt = 1 ms: the quasi-static answer does not depend on the
/// step) with the given reference parameters.
ojson referenceScene(const StabilityCase& c, const ReferenceSpec& spec, const ojson& params,
                     bool quick) {
  StabilityCase rc = c;
  rc.dt = 1e-3;
  return stabilityScene(rc, spec.plugin, params, quick);
}

/// The cache key of a reference solve: its scene without the words (the cases of one E at two
/// time steps share it) and, for the slivers, the mesh.
CacheKey referenceKey(const StabilityCase& c, ojson scene, const fs::path& outDir) {
  scene.erase("name");
  scene.erase("description");
  CacheKey key;
  key.add("harness.stability_reference/2").add(scene.dump());
  if (c.organ == "slivers") key.add(sha256File((outDir / "meshes" / "slivers.obj").string()));
  return key;
}

std::optional<ReferenceSolve> cachedReference(Cache& cache, const CacheKey& key) {
  if (auto hit = cache.get("harness.stability_reference", key)) {
    try {
      ReferenceSolve ref;
      ByteReader r(*hit);
      r.matrix(ref.rest);
      r.matrix(ref.final);
      ref.tets = r.pod<long long>();
      ref.ok = r.atEnd() && ref.rest.rows() == ref.final.rows() && ref.rest.rows() > 0;
      if (ref.ok) return ref;
    } catch (const std::exception&) {
      // unreadable entry: solve again
    }
  }
  return std::nullopt;
}

/// A finished reference run (`deformbench run` of its scene into dir): its rest and final
/// surface and tet count, or why there is none.
ReferenceSolve readReferenceRun(const fs::path& dir) {
  ReferenceSolve ref;
  try {
    std::ifstream in(dir / "results.json");
    if (!in) throw std::runtime_error("no results.json");
    const ojson doc = ojson::parse(in);
    const ojson& run = doc.at("runs").at(0);
    const std::string status = run.at("status");
    if (status != "ok") {
      ref.message = "reference " + status + ": " + run.value("message", "");
      return ref;
    }
    if (!run.value("valid", true)) {
      ref.message = "reference invalid: " + run.value("invalid_reason", std::string());
      return ref;
    }
    ref.rest = readObj((dir / doc.at("organ").at("rest_surface").get<std::string>()).string()).V;
    ref.final = readObj((dir / run.at("final_surface").get<std::string>()).string()).V;
    if (run.contains("counts") && run["counts"].contains("elements"))
      ref.tets = run["counts"]["elements"].get<long long>();
    ref.ok = ref.rest.rows() == ref.final.rows() && ref.rest.rows() > 0;
    if (!ref.ok) ref.message = "reference surface has the wrong size";
  } catch (const std::exception& e) {
    ref.message = std::string("reference: ") + e.what();
  }
  return ref;
}

/// The case's reference from its solve at the defaults and its coarser one. The estimate assumes
/// second order: |fine - coarse| / ((h_coarse / h_fine)^2 - 1), h from the tet counts.
CaseReference combineReference(const ReferenceSpec& spec, const ReferenceSolve& fine,
                               const ReferenceSolve& coarse) {
  CaseReference ref;
  if (!fine.ok) {
    ref.message = fine.message;
    return ref;
  }
  ref.ok = true;
  ref.rest = fine.rest;
  ref.final = fine.final;
  ref.what = spec.plugin + " P" + std::to_string(spec.order) + ", " +
             std::to_string(spec.elements) + " target tets" +
             (fine.tets > 0 ? " (" + std::to_string(fine.tets) + " tets)" : "");
  const double rms = std::sqrt((fine.final - fine.rest).rowwise().squaredNorm().mean());
  const double h =
      fine.tets > 0 && coarse.tets > 0 ? std::cbrt(double(fine.tets) / double(coarse.tets)) : 0.0;
  if (!coarse.ok) {
    ref.estimateNote = "no estimate: the coarser solve: " + coarse.message;
  } else if (h < 1.05) {
    ref.estimateNote = "no estimate: the coarser level has nearly as many tets (" +
                       std::to_string(coarse.tets) + ")";
  } else if (coarse.final.rows() == fine.final.rows() && rms > 0) {
    ref.estimate =
        std::sqrt((fine.final - coarse.final).rowwise().squaredNorm().mean()) / rms / (h * h - 1);
  }
  return ref;
}

/// The final surface of a finished case run (results.json's first run), or nullopt.
std::optional<MatX3> finalSurfaceOf(const fs::path& runDir) {
  try {
    std::ifstream in(runDir / "results.json");
    if (!in) return std::nullopt;
    const ojson doc = ojson::parse(in);
    const ojson& run = doc.at("runs").at(0);
    if (!run.contains("final_surface")) return std::nullopt;
    return readObj((runDir / run.at("final_surface").get<std::string>()).string()).V;
  } catch (const std::exception&) {
    return std::nullopt;
  }
}

/// Mean downward displacement of the cantilever's tip face (x at its largest).
double tipSag(const MatX3& surface, const MatX3& rest) {
  const double xMax = rest.col(0).maxCoeff();
  double sum = 0;
  int n = 0;
  for (Eigen::Index i = 0; i < rest.rows(); ++i) {
    if (rest(i, 0) < xMax - 1e-9) continue;
    sum += rest(i, 2) - surface(i, 2);
    ++n;
  }
  return n ? sum / n : -1;
}

}  // namespace

namespace {

/// The case set, or the --case ones of it (InputError names an unknown one).
std::vector<StabilityCase> selectedCases(const StabilityOptions& options) {
  std::vector<StabilityCase> cases = stabilityCases(options.quick);
  if (!options.cases.empty()) {
    std::vector<StabilityCase> kept;
    for (const auto& c : cases)
      if (std::find(options.cases.begin(), options.cases.end(), c.id) != options.cases.end())
        kept.push_back(c);
    for (const auto& want : options.cases) {
      if (std::none_of(cases.begin(), cases.end(),
                       [&](const StabilityCase& c) { return c.id == want; })) {
        std::string known;
        for (const auto& c : cases) known += (known.empty() ? "" : ", ") + c.id;
        throw InputError("--case", want, "unknown stability case (known: " + known + ")");
      }
    }
    cases = kept;
  }
  return cases;
}

/// A (model, case) to run: its record (status set when there is nothing to run).
struct Pending {
  StabilityRecord record;
  fs::path dir, caseFile;
  std::string label;
  bool rerun = false;  ///< its finished case was stale or failed: run it, whatever is on disk
};

/// The record a finished case left in caseFile while it stands (the same scenes; with
/// --retry-failed, not failed); nullopt: run the case again.
std::optional<StabilityRecord> resumedRecord(const fs::path& caseFile, const std::string& plugin,
                                             const StabilityCase& c, const std::string& hash,
                                             const StabilityOptions& options) {
  try {
    std::ifstream in(caseFile);
    const ojson j = ojson::parse(in);
    StabilityRecord r;
    r.model = plugin;
    r.caseId = c.id;
    r.group = c.group;
    r.status = j.at("status");
    r.step = j["step"].is_null() ? -1 : j["step"].get<int>();
    r.message = j.value("message", "");
    r.wallS = j.value("wall_s", 0.0);
    r.verdict = j.value("verdict", "");
    r.reason = j.value("reason", "");
    r.referenceSource = j.value("reference_error_source", "");
    r.reference = j.value("reference", "");
    r.sceneHash = j.value("scene_sha256", "");
    for (auto [key, v] : {std::pair{"error_ratio", &r.errorRatio},
                          {"displacement_ratio", &r.displacementRatio},
                          {"relative_displacement", &r.relativeDisplacement},
                          {"tip_sag_m", &r.tipSag},
                          {"reference_error", &r.referenceError}})
      *v = j.contains(key) && j[key].is_number() ? j[key].get<double>() : -1.0;
    r.resumed = true;
    // A case whose scene changed (another case set, reference or model parameters) or,
    // with --retry-failed, that failed is run again.
    if (r.sceneHash == hash && !(options.retryFailed && r.status == "failed")) return r;
  } catch (const std::exception&) {
    // unreadable: run it again
  }
  return std::nullopt;
}

/// Every (model, case): the resumed records that stand into records, the others (their scenes
/// written) into pending.
void planCases(PluginLoader& loader, const StabilityOptions& options,
               const std::vector<std::string>& models, const std::vector<StabilityCase>& cases,
               const ReferenceSpec& refSpec, std::vector<StabilityRecord>& records,
               std::vector<Pending>& pending) {
  const std::string sliverHash =
      fs::exists(options.outDir / "meshes" / "slivers.obj")
          ? sha256File((options.outDir / "meshes" / "slivers.obj").string())
          : std::string();
  for (const std::string& plugin : models) {
    const std::string problem = pluginProblem(loader, plugin);
    const ojson params = stabilityParams(loader, plugin, options.quick);
    for (const StabilityCase& c : cases) {
      const fs::path caseFile = options.outDir / "cases" / plugin / (c.id + ".json");
      const ojson scene = stabilityScene(c, plugin, params, options.quick);
      // The case's identity for --resume: its scene, the reference's scene, the sliver mesh.
      std::string identity = scene.dump();
      if (c.reference)
        identity += referenceScene(c, refSpec, refSpec.params, options.quick).dump() +
                    referenceScene(c, refSpec, refSpec.coarse, options.quick).dump();
      if (c.organ == "slivers") identity += sliverHash;
      const std::string hash = sha256Hex(identity.data(), identity.size());
      if (options.resume && fs::exists(caseFile)) {
        if (std::optional<StabilityRecord> r = resumedRecord(caseFile, plugin, c, hash, options)) {
          records.push_back(*r);
          continue;
        }
      }
      Pending p;
      p.rerun = options.resume && fs::exists(caseFile);
      p.record.model = plugin;
      p.record.caseId = c.id;
      p.record.group = c.group;
      p.record.sceneHash = hash;
      p.caseFile = caseFile;
      p.dir = options.outDir / "runs" / plugin / c.id;
      p.label = plugin + " " + c.id;
      if (!problem.empty()) {
        p.record.status = "failed";
        p.record.message = "plugin cannot be loaded: " + problem;
      }
      const fs::path sceneFile = options.outDir / "scenes" / plugin / (c.id + ".json");
      fs::create_directories(sceneFile.parent_path());
      writeFileAtomic(sceneFile, scene.dump(2) + "\n");
      pending.push_back(p);
    }
  }
}

/// `deformbench run` of sceneFile into dir as a "child" task (dispatch.h).
ojson childRunTask(const std::string& exe, const StabilityOptions& options,
                   const fs::path& sceneFile, const fs::path& dir, double timeoutS, bool resume) {
  std::vector<std::string> argv = {exe};
  for (const auto& a : pluginDirArgs(options.pluginDirs)) argv.push_back(a);
  argv.insert(argv.end(),
              {"run", fs::absolute(sceneFile).string(), "--out", fs::absolute(dir).string()});
  if (!options.cacheDir.empty())
    argv.insert(argv.end(), {"--cache-dir", fs::absolute(options.cacheDir).string()});
  return {{"kind", "child"},
          {"argv", argv},
          {"log", fs::absolute(dir / "log.txt").string()},
          {"timeout_s", timeoutS},
          {"fresh_dir", fs::absolute(dir).string()},
          {"outcome", fs::absolute(dir / "outcome.json").string()},
          {"resume", resume}};
}

/// A reference solve of one case (tag "": at the defaults, "coarse": the coarser level).
struct RefJob {
  std::string caseId, tag;
  CacheKey key;
  fs::path dir;
  ReferenceSolve solve;
  std::string hex;  ///< the key's digest
  int twin = -1;    ///< the job with the same scene whose solve this one takes
};

/// Each judged case's reference (at the defaults and the coarser level): from the cache, else a
/// "child" task appended to tasks (its own time limit, so a reference that takes too long leaves
/// its case unchecked instead of stopping the command); refJobOfTask maps the task to its job.
std::vector<RefJob> planReferenceJobs(
    const StabilityOptions& options, const std::vector<StabilityCase>& cases,
    const ReferenceSpec& refSpec, const std::vector<Pending>& pending,
    const std::vector<StabilityRecord>& records, Cache& cache, const std::string& exe,
    double refTimeout, std::vector<ojson>& tasks, std::map<size_t, size_t>& refJobOfTask) {
  std::vector<RefJob> refJobs;
  std::set<std::string> judged;
  for (const Pending& p : pending) judged.insert(p.record.caseId);
  for (const StabilityRecord& r : records)  // resumed before they were judged
    if (r.verdict.empty()) judged.insert(r.caseId);
  for (const StabilityCase& c : cases) {
    if (!c.reference || !judged.count(c.id)) continue;
    for (const std::string tag : {"", "coarse"}) {
      RefJob job;
      job.caseId = c.id;
      job.tag = tag;
      if (!refSpec.problem.empty()) {
        job.solve.message = "reference: " + refSpec.plugin + " does not load: " + refSpec.problem;
        refJobs.push_back(job);
        continue;
      }
      const ojson scene =
          referenceScene(c, refSpec, tag.empty() ? refSpec.params : refSpec.coarse, options.quick);
      job.key = referenceKey(c, scene, options.outDir);
      if (auto hit = cachedReference(cache, job.key)) {
        job.solve = *hit;
        refJobs.push_back(job);
        continue;
      }
      if (const auto twin = std::find_if(refJobs.begin(), refJobs.end(),
                                         [&](const RefJob& j) { return j.hex == job.key.hex(); });
          twin != refJobs.end()) {  // the same scene (one E at two time steps): solved once
        job.twin = int(twin - refJobs.begin());
        job.hex = job.key.hex();
        refJobs.push_back(job);
        continue;
      }
      job.hex = job.key.hex();
      const std::string name = tag.empty() ? c.id : c.id + "_" + tag;
      const fs::path sceneFile = options.outDir / "reference" / "scenes" / (name + ".json");
      fs::create_directories(sceneFile.parent_path());
      writeFileAtomic(sceneFile, scene.dump(2) + "\n");
      // The folder names the scene's hash: a --resume never reads another scene's outcome.
      job.dir = options.outDir / "reference" / "runs" / (name + "_" + job.hex.substr(0, 8));
      refJobOfTask[tasks.size()] = refJobs.size();
      tasks.push_back(childRunTask(exe, options, sceneFile, job.dir, refTimeout, options.resume));
      refJobs.push_back(job);
    }
  }
  return refJobs;
}

/// A reference task's outcome into its job, and into the cache when it solved.
void finishReferenceJob(RefJob& job, const ojson& o, double refTimeout, Cache& cache) {
  ChildOutcome outcome;
  outcome.waitStatus = o.value("wait_status", 0);
  outcome.timedOut = o.value("timed_out", false);
  std::string failure = o.value("spawn_error", "");
  if (failure.empty())
    failure = childFailure(outcome, refTimeout, lastLogLine(job.dir / "log.txt", 300));
  if (!failure.empty()) {
    job.solve.message = "reference failed: " + failure;
  } else {
    job.solve = readReferenceRun(job.dir);
    if (job.solve.ok) {
      ByteWriter w;
      w.matrix(job.solve.rest);
      w.matrix(job.solve.final);
      w.pod(job.solve.tets);
      cache.put("harness.stability_reference", job.key, w.bytes());
    }
  }
}

/// A case task's outcome into its record: status, step, message, wall time.
void recordCaseOutcome(Pending& p, const ojson& o, double timeout) {
  StabilityRecord r;
  const std::string spawnError = o.value("spawn_error", "");
  if (!spawnError.empty()) {
    r.status = "failed";
    r.message = spawnError;
  } else {
    r = classifyStabilityRun(o.value("wait_status", 0), o.value("timed_out", false), timeout,
                             p.dir / "results.json", lastLogLine(p.dir / "log.txt", 300));
  }
  p.record.status = r.status;
  p.record.step = r.step;
  p.record.message = r.message;
  p.record.wallS = o.value("wall_s", 0.0);
}

/// Records in (model, case) order whatever order the children finished in.
std::vector<StabilityRecord> orderedRecords(const std::vector<StabilityRecord>& records,
                                            const std::vector<std::string>& models,
                                            const std::vector<StabilityCase>& cases) {
  std::map<std::pair<std::string, std::string>, StabilityRecord> byKey;
  for (const auto& r : records) byKey[{r.model, r.caseId}] = r;
  std::vector<StabilityRecord> ordered;
  for (const auto& plugin : models)
    for (const auto& c : cases)
      if (byKey.count({plugin, c.id})) ordered.push_back(byKey.at({plugin, c.id}));

  return ordered;
}

/// Verdicts: each case's reference (solved once or read from the cache), then every finished
/// run compared with it (resumed records keep theirs); the reference lines of the notes.
void judgeRecords(PluginLoader& loader, const StabilityOptions& options,
                  const ReferenceSpec& refSpec,
                  const std::map<std::string, StabilityCase>& caseById,
                  std::vector<RefJob>& refJobs, std::vector<StabilityRecord>& ordered,
                  std::vector<std::string>& referenceFailures,
                  std::vector<std::string>& referenceLines) {
  std::map<std::string, std::vector<StabilityRecord*>> toJudge;
  for (auto& r : ordered)
    if (r.verdict.empty()) toJudge[r.caseId].push_back(&r);
  for (RefJob& j : refJobs)
    if (j.twin >= 0) j.solve = refJobs[size_t(j.twin)].solve;
  for (auto& [id, recs] : toJudge) {
    const StabilityCase& c = caseById.at(id);
    const bool anyStable = std::any_of(
        recs.begin(), recs.end(), [](const StabilityRecord* r) { return r->status == "stable"; });
    CaseReference ref;
    if (c.reference) {
      ReferenceSolve fine, coarse;
      fine.message = coarse.message = "reference not run";
      for (const RefJob& j : refJobs)
        if (j.caseId == id) (j.tag.empty() ? fine : coarse) = j.solve;
      ref = combineReference(refSpec, fine, coarse);
    }
    // The reference's own error: against beam theory where there is one, else its estimate.
    double refError = -1;
    std::string refSource;
    if (ref.ok && c.beamTheory > 0) {
      refError = std::abs(tipSag(ref.final, ref.rest) - c.beamTheory) / c.beamTheory;
      refSource = "beam theory";
    } else if (ref.ok && ref.estimate >= 0) {
      refError = ref.estimate;
      refSource = "coarser solve";
    }
    if (ref.ok) {
      std::string line = id + ": " + ref.what;
      if (c.beamTheory > 0) line += ", tip sag " + formatG(tipSag(ref.final, ref.rest)) + " m";
      if (refError >= 0) line += ", error " + formatG(100 * refError) + "% (" + refSource + ")";
      if (c.beamTheory > 0 && ref.estimate >= 0)
        line += ", coarser-solve estimate " + formatG(100 * ref.estimate) + "%";
      if (refError < 0 && !ref.estimateNote.empty()) line += ", " + ref.estimateNote;
      referenceLines.push_back(line);
    }
    // The surface vertices in the case's fixed box (the support of the collapse test).
    std::vector<int> held;
    if (ref.ok) {
      const ojson box =
          stabilityScene(c, "", ojson::object(), options.quick)["organ"]["fixed"]["box"];
      const Vec3 lo(box[0][0], box[0][1], box[0][2]), hi(box[1][0], box[1][1], box[1][2]);
      for (Eigen::Index i = 0; i < ref.rest.rows(); ++i)
        if ((ref.rest.row(i).transpose().array() >= lo.array()).all() &&
            (ref.rest.row(i).transpose().array() <= hi.array()).all())
          held.push_back(int(i));
    }
    for (StabilityRecord* r : recs) {
      const fs::path runDir = options.outDir / "runs" / r->model / r->caseId;
      const std::optional<MatX3> final =
          r->status == "stable" ? finalSurfaceOf(runDir) : std::nullopt;
      const MatX3* model = final ? &*final : nullptr;
      r->referenceError = refError;
      r->referenceSource = refSource;
      r->reference = ref.what;
      *r = judgeStability(*r, model, ref.ok ? &ref.final : nullptr, ref.rest,
                          options.accuracyThreshold, held);
      // The reference's own row is the reference: never accurate by comparison with itself.
      if (r->model == refSpec.plugin &&
          stabilityParams(loader, r->model, options.quick) == refSpec.params &&
          (r->verdict == "accurate" || r->verdict == "inaccurate")) {
        r->verdict = "unchecked";
        r->reason = "the reference itself";
        r->errorRatio = -1;
      }
      if (ref.ok && model && model->rows() == ref.rest.rows()) {
        r->relativeDisplacement = relativeDisplacement(ref.rest, *model);
        if (c.beamTheory > 0) r->tipSag = tipSag(*model, ref.rest);
      }
      const fs::path caseFile = options.outDir / "cases" / r->model / (r->caseId + ".json");
      if (fs::exists(caseFile)) writeFileAtomic(caseFile, recordJson(*r).dump(2) + "\n");
    }
    if (c.reference && anyStable && !ref.ok) referenceFailures.push_back(id + ": " + ref.message);
  }
}

/// stability.md / .csv / .json: a row per record and the notes.
void writeStabilityTable(const std::vector<StabilityRecord>& ordered,
                         const std::map<std::string, StabilityCase>& caseById,
                         const ReferenceSpec& refSpec, const StabilityOptions& options,
                         double timeout, const std::vector<std::string>& referenceFailures,
                         const std::vector<std::string>& referenceLines,
                         const std::vector<std::string>& scaleLines) {
  Table t;
  t.name = "stability";
  t.title = "every model over stiff, large-step and extreme cases";
  t.notes = {
      "Each case ran in its own process (`deformbench run` on scenes/<model>/<case>.json) "
      "with a " +
          formatG(timeout) + " s limit; failed = threw, crashed (signal) or timed out.",
      std::string("Organ: the cube phantom, bottom tenth fixed, gravity, unless the case says "
                  "otherwise (cantilever: the beam phantom, root face fixed; slivers: the liver "
                  "phantom with needle triangles; scale: no gravity); ") +
          (options.quick ? "--quick case set." : "full case set.")};
  t.notes.push_back(
      "verdict: the final surface against the reference's quasi-static answer on the same scene "
      "(" +
      (refSpec.problem.empty()
           ? refSpec.plugin + " at its defaults: P" + std::to_string(refSpec.order) + ", " +
                 std::to_string(refSpec.elements) + " target tets"
           : refSpec.plugin + ", which does not load") +
      ", solved once per case, cached; its error is reference_error: against beam theory on "
      "the cantilevers, elsewhere estimated as its RMS difference from a coarser P" +
      std::to_string(refSpec.order) + " solve (" +
      (refSpec.coarse.contains("elements") ? refSpec.coarse["elements"].dump() : "?") +
      " target tets, h x 1.4) over its RMS displacement): accurate when error_ratio = rmse_all "
      "/ the reference's RMS displacement <= " +
      formatG(options.accuracyThreshold) +
      "; else inaccurate, frozen (moves < 10% of the reference: displacement_ratio < 0.1), "
      "too_soft (> 2x), wrong_shape or scale_dependent (scale group: the model's "
      "relative_displacement differs by over 10% across 1 cm, 10 cm and 1 m). collapsed: the "
      "model went through its support or moved by more than its size while the reference moves "
      "it by under 10% of its size. unchecked: no quasi-static answer (pull, invert, flatten), "
      "no reference, unsupported, the reference itself, or reference not converged (its "
      "reference_error above " +
      formatG(options.accuracyThreshold) +
      "). A model still moving at the end is compared as it is.");
  t.notes.push_back(
      "poisson group: a model stiffer than the reference there (displacement_ratio well below 1) "
      "is locking; scale group: the same problem at 1 cm, 10 cm and 1 m (force x s^2, density / "
      "s^2, no gravity), so relative_displacement (RMS displacement / organ size) must not "
      "change; cantilever group: tip_sag against beam theory (Euler-Bernoulli + Timoshenko "
      "shear).");
  t.columns = {{"model", "model"},
               {"case", "case"},
               {"group", "group"},
               {"young", "E Pa"},
               {"poisson", "nu"},
               {"dt", "dt s"},
               {"force", "force N"},
               {"status", "status"},
               {"step", "step"},
               {"verdict", "verdict"},
               {"reason", "reason"},
               {"error_ratio", "error ratio"},
               {"displacement_ratio", "displacement ratio"},
               {"relative_displacement", "rel. displacement"},
               {"tip_sag_m", "tip sag m"},
               {"beam_theory_m", "beam theory m"},
               {"reference_error", "reference error"},
               {"reference", "reference"},
               {"wall_s", "wall s"},
               {"message", "message"},
               {"scene", "scene"}};
  int crashes = 0;
  std::map<std::string, std::map<std::string, int>> verdicts;
  std::map<std::string, std::vector<std::string>> inaccurate;
  for (const auto& r : ordered) {
    const StabilityCase& c = caseById.at(r.caseId);
    ojson row = recordJson(r);
    row["young"] = c.young;
    row["poisson"] = c.poisson;
    row["dt"] = c.dt;
    row["force"] = c.force;
    row["extra"] = c.extra;
    row["beam_theory_m"] = c.beamTheory > 0 ? ojson(c.beamTheory) : ojson(nullptr);
    row["scene"] = "scenes/" + r.model + "/" + r.caseId + ".json";
    if (r.message.rfind("killed by signal", 0) == 0) ++crashes;
    ++verdicts[r.model][r.verdict];
    if (r.verdict == "inaccurate" || r.verdict == "collapsed")
      inaccurate[r.model].push_back(r.caseId + " " +
                                    (r.verdict == "collapsed" ? "collapsed" : r.reason));
    t.rows.push_back(row);
  }
  t.notes.push_back("Crashes (killed by a signal): " + std::to_string(crashes) + ".");
  for (const auto& [model, counts] : verdicts) {
    std::string line = "Verdicts of " + model + ":";
    for (const char* v : kStabilityVerdicts)
      line += std::string(" ") + v + " " + std::to_string(counts.count(v) ? counts.at(v) : 0);
    if (inaccurate.count(model)) {
      line += " (inaccurate or collapsed:";
      for (const auto& what : inaccurate.at(model)) line += " " + what + ",";
      line.back() = ')';
    }
    t.notes.push_back(line + ".");
  }
  for (const auto& f : referenceFailures) t.notes.push_back("No reference for " + f + ".");
  for (const auto& f : referenceLines) t.notes.push_back("Reference of " + f + ".");
  for (const auto& f : scaleLines)
    t.notes.push_back("scale_dependent (relative displacement over 10% apart) " + f + ".");
  writeTable(t, options.outDir);
}

}  // namespace

std::vector<StabilityRecord> runStability(PluginLoader& loader, const StabilityOptions& options,
                                          Progress* progress) {
  std::vector<std::string> models = options.models;
  if (models.empty()) models = loader.discover();
  const std::vector<StabilityCase> cases = selectedCases(options);
  const double timeout = options.timeoutS > 0 ? options.timeoutS : (options.quick ? 60.0 : 120.0);
  const std::string exe = options.executable.empty() ? selfExecutable() : options.executable;
  fs::create_directories(options.outDir);

  if (std::any_of(cases.begin(), cases.end(),
                  [](const StabilityCase& c) { return c.organ == "slivers"; })) {
    fs::create_directories(options.outDir / "meshes");
    writeObj((options.outDir / "meshes" / "slivers.obj").string(),
             sliverMesh(options.quick ? 0.4 : 0.7));
  }

  std::vector<StabilityRecord> records;
  std::vector<Pending> pending;
  const ReferenceSpec refSpec = stabilityReference(loader);
  planCases(loader, options, models, cases, refSpec, records, pending);
  if (progress) progress->addTotal(int(pending.size()));

  const auto finishCase = [&](const Pending& p) {
    fs::create_directories(p.caseFile.parent_path());
    writeFileAtomic(p.caseFile, recordJson(p.record).dump(2) + "\n");
    std::string result = p.record.status;
    if (p.record.step >= 0) result += " at step " + std::to_string(p.record.step);
    if (p.record.status == "failed") result += " (" + p.record.message + ")";
    if (progress) progress->finish(p.label, result);
    records.push_back(p.record);
  };

  // Each (model, case) is a "child" task (dispatch.h): here with --jobs, on MPI ranks, or in a
  // Slurm array whose outcome.json files a later --resume reads.
  std::vector<ojson> tasks;
  std::vector<Pending*> jobCase;
  for (Pending& p : pending) {
    if (!p.record.status.empty()) {  // plugin did not load: nothing to run
      finishCase(p);
      continue;
    }
    const fs::path scene = options.outDir / "scenes" / p.record.model / (p.record.caseId + ".json");
    tasks.push_back(childRunTask(exe, options, scene, p.dir, timeout, options.resume && !p.rerun));
    jobCase.push_back(&p);
  }
  // Each case's reference: from the cache, else a "child" task beside the models'.
  const double refTimeout = 5 * timeout;
  Cache cache(options.cacheDir.empty() ? Cache::defaultDir() : fs::path(options.cacheDir));
  std::map<size_t, size_t> refJobOfTask;  ///< task index -> refJobs index
  std::vector<RefJob> refJobs = planReferenceJobs(options, cases, refSpec, pending, records, cache,
                                                  exe, refTimeout, tasks, refJobOfTask);
  if (progress) progress->addTotal(int(refJobOfTask.size()));
  const auto refLabel = [&](const RefJob& j) {
    return "reference " + j.caseId + (j.tag.empty() ? "" : " (" + j.tag + ")");
  };

  std::unique_ptr<Dispatcher> local;
  Dispatcher* dispatcher = options.dispatcher;
  if (!dispatcher) {
    local = localDispatcher(options.jobs);
    dispatcher = local.get();
  }
  dispatcher->run(
      tasks,
      [&](size_t i) {
        if (!progress) return;
        if (refJobOfTask.count(i))
          progress->start(refLabel(refJobs[refJobOfTask.at(i)]));
        else
          progress->start(jobCase[i]->label);
      },
      [&](size_t i, const ojson& o) {
        if (refJobOfTask.count(i)) {
          RefJob& job = refJobs[refJobOfTask.at(i)];
          finishReferenceJob(job, o, refTimeout, cache);
          if (progress) progress->finish(refLabel(job), job.solve.ok ? "ok" : job.solve.message);
          return;
        }
        Pending& p = *jobCase[i];
        recordCaseOutcome(p, o, timeout);
        finishCase(p);
      });

  std::vector<StabilityRecord> ordered = orderedRecords(records, models, cases);
  std::vector<std::string> referenceFailures, referenceLines;
  std::map<std::string, StabilityCase> caseById;
  for (const auto& c : cases) caseById[c.id] = c;
  judgeRecords(loader, options, refSpec, caseById, refJobs, ordered, referenceFailures,
               referenceLines);
  // The scale group (issue 35): the same problem in other units must move alike.
  const std::vector<std::string> scaleLines = markScaleDependent(ordered);
  for (const StabilityRecord& r : ordered) {
    const fs::path caseFile = options.outDir / "cases" / r.model / (r.caseId + ".json");
    if (r.group == "scale" && fs::exists(caseFile))
      writeFileAtomic(caseFile, recordJson(r).dump(2) + "\n");
  }

  writeStabilityTable(ordered, caseById, refSpec, options, timeout, referenceFailures,
                      referenceLines, scaleLines);
  return ordered;
}

}  // namespace deform::harness
