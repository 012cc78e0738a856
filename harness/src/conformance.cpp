// The conformance suite (see conformance.h). Every check builds its scene in memory on the cube
// phantom (coarse, a slab at the bottom fixed) so that a plugin's whole suite takes seconds.
#include <deform/engine/interaction.h>
#include <deform/engine/scene.h>
#include <deform/geometry/phantom.h>
#include <deform/sdk/enum_names.h>
#include <deform/sdk/mesh.h>
#include <deform_harness/child_process.h>
#include <deform_harness/conformance.h>
#include <deform_harness/metrics.h>
#include <deform_harness/runner.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <sstream>

namespace deform::harness {

namespace {

namespace fs = std::filesystem;
using nlohmann::json;

/// A check's verdict: thrown from inside a check to end it.
struct Verdict {
  CheckOutcome outcome;
  std::string detail;
};

[[noreturn]] void fail(const std::string& why) {
  throw Verdict{CheckOutcome::Failed, why};
}
[[noreturn]] void skip(const std::string& why) {
  throw Verdict{CheckOutcome::Skipped, why};
}
void require(bool ok, const std::string& why) {
  if (!ok) fail(why);
}

std::string mm(double metres) {
  std::ostringstream s;
  s.precision(3);
  s << 1e3 * metres << " mm";
  return s.str();
}

/// The cube phantom, bottom `fixedFraction` of its height fixed, no gravity, 50 ms at 1 ms.
json phantomScene(double fixedFraction, Box* bboxOut = nullptr) {
  const Box b = boundingBox(makePhantom("cube", 0.5).V);
  if (bboxOut) *bboxOut = b;
  const Vec3 m = Vec3::Constant(0.05 * b.diagonal());
  const Vec3 lo = b.lo - m;
  const Vec3 hi(b.hi.x() + m.x(), b.hi.y() + m.y(), b.lo.z() + fixedFraction * b.size().z());
  json j;
  j["name"] = "conformance";
  j["organ"] = {{"mesh", "phantom:cube"},
                {"resolution", 0.5},
                {"material", {{"young", 5500}, {"poisson", 0.3}, {"density", 1000}}},
                {"fixed", {{"box", {{lo.x(), lo.y(), lo.z()}, {hi.x(), hi.y(), hi.z()}}}}}};
  j["gravity"] = {0, 0, 0};
  j["dt"] = 1e-3;
  j["duration"] = 0.05;
  j["models"] = json::array({{{"plugin", "any"}}});
  return j;
}

struct Case {
  Scene scene;
  Organ organ;
};

Case makeCase(const json& j) {
  Case c;
  c.scene = parseScene(j, "<conformance>");
  c.organ = loadOrgan(c.scene);
  return c;
}

/// A quasi-static model has no inertia: the time step only samples the trajectory, and 10 ms
/// keeps reference-class solvers to seconds per check. Not in a scene with dynamics: its ODE
/// bodies integrate with the scene's dt, which their couplings' stability depends on
/// (liver_instruments' box at 10 ms: (k dt^2 + 2 c dt) / m = 6, over the limit 4).
Scene sceneFor(const Scene& scene, const ModelInfo& info) {
  Scene s = scene;
  if (info.has(Capability::QuasiStatic) && !scene.needsDynamics()) s.dt = std::max(s.dt, 0.01);
  return s;
}

Real maxDisplacement(const MatX3& x, const MatX3& rest) {
  return (x.topRows(rest.rows()) - rest).rowwise().norm().maxCoeff();
}

Vec3 topCentreVertex(const MatX3& rest, const Box& b) {
  return rest.row(nearestVertex(rest, Vec3(b.center().x(), b.center().y(), b.hi.z()))).transpose();
}

RunRecord runOk(const ModelInfo& info, const Case& c, Cache& cache, const RunOptions& o = {}) {
  RunRecord r = runModel(info, ParamValues::defaults(info.params), sceneFor(c.scene, info), c.organ,
                         cache, o);
  if (r.status != RunStatus::Ok)
    fail(std::string("the run ended ") + statusName(r.status) + ": " + r.message);
  return r;
}

using Check = void (*)(const ModelInfo&, Cache&, const ConformanceOptions&, std::string& detail);

// ------------------------------------------------------------------------------------ checks

void checkInit(const ModelInfo& info, Cache& cache, const ConformanceOptions&, std::string&) {
  require(!info.description.empty(), "the model has no description");
  require(!info.version.empty(), "the model has no version");
  require(static_cast<bool>(info.create), "the model has no create function");
  const Case c = makeCase(phantomScene(0.15));
  std::unique_ptr<Model> model = info.create();
  require(model != nullptr, "create() returned nothing");
  const ParamValues params = ParamValues::defaults(info.params);
  model->init(ModelSetup{c.organ, params, cache, c.scene.dt, c.scene.gravity});
  long long largest = 0;
  for (const auto& [k, v] : model->counts()) {
    require(v >= 0, "count '" + k + "' is negative");
    largest = std::max(largest, v);
  }
  require(largest > 0, "counts() reports no positive count");
  require(model->surface().rows() == c.organ.surface.numVertices(),
          "surface() has " + std::to_string(model->surface().rows()) + " rows, the organ " +
              std::to_string(c.organ.surface.numVertices()) + " vertices");
  require(model->nodes().rows() > 0, "nodes() is empty");
  const Real d = maxDisplacement(model->surface(), c.organ.surface.V);
  require(d < 1e-6 * boundingBox(c.organ.surface.V).diagonal(),
          "surface() right after init is " + mm(d) + " from the rest surface");
  require(!fixedNodeIndices(model->nodes(), c.organ.fixed, c.organ.surface).empty(),
          "the fixed slab pins no node");
}

void checkParams(const ModelInfo& info, Cache&, const ConformanceOptions&, std::string& detail) {
  for (const ParamSpec& p : info.params) {
    require(!p.key.empty(), "a parameter has no key");
    require(!p.description.empty(), "parameter '" + p.key + "' has no description");
    const ParamValue& d = p.defaultValue;
    double x = NAN;
    if (const auto* r = std::get_if<double>(&d)) x = *r;
    if (const auto* i = std::get_if<long long>(&d)) x = double(*i);
    if (!std::isnan(x))
      require(p.min <= x && x <= p.max,
              "parameter '" + p.key + "': the default is outside its declared range");
    if (const auto* s = std::get_if<std::string>(&d); s && !p.choices.empty())
      require(std::find(p.choices.begin(), p.choices.end(), *s) != p.choices.end(),
              "parameter '" + p.key + "': the default is not one of its choices");
    // The harness must refuse a value outside the range before the model sees it.
    if (std::isfinite(p.max) && !std::isnan(x)) {
      bool refused = false;
      try {
        const json above = p.type == ParamType::Int ? json(static_cast<long long>(p.max) + 1)
                                                    : json(p.max + std::max(1.0, std::abs(p.max)));
        resolveParams(info.params, json{{p.key, above}}, "", "/params");
      } catch (const InputError&) {
        refused = true;
      }
      require(refused, "parameter '" + p.key + "': a value above its maximum was accepted");
    }
  }
  // The sweep's axes (and the older knob) name parameters of the model, with valid values.
  for (const auto& [axis, knob] :
       {std::pair{"resolution", &info.resolution}, std::pair{"effort", &info.effort},
        std::pair{"knob", &info.knob}}) {
    if (knob->param.empty()) continue;
    require(info.param(knob->param) != nullptr,
            std::string(axis) + " '" + knob->param + "' is not a parameter of the model");
    for (const auto* values : {&knob->values, &knob->quickValues})
      for (const ParamValue& v : *values) {
        try {
          resolveParams(info.params,
                        json{{knob->param, std::visit([](const auto& x) { return json(x); }, v)}},
                        "", "/params");
        } catch (const InputError& e) {
          require(false, std::string(axis) + " '" + knob->param + "': " + e.what());
        }
      }
  }
  detail = std::to_string(info.params.size()) + " parameters";
}

void checkRest(const ModelInfo& info, Cache& cache, const ConformanceOptions&,
               std::string& detail) {
  const Case c = makeCase(phantomScene(0.15));
  const RunRecord r = runOk(info, c, cache);
  require(r.steps == sceneFor(c.scene, info).numSteps(), "the run stopped early");
  const Real d = maxDisplacement(r.finalSurface, c.organ.surface.V);
  require(d < 1e-6 * boundingBox(c.organ.surface.V).diagonal(),
          "without gravity or load the surface moved " + mm(d));
  detail = "moved " + mm(d);
}

void checkSag(const ModelInfo& info, Cache& cache, const ConformanceOptions&, std::string& detail) {
  if (!info.has(Capability::Gravity)) skip("no gravity capability");
  json j = phantomScene(0.15);
  j["gravity"] = {0, 0, -9.81};
  j["duration"] = 0.1;
  const Case c = makeCase(j);
  const RunRecord r = runOk(info, c, cache);
  const double dz = (r.finalSurface.col(2) - c.organ.surface.V.col(2)).mean();
  require(dz < -1e-7, "under gravity the mean z displacement is " + mm(dz) + ", not downwards");
  detail = "mean sag " + mm(-dz);
}

void checkGrasp(const ModelInfo& info, Cache& cache, const ConformanceOptions&,
                std::string& detail) {
  if (!info.has(Capability::Grasp)) skip("no grasp capability");
  // The jaws close at t = 0 on the top centre (the surface is then at rest), the tool rises by
  // `lift` over 80 ms and holds. Every grasped surface vertex must end at its rest position
  // plus the tool's displacement.
  Box b;
  json j = phantomScene(0.15, &b);
  const Vec3 top = topCentreVertex(makePhantom("cube", 0.5).V, b);
  const Real lift = 0.1 * b.size().z();
  const Real radius = 0.2 * b.size().minCoeff();
  j["tools"] = {{{"type", "grasper"},
                 {"radius", radius},
                 {"trajectory",
                  {{{"t", 0.0}, {"pos", {top.x(), top.y(), top.z()}}, {"jaw", "closed"}},
                   {{"t", 0.08}, {"pos", {top.x(), top.y(), top.z() + lift}}}}}}};
  j["duration"] = 0.1;
  const Case c = makeCase(j);
  const RunRecord r = runOk(info, c, cache);
  require(r.emptyGrasps.empty(), "the grasp closed on no node");
  const std::vector<int> held = deform::graspedSurfaceVertices(c.organ.surface.V, top, radius);
  Real worst = 0;
  int worstV = -1;
  for (int v : held) {
    const Vec3 target = c.organ.surface.V.row(v).transpose() + Vec3(0, 0, lift);
    const Real d = (r.finalSurface.row(v).transpose() - target).norm();
    if (d > worst) worst = d, worstV = v;
  }
  require(worst <= kConformanceGraspTolerance,
          "grasped surface vertex " + std::to_string(worstV) + " is " + mm(worst) +
              " from its target (tolerance " + mm(kConformanceGraspTolerance) + "; " +
              std::to_string(held.size()) + " grasped vertices, lift " + mm(lift) + ")");
  require(r.graspResidual >= 0 && r.graspResidual <= kConformanceGraspTolerance,
          "grasp_residual_m (RMS over the grasp) is " + mm(r.graspResidual));
  require(r.valid, "the run is invalid: " + r.invalidReason);
  // Small jaws (5 mm: a few vertices, narrower than most models' own node spacing) must hold
  // too: the grasp is on the surface, whatever the model's nodes are (issue G1).
  json small = phantomScene(0.15, &b);
  small["tools"] = {{{"type", "grasper"},
                     {"radius", 0.005},
                     {"trajectory",
                      {{{"t", 0.0}, {"pos", {top.x(), top.y(), top.z()}}, {"jaw", "closed"}},
                       {{"t", 0.08}, {"pos", {top.x(), top.y(), top.z() + 0.01}}}}}}};
  small["duration"] = 0.1;
  const RunRecord rs = runOk(info, makeCase(small), cache);
  require(rs.emptyGrasps.empty() && rs.graspResidual >= 0 &&
              rs.graspResidual <= kConformanceGraspTolerance,
          "with 5 mm jaws grasp_residual_m is " + mm(rs.graspResidual));
  detail = std::to_string(held.size()) + " grasped vertices within " + mm(worst) +
           "; 5 mm jaws: residual " + mm(rs.graspResidual);
}

void checkPointForce(const ModelInfo& info, Cache& cache, const ConformanceOptions&,
                     std::string& detail) {
  if (!info.has(Capability::PointForce)) skip("no point_force capability");
  Box b;
  json j = phantomScene(0.15, &b);
  const Vec3 top(b.center().x(), b.center().y(), b.hi.z());
  j["loads"] = {
      {{"type", "point_force"}, {"at", {top.x(), top.y(), top.z()}}, {"force", {0, 0, 0.5}}}};
  const Case c = makeCase(j);
  const RunRecord r = runOk(info, c, cache);
  const int v = nearestVertex(c.organ.surface.V, top);
  const Real dz = r.finalSurface(v, 2) - c.organ.surface.V(v, 2);
  require(dz > 0, "an upward force moved the loaded vertex by " + mm(dz));
  // The loaded patch (the harness's pressure patch, weighted by its shares: the same for every
  // model) moves along an oblique force.
  json oblique = phantomScene(0.15, &b);
  oblique["loads"] = {
      {{"type", "point_force"}, {"at", {top.x(), top.y(), top.z()}}, {"force", {0.3, 0, 0.5}}}};
  const Case co = makeCase(oblique);
  const SurfacePatch patch = Interaction(co.scene, co.organ.surface).loadPatches().at(0);
  const RunRecord ro = runOk(info, co, cache);
  Vec3 u = Vec3::Zero();
  for (size_t k = 0; k < patch.vertices.size(); ++k) {
    const int pv = patch.vertices[k];
    u += patch.weights[k] * (ro.finalSurface.row(pv) - co.organ.surface.V.row(pv)).transpose();
  }
  const Real along = u.dot(Vec3(0.3, 0, 0.5).normalized());
  require(along > 0.3 * u.norm(), "under an oblique force the loaded patch moved " + mm(u.norm()) +
                                      ", only " + mm(along) + " along the force");
  detail = "loaded vertex rose " + mm(dz) + "; patch moved " + mm(along) + " along the force";
}

void checkReset(const ModelInfo& info, Cache& cache, const ConformanceOptions&, std::string&) {
  Box b;
  json j = phantomScene(0.15, &b);
  j["gravity"] = {0, 0, -9.81};
  const Vec3 top = topCentreVertex(makePhantom("cube", 0.5).V, b);
  j["tools"] = {{{"type", "grasper"},
                 {"radius", 0.2 * b.size().minCoeff()},
                 {"trajectory",
                  {{{"t", 0.0}, {"pos", {top.x(), top.y(), top.z()}}, {"jaw", "open"}},
                   {{"t", 0.005}, {"pos", {top.x(), top.y(), top.z()}}, {"jaw", "closed"}},
                   {{"t", 0.03}, {"pos", {top.x(), top.y() + 0.02 * b.size().y(), top.z()}}}}}}};
  j["duration"] = 0.03;
  j["compare_at"] = {0.01, 0.03};
  const Case c = makeCase(j);
  Scene scene = sceneFor(c.scene, info);
  if (!info.has(Capability::Grasp)) scene.tools.clear();
  std::unique_ptr<Model> model = info.create();
  const ParamValues params = ParamValues::defaults(info.params);
  model->init(ModelSetup{c.organ, params, cache, scene.dt, scene.gravity});
  RunRecord a, b2;
  simulate(*model, scene, c.organ, RunOptions{}, a);
  require(a.status == RunStatus::Ok, std::string("first run ") + statusName(a.status));
  model->reset();
  require(model->surface() == c.organ.surface.V ||
              maxDisplacement(model->surface(), c.organ.surface.V) <
                  1e-6 * boundingBox(c.organ.surface.V).diagonal(),
          "reset() does not go back to the rest surface");
  simulate(*model, scene, c.organ, RunOptions{}, b2);
  require(b2.status == RunStatus::Ok, std::string("run after reset ") + statusName(b2.status));
  require(a.compared.size() == b2.compared.size(), "the two runs compared different instants");
  for (size_t i = 0; i < a.compared.size(); ++i)
    require(a.compared[i].positions == b2.compared[i].positions,
            "the run after reset() differs at compared instant " + std::to_string(i));
  require(a.finalSurface == b2.finalSurface, "the final surfaces differ after reset()");
}

/// How long the "scenes" check runs each shipped scene: their grasps close at 0.1 s, and 20 ms
/// of holding shows a grasp that blows up (every model's dominant cost in the suite is here).
constexpr Real kSceneCheckSeconds = 0.12;

void checkScenes(const ModelInfo& info, Cache& cache, const ConformanceOptions& o,
                 std::string& detail) {
  if (o.scenesDir.empty() || !fs::is_directory(o.scenesDir))
    skip("no folder of shipped scenes (--scenes DIR)");
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(o.scenesDir))
    if (e.path().extension() == ".json") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  int ran = 0;
  for (const fs::path& f : files) {
    std::ifstream in(f);
    json j = json::parse(in, nullptr, false);
    if (j.is_discarded() || !j.contains("organ")) continue;
    const std::string mesh = j["organ"].value("mesh", "");
    if (mesh.rfind("phantom:", 0) != 0) continue;  // real meshes are optional data
    j["organ"]["resolution"] = 0.3;                // coarse organ: seconds per scene
    const Scene scene = parseScene(j, f.string());
    if (!unsupportedReason(info, scene).empty()) continue;
    const Organ organ = loadOrgan(scene);
    const Scene run = sceneFor(scene, info);
    RunOptions ro;
    ro.maxSteps = static_cast<int>(std::lround(kSceneCheckSeconds / run.dt));
    // The scene's own parameters for this model when it lists it (a scene may need them, e.g.
    // an implicit integrator), else the model's "conformance" preset (a smaller precomputation,
    // e.g. bullet_deformable's tets), else the defaults.
    ParamValues params = ParamValues::defaults(info.params);
    if (const auto it = info.presets.find("conformance");
        it != info.presets.end() && !it->second.empty())
      for (const auto& [key, value] : it->second.front()) params.set(key, value);
    for (const ModelSpec& spec : scene.models) {
      if (spec.model == info.name)
        params = resolveParams(info.params, spec.params, scene.file, spec.jsonPath + "/params");
    }
    const RunRecord r = runModel(info, params, run, organ, cache, ro);
    ++ran;
    require(r.status == RunStatus::Ok,
            f.filename().string() + ": the run ended " + statusName(r.status) + ": " + r.message);
    require(r.finalSurface.allFinite(), f.filename().string() + ": NaN or Inf in the surface");
  }
  if (ran == 0) skip("no shipped scene this model supports");
  std::ostringstream d;
  d << ran << " scenes, " << kSceneCheckSeconds << " s each";
  detail = d.str();
}

void checkViolent(const ModelInfo& info, Cache& cache, const ConformanceOptions&,
                  std::string& detail) {
  if (!info.has(Capability::PointForce)) skip("no point_force capability");
  if (info.has(Capability::QuasiStatic)) skip("quasi-static: no time integration to blow up");
  // A soft organ, a huge force and a coarse step: whatever happens, the run ends as a status.
  Box b;
  json j = phantomScene(0.15, &b);
  j["organ"]["material"]["young"] = 1000;
  j["organ"]["material"]["poisson"] = 0.49;
  const Vec3 top(b.center().x(), b.center().y(), b.hi.z());
  j["loads"] = {
      {{"type", "point_force"}, {"at", {top.x(), top.y(), top.z()}}, {"force", {0, 0, 1e5}}}};
  j["dt"] = 0.02;
  j["duration"] = 0.1;
  const Case c = makeCase(j);
  const RunRecord r =
      runModel(info, ParamValues::defaults(info.params), sceneFor(c.scene, info), c.organ, cache);
  require(r.status != RunStatus::Unsupported, "reported unsupported: " + r.message);
  if (r.status == RunStatus::Ok) {
    require(r.finalSurface.allFinite(), "ok but the surface has NaN or Inf");
    const Box box = boundingBox(c.organ.surface.V);
    const Vec3 grow = Vec3::Constant(0.5 * (tol::kDivergenceBoxFactor - 1) * box.diagonal());
    for (Eigen::Index v = 0; v < r.finalSurface.rows(); ++v) {
      const Vec3 x = r.finalSurface.row(v).transpose();
      require(((x - box.lo).array() >= -grow.array()).all() &&
                  ((x - box.hi).array() <= grow.array()).all(),
              "ok but vertex " + std::to_string(v) + " left the divergence box");
    }
  } else {
    require(!r.message.empty(), std::string(statusName(r.status)) + " without a message");
  }
  detail = std::string("ended ") + statusName(r.status);
}

/// Signed distance to the probe: tip sphere (centre c, radius r) and shaft capsule (radius r,
/// from c up along +z for L).
Real probeDistance(const Vec3& p, const Vec3& c, Real r, Real L) {
  const Real s = std::clamp((p - c).z(), Real(0), L);
  return std::min((p - c).norm(), (p - c - Vec3(0, 0, s)).norm()) - r;
}

void checkContact(const ModelInfo& info, Cache& cache, const ConformanceOptions&,
                  std::string& detail) {
  // A probe comes down onto the top centre and presses 10% of the height into it.
  Box b;
  json j = phantomScene(0.2, &b);
  const Vec3 top(b.center().x(), b.center().y(), b.hi.z());
  const Real radius = 0.15 * b.size().x(), depth = 0.1 * b.size().z(), shaft = 0.5 * b.size().z();
  const Vec3 start = top + Vec3(0, 0, radius + 0.002);
  const Vec3 end = top + Vec3(0, 0, radius - depth);
  j["tools"] = {{{"type", "probe"},
                 {"radius", radius},
                 {"shaft", {{"length", shaft}}},
                 {"trajectory",
                  {{{"t", 0.0}, {"pos", {start.x(), start.y(), start.z()}}},
                   {{"t", 0.04}, {"pos", {end.x(), end.y(), end.z()}}}}}}};
  j["contact"] = {{"thickness", 1e-4}};
  const Case c = makeCase(j);
  if (!info.has(Capability::Contact)) {
    const RunRecord r = runModel(info, ParamValues::defaults(info.params), c.scene, c.organ, cache);
    require(
        r.status == RunStatus::Unsupported,
        std::string("no contact capability, yet the probe scene ended ") + statusName(r.status));
    skip("no contact capability (the probe scene is refused as unsupported, as it must be)");
  }
  Scene run = sceneFor(c.scene, info);
  std::unique_ptr<Model> model = info.create();
  const ParamValues params = ParamValues::defaults(info.params);
  model->init(ModelSetup{c.organ, params, cache, run.dt, run.gravity});
  const std::vector<int> fixed = fixedNodeIndices(model->nodes(), c.organ.fixed, c.organ.surface);
  const bool nodesAreSurface = model->nodes().rows() == c.organ.surface.numVertices();
  Interaction inter(run, c.organ.surface);
  require(inter.contactWorld() != nullptr, "no contact world (core built without Bullet)");
  Real worst = 1e9;
  for (int k = 0; k < run.numSteps(); ++k) {
    const StepInput in = inter.prepare(k * run.dt, run.dt, *model);
    require(model->step(in) == StepStatus::Ok, "step " + std::to_string(k) + " did not end ok");
    inter.finishStep(in, *model);
    const Vec3 p = in.contact->position(0);
    const MatX3& x = model->surface();
    for (Eigen::Index i = 0; i < x.rows(); ++i)
      worst = std::min(worst, probeDistance(x.row(i).transpose(), p, radius, shaft));
    if (nodesAreSurface) {
      const MatX3& n = model->nodes();
      for (Eigen::Index i = 0; i < n.rows(); ++i) {
        if (std::binary_search(fixed.begin(), fixed.end(), int(i))) continue;
        worst = std::min(worst, probeDistance(n.row(i).transpose(), p, radius, shaft));
      }
    }
  }
  require(worst >= -1e-6, "a surface point ended a step " + mm(-worst) + " inside the probe");
  const int topV = nearestVertex(c.organ.surface.V, top);
  require(model->surface()(topV, 2) < top.z() - 0.5 * depth, "the probe did not push the organ");
  detail = "deepest penetration " + mm(std::max<Real>(0, -worst));
}

struct CheckDef {
  const char* name;
  Check fn;
};

const std::vector<CheckDef>& checks() {
  static const std::vector<CheckDef> all = {
      {"init", checkInit},       {"params", checkParams}, {"rest", checkRest},
      {"sag", checkSag},         {"grasp", checkGrasp},   {"point_force", checkPointForce},
      {"reset", checkReset},     {"scenes", checkScenes}, {"violent_load", checkViolent},
      {"contact", checkContact},
  };
  return all;
}

bool listed(const std::vector<std::string>& list, const std::string& s) {
  return list.empty() || std::find(list.begin(), list.end(), s) != list.end();
}

bool expectedToFail(const ConformanceOptions& o, const CheckResult& r) {
  for (const std::string& e : o.expectedFailures) {
    if (e == r.plugin + "/" + r.check || e == r.plugin + "/" + r.model + "/" + r.check) return true;
  }
  return false;
}

}  // namespace

const char* checkOutcomeName(CheckOutcome o) {
  static constexpr EnumName<CheckOutcome> kNames[] = {{CheckOutcome::Passed, "pass"},
                                                      {CheckOutcome::Failed, "FAIL"},
                                                      {CheckOutcome::Skipped, "skip"},
                                                      {CheckOutcome::ExpectedFailure, "xfail"},
                                                      {CheckOutcome::UnexpectedPass, "XPASS"}};
  return enumName(kNames, o, "?");
}

const std::vector<std::string>& conformanceCheckNames() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n = {"load"};
    for (const CheckDef& c : checks()) n.push_back(c.name);
    return n;
  }();
  return names;
}

fs::path defaultConformanceScenesDir() {
  std::error_code ec;
  const std::string exe = selfExecutable();
  if (!exe.empty()) {
    const fs::path installed =
        (fs::path(exe).parent_path() / ".." / "share" / "deformbench" / "scenes")
            .lexically_normal();
    if (fs::is_directory(installed, ec)) return installed;
  }
#ifdef DEFORM_SOURCE_DIR
  const fs::path source = fs::path(DEFORM_SOURCE_DIR) / "scenes";
  if (fs::is_directory(source, ec)) return source;
#endif
  return {};
}

std::vector<CheckResult> runConformance(PluginLoader& loader, Cache& cache,
                                        const ConformanceOptions& o) {
  for (const auto& [option, names] :
       {std::pair{"--check", &o.checks}, std::pair{"--skip-check", &o.skipChecks}}) {
    for (const std::string& c : *names) {
      if (!listed(conformanceCheckNames(), c)) {
        std::string known;
        for (const auto& n : conformanceCheckNames()) known += (known.empty() ? "" : ", ") + n;
        throw InputError(option, "", "unknown check '" + c + "' (known: " + known + ")");
      }
    }
  }
  const auto wanted = [&o](const std::string& check) {
    return listed(o.checks, check) &&
           std::find(o.skipChecks.begin(), o.skipChecks.end(), check) == o.skipChecks.end();
  };
  std::vector<std::string> plugins = o.plugins;
  if (plugins.empty()) plugins = loader.discover();
  if (plugins.empty()) {
    std::string dirs;
    for (const auto& d : loader.searchPath()) dirs += (dirs.empty() ? "" : ", ") + d;
    throw InputError("conformance", "",
                     "no plugin found in: " + dirs + " (name a folder with --plugin-dir DIR)");
  }
  std::vector<CheckResult> results;
  const auto finish = [&](CheckResult r) {
    const bool expected = expectedToFail(o, r);
    if (expected && r.outcome == CheckOutcome::Failed) r.outcome = CheckOutcome::ExpectedFailure;
    if (expected && r.outcome == CheckOutcome::Passed) {
      r.outcome = CheckOutcome::UnexpectedPass;
      r.detail = "listed as an expected failure but passed: remove it from the list" +
                 (r.detail.empty() ? "" : " (" + r.detail + ")");
    }
    if (o.report) o.report(r);
    results.push_back(std::move(r));
  };
  int modelsSeen = 0;
  for (const std::string& plugin : plugins) {
    CheckResult load;
    load.plugin = plugin;
    load.check = "load";
    const std::vector<ModelInfo>* models = nullptr;
    try {
      models = &loader.loadFile(loader.locate(plugin));
      forceSingleThreadedNumerics();
      if (models->empty()) {
        load.outcome = CheckOutcome::Failed;
        load.detail = "the plugin registers no model";
      } else {
        load.detail = std::to_string(models->size()) + " model(s)";
      }
    } catch (const PluginError& e) {
      if (!o.plugins.empty() && e.kind() == PluginError::Kind::FileNotFound) throw;
      load.outcome = CheckOutcome::Failed;
      load.detail = e.what();
    }
    if (wanted("load")) finish(load);
    if (!models) continue;
    for (const ModelInfo& info : *models) {
      if (!listed(o.models, info.name)) continue;
      ++modelsSeen;
      for (const CheckDef& def : checks()) {
        if (!wanted(def.name)) continue;
        CheckResult r;
        r.plugin = plugin;
        r.model = info.name;
        r.check = def.name;
        const auto start = std::chrono::steady_clock::now();
        try {
          def.fn(info, cache, o, r.detail);
          r.outcome = CheckOutcome::Passed;
        } catch (const Verdict& v) {
          r.outcome = v.outcome;
          r.detail = v.detail;
        } catch (const std::exception& e) {
          r.outcome = CheckOutcome::Failed;
          r.detail = std::string("exception: ") + e.what();
        } catch (...) {
          r.outcome = CheckOutcome::Failed;
          r.detail = "unknown exception";
        }
        r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
        finish(std::move(r));
      }
    }
  }
  if (!o.models.empty() && modelsSeen == 0) {
    std::string names;
    for (const auto& m : o.models) names += (names.empty() ? "" : ", ") + m;
    throw InputError("--model", "", "no model named " + names + " in the plugins checked");
  }
  return results;
}

}  // namespace deform::harness
