// The conformance suite every plugin must pass (STYLE.md item 7), run against every plugin found
// in the build tree's plugin folder and every model each one registers. Scenes are built in
// memory on small phantoms so each plugin takes seconds. Checks a model's capabilities say do
// not apply are skipped with the reason.
#include <deform/interaction.h>
#include <deform/phantom.h>
#include <deform/plugin_loader.h>
#include <deform/scene.h>
#include <deform_harness/runner.h>
#include <gtest/gtest.h>

#include "conformance_common.h"

#include <filesystem>
#include <fstream>
#include <iostream>

namespace deform::harness {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

/// A phantom scene: organ, fixed slab at the bottom (fraction of the height), no gravity.
json phantomScene(const std::string& phantom, double resolution, double fixedFraction,
                  Box* bboxOut = nullptr) {
  const Box b = boundingBox(makePhantom(phantom, resolution).V);
  if (bboxOut) *bboxOut = b;
  const Vec3 m = Vec3::Constant(0.05 * b.diagonal());
  const Vec3 lo = b.lo - m;
  const Vec3 hi(b.hi.x() + m.x(), b.hi.y() + m.y(), b.lo.z() + fixedFraction * b.size().z());
  json j;
  j["name"] = "conformance-" + phantom;
  j["organ"] = {{"mesh", "phantom:" + phantom},
                {"resolution", resolution},
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
  c.scene = parseScene(j, "");
  c.organ = loadOrgan(c.scene);
  return c;
}

/// The scene as a model runs it: a quasi-static model has no inertia, so the time step only
/// samples the trajectory; 10 ms keeps the reference-class solvers to seconds per test.
Scene sceneFor(const Scene& scene, const ModelInfo& info) {
  Scene s = scene;
  if (info.has(Capability::QuasiStatic)) s.dt = std::max(s.dt, 0.01);
  return s;
}

class Conformance : public ::testing::TestWithParam<std::string> {
 protected:
  const std::vector<ModelInfo>& models() {
    return conformanceLoader().loadFile(conformanceLoader().locate(GetParam()));
  }
};

Real maxDisplacement(const MatX3& x, const MatX3& rest) {
  return (x.topRows(rest.rows()) - rest).rowwise().norm().maxCoeff();
}

TEST_P(Conformance, CountsSurfaceAndNodesAfterInit) {
  const Case c = makeCase(phantomScene("cube", 0.5, 0.15));
  for (const ModelInfo& info : models()) {
    SCOPED_TRACE(info.name);
    EXPECT_FALSE(info.description.empty());
    EXPECT_FALSE(info.version.empty());
    std::unique_ptr<Model> model = info.create();
    ASSERT_TRUE(model);
    const ParamValues params = ParamValues::defaults(info.params);
    model->init(ModelSetup{c.organ, params, conformanceCache(), c.scene.dt, c.scene.gravity});
    const Counts counts = model->counts();
    // Counts are sizes: none negative, and the model has something (a count of a disabled
    // feature, e.g. bending constraints switched off, may be 0).
    EXPECT_FALSE(counts.empty()) << "a model reports at least one count";
    long long largest = 0;
    for (const auto& [k, v] : counts) {
      EXPECT_GE(v, 0) << k;
      largest = std::max(largest, v);
    }
    EXPECT_GT(largest, 0);
    EXPECT_EQ(model->surface().rows(), c.organ.surface.numVertices());
    EXPECT_GT(model->nodes().rows(), 0);
    EXPECT_LT(maxDisplacement(model->surface(), c.organ.surface.V),
              1e-6 * boundingBox(c.organ.surface.V).diagonal())
        << "surface() right after init is the rest surface";
    EXPECT_FALSE(fixedNodeIndices(model->nodes(), c.organ.fixed, c.organ.surface).empty())
        << "the fixed slab pins some node";
  }
}

TEST_P(Conformance, RestStaysAtRestWithoutGravity) {
  const Case c = makeCase(phantomScene("cube", 0.5, 0.15));
  for (const ModelInfo& info : models()) {
    SCOPED_TRACE(info.name);
    const RunRecord r = runModel(info, ParamValues::defaults(info.params), sceneFor(c.scene, info),
                                 c.organ, conformanceCache());
    ASSERT_EQ(r.status, RunStatus::Ok) << r.message;
    EXPECT_EQ(r.steps, sceneFor(c.scene, info).numSteps());
    EXPECT_LT(maxDisplacement(r.finalSurface, c.organ.surface.V),
              1e-6 * boundingBox(c.organ.surface.V).diagonal());
  }
}

TEST_P(Conformance, GravitySagsTheOrgan) {
  // The cube standing on its fixed bottom slab: under gravity its free part settles downwards.
  json j = phantomScene("cube", 0.5, 0.15);
  j["gravity"] = {0, 0, -9.81};
  j["duration"] = 0.1;
  const Case c = makeCase(j);
  int tested = 0;
  for (const ModelInfo& info : models()) {
    SCOPED_TRACE(info.name);
    if (!info.has(Capability::Gravity)) continue;
    ++tested;
    const RunRecord r = runModel(info, ParamValues::defaults(info.params), sceneFor(c.scene, info),
                                 c.organ, conformanceCache());
    ASSERT_EQ(r.status, RunStatus::Ok) << r.message;
    const VecX dz = r.finalSurface.col(2) - c.organ.surface.V.col(2);
    EXPECT_LT(dz.mean(), -1e-7) << "mean z displacement " << dz.mean() << " m";
  }
  if (tested == 0) GTEST_SKIP() << "no model of this plugin has the gravity capability";
}

TEST_P(Conformance, GraspMovesTheGraspedRegionWithTheTool) {
  Box b;
  json j = phantomScene("cube", 0.5, 0.15, &b);
  const MatX3 rest = makePhantom("cube", 0.5).V;
  const Vec3 top =
      rest.row(nearestVertex(rest, Vec3(b.center().x(), b.center().y(), b.hi.z()))).transpose();
  const Real lift = 0.1 * b.size().z();
  const Real radius = 0.2 * b.size().minCoeff();
  j["tools"] = {{{"type", "grasper"},
                 {"radius", radius},
                 {"trajectory",
                  {{{"t", 0.0}, {"pos", {top.x(), top.y(), top.z()}}, {"jaw", "closed"}},
                   {{"t", 0.08}, {"pos", {top.x(), top.y(), top.z() + lift}}}}}}};
  j["duration"] = 0.1;
  const Case c = makeCase(j);
  int tested = 0;
  for (const ModelInfo& info : models()) {
    SCOPED_TRACE(info.name);
    if (!info.has(Capability::Grasp)) continue;
    ++tested;
    const RunRecord r = runModel(info, ParamValues::defaults(info.params), sceneFor(c.scene, info),
                                 c.organ, conformanceCache());
    ASSERT_EQ(r.status, RunStatus::Ok) << r.message;
    EXPECT_TRUE(r.emptyGrasps.empty()) << "the grasp closed on no node";
    const std::vector<int> region = nearestVertices(c.organ.surface.V, top, 5);
    double dz = 0;
    for (int v : region) dz += r.finalSurface(v, 2) - c.organ.surface.V(v, 2);
    dz /= double(region.size());
    EXPECT_GT(dz, 0.3 * lift) << "grasped region rose " << dz << " m of the tool's " << lift;
  }
  if (tested == 0) GTEST_SKIP() << "no model of this plugin has the grasp capability";
}

// Issue G1: the grasp is defined on the surface, the same set for every model, and every model
// makes the grasped surface points follow the tool through its own mapping. Small jaws (5 mm, a
// few surface vertices) on the top of the cube, lifted 1 cm: every model holds the grasped
// vertices within 0.5 mm of their targets (RMS over the grasp, grasp_residual_m) and the run is
// valid.
TEST_P(Conformance, GraspHoldsTheGraspedSurfaceWithinHalfAMillimetre) {
  Box b;
  json j = phantomScene("cube", 0.5, 0.15, &b);
  const MatX3 rest = makePhantom("cube", 0.5).V;
  const Vec3 top =
      rest.row(nearestVertex(rest, Vec3(b.center().x(), b.center().y(), b.hi.z()))).transpose();
  j["tools"] = {{{"type", "grasper"},
                 {"radius", 0.005},
                 {"trajectory",
                  {{{"t", 0.0}, {"pos", {top.x(), top.y(), top.z()}}, {"jaw", "closed"}},
                   {{"t", 0.08}, {"pos", {top.x(), top.y(), top.z() + 0.01}}}}}}};
  j["duration"] = 0.1;
  const Case c = makeCase(j);
  int tested = 0;
  for (const ModelInfo& info : models()) {
    SCOPED_TRACE(info.name);
    if (!info.has(Capability::Grasp)) continue;
    ++tested;
    const RunRecord r = runModel(info, ParamValues::defaults(info.params), sceneFor(c.scene, info),
                                 c.organ, conformanceCache());
    ASSERT_EQ(r.status, RunStatus::Ok) << r.message;
    EXPECT_TRUE(r.emptyGrasps.empty());
    ASSERT_GE(r.graspResidual, 0.0) << "no grasp was in force";
    EXPECT_LT(r.graspResidual, 0.5e-3) << "grasp_residual_m";
    EXPECT_TRUE(r.valid) << r.invalidReason;
  }
  if (tested == 0) GTEST_SKIP() << "no model of this plugin has the grasp capability";
}

// Issue G1: the same per-vertex forces for every model; the loaded patch (the harness's pressure
// patch, weighted by its shares) moves along the force.
TEST_P(Conformance, PointForceMovesTheLoadedPatchAlongTheForce) {
  Box b;
  json j = phantomScene("cube", 0.5, 0.15, &b);
  const Vec3 top(b.center().x(), b.center().y(), b.hi.z());
  j["loads"] = {
      {{"type", "point_force"}, {"at", {top.x(), top.y(), top.z()}}, {"force", {0.3, 0, 0.5}}}};
  const Case c = makeCase(j);
  const SurfacePatch patch = Interaction(c.scene, c.organ.surface).loadPatches().at(0);
  int tested = 0;
  for (const ModelInfo& info : models()) {
    SCOPED_TRACE(info.name);
    if (!info.has(Capability::PointForce)) continue;
    ++tested;
    const RunRecord r = runModel(info, ParamValues::defaults(info.params), sceneFor(c.scene, info),
                                 c.organ, conformanceCache());
    ASSERT_EQ(r.status, RunStatus::Ok) << r.message;
    Vec3 u = Vec3::Zero();
    for (size_t k = 0; k < patch.vertices.size(); ++k) {
      const int v = patch.vertices[k];
      u += patch.weights[k] * (r.finalSurface.row(v) - c.organ.surface.V.row(v)).transpose();
    }
    EXPECT_GT(u.dot(Vec3(0.3, 0, 0.5).normalized()), 0.3 * u.norm())
        << "the patch moved " << u.transpose() << " m";
  }
  if (tested == 0) GTEST_SKIP() << "no model of this plugin has the point_force capability";
}

TEST_P(Conformance, PointForceMovesTheLoadedVertexAlongTheForce) {
  Box b;
  json j = phantomScene("cube", 0.5, 0.15, &b);
  const Vec3 top(b.center().x(), b.center().y(), b.hi.z());
  j["loads"] = {
      {{"type", "point_force"}, {"at", {top.x(), top.y(), top.z()}}, {"force", {0, 0, 0.5}}}};
  const Case c = makeCase(j);
  int tested = 0;
  for (const ModelInfo& info : models()) {
    SCOPED_TRACE(info.name);
    if (!info.has(Capability::PointForce)) continue;
    ++tested;
    const RunRecord r = runModel(info, ParamValues::defaults(info.params), sceneFor(c.scene, info),
                                 c.organ, conformanceCache());
    ASSERT_EQ(r.status, RunStatus::Ok) << r.message;
    const int v = nearestVertex(c.organ.surface.V, top);
    EXPECT_GT(r.finalSurface(v, 2) - c.organ.surface.V(v, 2), 0.0);
  }
  if (tested == 0) GTEST_SKIP() << "no model of this plugin has the point_force capability";
}

TEST_P(Conformance, ResetThenRerunReproducesBitForBit) {
  Box b;
  json j = phantomScene("cube", 0.5, 0.15, &b);
  j["gravity"] = {0, 0, -9.81};
  const MatX3 rest = makePhantom("cube", 0.5).V;
  const Vec3 top =
      rest.row(nearestVertex(rest, Vec3(b.center().x(), b.center().y(), b.hi.z()))).transpose();
  j["tools"] = {{{"type", "grasper"},
                 {"radius", 0.2 * b.size().minCoeff()},
                 {"trajectory",
                  {{{"t", 0.0}, {"pos", {top.x(), top.y(), top.z()}}, {"jaw", "open"}},
                   {{"t", 0.005}, {"pos", {top.x(), top.y(), top.z()}}, {"jaw", "closed"}},
                   {{"t", 0.03}, {"pos", {top.x(), top.y() + 0.02 * b.size().y(), top.z()}}}}}}};
  j["duration"] = 0.03;
  j["compare_at"] = {0.01, 0.03};
  const Case c = makeCase(j);
  for (const ModelInfo& info : models()) {
    SCOPED_TRACE(info.name);
    Scene scene = sceneFor(c.scene, info);
    if (!info.has(Capability::Grasp)) scene.tools.clear();
    std::unique_ptr<Model> model = info.create();
    const ParamValues params = ParamValues::defaults(info.params);
    model->init(ModelSetup{c.organ, params, conformanceCache(), scene.dt, scene.gravity});
    RunRecord a, b2;
    simulate(*model, scene, c.organ, RunOptions{}, a);
    ASSERT_EQ(a.status, RunStatus::Ok) << a.message;
    model->reset();
    EXPECT_TRUE(model->surface() == c.organ.surface.V ||
                maxDisplacement(model->surface(), c.organ.surface.V) <
                    1e-6 * boundingBox(c.organ.surface.V).diagonal())
        << "reset() goes back to the rest state";
    simulate(*model, scene, c.organ, RunOptions{}, b2);
    ASSERT_EQ(b2.status, RunStatus::Ok) << b2.message;
    ASSERT_EQ(a.compared.size(), b2.compared.size());
    for (size_t i = 0; i < a.compared.size(); ++i)
      EXPECT_TRUE(a.compared[i].positions == b2.compared[i].positions) << "instant " << i;
    EXPECT_TRUE(a.finalSurface == b2.finalSurface);
  }
}

TEST_P(Conformance, NoNanOnTheShippedScenes) {
  const fs::path dir = fs::path(DEFORM_SOURCE_DIR) / "scenes";
  if (!fs::is_directory(dir)) GTEST_SKIP() << "no scenes folder";
  int ran = 0;
  for (const auto& entry : fs::directory_iterator(dir)) {
    if (entry.path().extension() != ".json") continue;
    SCOPED_TRACE(entry.path().filename().string());
    std::ifstream in(entry.path());
    json j = json::parse(in);
    const std::string mesh = j["organ"]["mesh"];
    if (mesh.rfind("phantom:", 0) == 0) {
      j["organ"]["resolution"] = 0.3;  // shortened: coarse organ
    } else {
      continue;  // real meshes are optional (eval-data); the standard scenes are the phantoms
    }
    const Scene scene = parseScene(j, entry.path().string());
    const Organ organ = loadOrgan(scene);
    for (const ModelInfo& info : models()) {
      SCOPED_TRACE(info.name);
      if (!unsupportedReason(info, scene).empty()) continue;
      // The scene's own parameters for this model when it lists it, else the defaults.
      ParamValues params = ParamValues::defaults(info.params);
      for (const ModelSpec& spec : scene.models) {
        if (spec.plugin == GetParam() && spec.model == info.name)
          params = resolveParams(info.params, spec.params, scene.file, spec.jsonPath + "/params");
      }
      const Scene run = sceneFor(scene, info);
      RunOptions o;
      o.maxSteps = static_cast<int>(std::lround(0.15 / run.dt));  // past the grasps' closing
      const RunRecord r = runModel(info, params, run, organ, conformanceCache(), o);
      ++ran;
      EXPECT_EQ(r.status, RunStatus::Ok) << r.message;
      EXPECT_TRUE(r.finalSurface.allFinite());
    }
  }
  if (ran == 0) GTEST_SKIP() << "no shipped scene this plugin supports";
}

TEST_P(Conformance, ViolentLoadEndsAsAStatusNeverACrashOrNan) {
  // Issue F9 item 5: a soft organ, a huge force and a coarse time step. Whatever the model does
  // (stay stable, blow up, give up), the run must end as a status: "ok" only with a finite
  // surface inside the divergence box, "diverged" or "failed" with a message saying why; no
  // exception escapes runModel and nothing crashes.
  Box b;
  json j = phantomScene("cube", 0.5, 0.15, &b);
  j["organ"]["material"]["young"] = 1000;
  j["organ"]["material"]["poisson"] = 0.49;
  const Vec3 top(b.center().x(), b.center().y(), b.hi.z());
  j["loads"] = {
      {{"type", "point_force"}, {"at", {top.x(), top.y(), top.z()}}, {"force", {0, 0, 1e5}}}};
  j["dt"] = 0.02;
  j["duration"] = 0.1;
  const Case c = makeCase(j);
  Box box = boundingBox(c.organ.surface.V);
  const Vec3 grow = Vec3::Constant(0.5 * (tol::kDivergenceBoxFactor - 1) * box.diagonal());
  int tested = 0;
  for (const ModelInfo& info : models()) {
    SCOPED_TRACE(info.name);
    if (!info.has(Capability::PointForce)) continue;
    // A quasi-static reference has no time integration to blow up; its Newton load stepping
    // on this load took 400 s (reference_fem, ending "ok"), too long for this suite.
    if (info.has(Capability::QuasiStatic)) continue;
    ++tested;
    RunRecord r;
    ASSERT_NO_THROW(r = runModel(info, ParamValues::defaults(info.params), sceneFor(c.scene, info),
                                 c.organ, conformanceCache()));
    std::cout << "[ extreme  ] " << info.name << ": " << statusName(r.status) << " after "
              << r.steps << " steps" << (r.message.empty() ? "" : ": " + r.message) << "\n";
    EXPECT_NE(r.status, RunStatus::Unsupported);
    if (r.status == RunStatus::Ok) {
      ASSERT_TRUE(r.finalSurface.allFinite());
      for (Eigen::Index v = 0; v < r.finalSurface.rows(); ++v) {
        const Vec3 x = r.finalSurface.row(v).transpose();
        ASSERT_TRUE(((x - box.lo).array() >= -grow.array()).all() &&
                    ((x - box.hi).array() <= grow.array()).all())
            << "vertex " << v << " left the divergence box but the run is ok";
      }
    } else {
      EXPECT_FALSE(r.message.empty()) << statusName(r.status) << " without a message";
    }
  }
  if (tested == 0) GTEST_SKIP() << "no dynamic model of this plugin has point forces";
}

INSTANTIATE_TEST_SUITE_P(Plugins, Conformance, ::testing::ValuesIn(conformancePluginNames()),
                         [](const ::testing::TestParamInfo<std::string>& p) { return p.param; });
GTEST_ALLOW_UNINSTANTIATED_PARAMETERIZED_TEST(Conformance);

TEST(ConformanceSetup, EveryPluginFoundLoadsAndRegistersAModel) {
  const std::vector<std::string> names = conformancePluginNames();
  if (names.empty()) GTEST_SKIP() << "no plugin in " << DEFORM_BUILD_PLUGIN_DIR << " yet";
  for (const std::string& name : names) {
    SCOPED_TRACE(name);
    const std::vector<ModelInfo>* models = nullptr;
    EXPECT_NO_THROW(models = &conformanceLoader().loadFile(conformanceLoader().locate(name)));
    if (models) {
      EXPECT_FALSE(models->empty());
    }
  }
}

}  // namespace
}  // namespace deform::harness
