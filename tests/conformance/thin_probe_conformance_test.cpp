// Contact conformance on surface triangles (issue F8, "the surface triangles for the others"): a
// probe whose tip is much thinner than the surface's edges, pressed into the middle of a coarse
// triangle, meets no vertex; every model whose collision proxy is its surface must still leave no
// point of its surface triangles inside the tip after any step.
#include <deform/contact.h>
#include <deform/distance.h>
#include <deform/interaction.h>
#include <deform/phantom.h>
#include <deform/plugin_loader.h>
#include <deform/scene.h>
#include <deform_harness/runner.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

namespace deform::harness {
namespace {

using nlohmann::json;

PluginLoader& thinProbeLoader() {
  static PluginLoader* l = new PluginLoader({DEFORM_BUILD_PLUGIN_DIR});
  return *l;
}

std::vector<std::string> plugins() {
  try {
    return PluginLoader({DEFORM_BUILD_PLUGIN_DIR}).discover();
  } catch (const std::exception&) {
    return {};
  }
}

Cache& thinProbeCache() {
  static Cache c(Cache::defaultDir());
  return c;
}

/// Plugins whose contact proxy is their surface (triangles); metaballs and particle_bem collide
/// with spheres of their own and are not asked this.
bool surfaceProxy(const std::string& plugin) {
  for (const char* p : {"pbd", "massspring", "fem_hex", "hybrid_fem_pbd", "reference_fem"})
    if (plugin == p) return true;
  return false;
}

class ThinProbeConformance : public ::testing::TestWithParam<std::string> {};

TEST_P(ThinProbeConformance, AThinTipInTheMiddleOfACoarseTriangleLeavesNoSurfacePointInside) {
  if (!surfaceProxy(GetParam())) GTEST_SKIP() << "its contact proxy is not its surface";
  const SurfaceMesh s = makePhantom("cube", 0.5);
  const Box b = boundingBox(s.V);
  // The top triangle nearest the top centre; the tip goes down onto its centroid.
  const Vec3 topCentre(b.center().x(), b.center().y(), b.hi.z());
  int tri = -1;
  Real best = 1e9, shortest = 0;
  for (int f = 0; f < s.numFaces(); ++f) {
    const Vec3 a = s.V.row(s.F(f, 0)), p = s.V.row(s.F(f, 1)), q = s.V.row(s.F(f, 2));
    if (std::max({a.z(), p.z(), q.z()}) - std::min({a.z(), p.z(), q.z()}) > 1e-9 ||
        a.z() < b.hi.z() - 1e-9)
      continue;
    const Real d = ((a + p + q) / 3 - topCentre).norm();
    if (d < best) {
      best = d;
      tri = f;
      shortest = std::min({(p - a).norm(), (q - p).norm(), (a - q).norm()});
    }
  }
  ASSERT_GE(tri, 0);
  const Vec3 centroid =
      (s.V.row(s.F(tri, 0)) + s.V.row(s.F(tri, 1)) + s.V.row(s.F(tri, 2))).transpose() / 3;
  const Real r = 0.12 * shortest, depth = 0.6 * r;  // the vertices stay > r away from the tip
  const Vec3 start = centroid + Vec3(0, 0, r + 0.002), end = centroid + Vec3(0, 0, r - depth);
  const Vec3 m = Vec3::Constant(0.05 * b.diagonal());
  json j;
  j["organ"] = {{"mesh", "phantom:cube"},
                {"resolution", 0.5},
                {"material", {{"young", 5500}, {"poisson", 0.3}, {"density", 1000}}},
                {"fixed",
                 {{"box",
                   {{b.lo.x() - m.x(), b.lo.y() - m.y(), b.lo.z() - m.z()},
                    {b.hi.x() + m.x(), b.hi.y() + m.y(), b.lo.z() + 0.2 * b.size().z()}}}}}};
  j["gravity"] = {0, 0, 0};
  j["dt"] = 1e-3;
  j["duration"] = 0.03;
  j["tools"] = {{{"type", "probe"},
                 {"radius", r},
                 {"shaft", {{"length", 0.0}}},
                 {"trajectory",
                  {{{"t", 0.0}, {"pos", {start.x(), start.y(), start.z()}}},
                   {{"t", 0.02}, {"pos", {end.x(), end.y(), end.z()}}}}}}};
  j["contact"] = {{"thickness", 1e-4}};
  j["models"] = json::array({{{"plugin", "any"}}});
  const Scene scene = parseScene(j, "");
  const Organ organ = loadOrgan(scene);
  int tested = 0;
  for (const ModelInfo& info : thinProbeLoader().loadFile(thinProbeLoader().locate(GetParam()))) {
    SCOPED_TRACE(info.name);
    if (!info.has(Capability::Contact)) continue;
    ++tested;
    Scene run = scene;
    if (info.has(Capability::QuasiStatic)) run.dt = 0.01;
    std::unique_ptr<Model> model = info.create();
    model->init(ModelSetup{organ, ParamValues::defaults(info.params), thinProbeCache(), run.dt,
                           run.gravity});
    Interaction inter(run, organ.surface);
    Real worst = 1e9, deepestVertex = 1e9;
    for (int k = 0; k < run.numSteps(); ++k) {
      const StepInput in = inter.prepare(k * run.dt, run.dt, *model);
      ASSERT_EQ(model->step(in), StepStatus::Ok) << "step " << k;
      inter.finishStep(in, *model);
      const Vec3 c = in.contact->position(0);
      const MatX3& x = model->surface();
      ASSERT_EQ(x.rows(), organ.surface.numVertices());
      for (int f = 0; f < organ.surface.numFaces(); ++f) {
        const TriangleClosestPoint cp = closestPointOnTriangle(
            c, x.row(organ.surface.F(f, 0)).transpose(), x.row(organ.surface.F(f, 1)).transpose(),
            x.row(organ.surface.F(f, 2)).transpose());
        worst = std::min(worst, std::sqrt(cp.dist2) - r);
      }
      for (Eigen::Index i = 0; i < x.rows(); ++i)
        deepestVertex = std::min(deepestVertex, (x.row(i).transpose() - c).norm() - r);
    }
    // The test means something: the tip really went below the rest surface between vertices.
    EXPECT_LT(end.z() - r, centroid.z() - 0.5 * depth);
    EXPECT_GT(deepestVertex, 0.0) << "a vertex touched the tip: not a between-vertices case";
    EXPECT_GE(worst, -1e-5) << "a surface point ended a step " << -worst << " m inside the tip";
    // The touched triangle was pushed down with the tip (its centroid is under the tip centre).
    const MatX3& x = model->surface();
    const Real zNow = (x(organ.surface.F(tri, 0), 2) + x(organ.surface.F(tri, 1), 2) +
                       x(organ.surface.F(tri, 2), 2)) /
                      3;
    EXPECT_LT(zNow, centroid.z() - 0.5 * depth) << "the tip did not push the triangle";
  }
  if (tested == 0) GTEST_SKIP() << "no model of this plugin has the contact capability";
}

/// Models whose projection response honours contact.friction.
bool frictionModel(const std::string& plugin) {
  for (const char* p : {"pbd", "massspring", "fem_hex"})
    if (plugin == p) return true;
  return false;
}

TEST_P(ThinProbeConformance, FrictionHoldsABoxOnAGentleSlopeThatItSlidesDownWithout) {
  if (!frictionModel(GetParam())) GTEST_SKIP() << "its contact response has no friction";
  // The slope: gravity tilted by 10 degrees towards +x (tan 10 deg = 0.18 < mu = 0.6).
  const SurfaceMesh s = makePhantom("cube", 0.5);
  const Box b = boundingBox(s.V);
  const Real g = 9.81, tilt = 10.0 * M_PI / 180.0;
  const Vec3 m = Vec3::Constant(0.05 * b.diagonal());
  const Real half = 0.15 * b.size().x();
  const Vec3 at(b.center().x(), b.center().y(), b.hi.z() + 0.1 * half);
  json j;
  j["organ"] = {{"mesh", "phantom:cube"},
                {"resolution", 0.5},
                {"material", {{"young", 20000}, {"poisson", 0.3}, {"density", 1000}}},
                {"fixed",
                 {{"box",
                   {{b.lo.x() - m.x(), b.lo.y() - m.y(), b.lo.z() - m.z()},
                    {b.hi.x() + m.x(), b.hi.y() + m.y(), b.lo.z() + 0.2 * b.size().z()}}}}}};
  j["gravity"] = {g * std::sin(tilt), 0, -g * std::cos(tilt)};
  // Stiffer than the probe cases, so that the organ's own shear under the tilted gravity (about
  // 0.7 mm at the top) stays well below the frictionless slide (about 12 mm).
  j["dt"] = 1e-3;
  j["duration"] = 0.12;
  j["objects"] = {{{"shape", "box"},
                   {"size", {2 * half, 2 * half, 0.2 * half}},
                   {"mass", 0.005},
                   {"pos", {at.x(), at.y(), at.z()}}}};
  j["models"] = json::array({{{"plugin", "any"}}});
  int tested = 0;
  for (const ModelInfo& info : thinProbeLoader().loadFile(thinProbeLoader().locate(GetParam()))) {
    SCOPED_TRACE(info.name);
    json k = j;
    k["contact"] = {{"thickness", 1e-4}, {"friction", 0.0}};
    const Scene frictionless = parseScene(k, "");
    k["contact"]["friction"] = 0.6;
    const Scene rough = parseScene(k, "");
    if (!unsupportedReason(info, rough).empty() || info.has(Capability::QuasiStatic)) continue;
    ++tested;
    const Organ organ = loadOrgan(rough);
    const ParamValues params = ParamValues::defaults(info.params);
    const RunRecord slide = runModel(info, params, frictionless, organ, thinProbeCache());
    const RunRecord stay = runModel(info, params, rough, organ, thinProbeCache());
    ASSERT_EQ(slide.status, RunStatus::Ok) << slide.message;
    ASSERT_EQ(stay.status, RunStatus::Ok) << stay.message;
    ASSERT_EQ(stay.objectsFinal.size(), 1u);
    const Real slid = slide.objectsFinal[0].x() - at.x(), held = stay.objectsFinal[0].x() - at.x();
    // Frictionless, it accelerates down the slope at about g sin(10 deg) = 1.7 m/s^2.
    EXPECT_GT(slid, 0.25 * 0.5 * g * std::sin(tilt) * 0.12 * 0.12) << "it did not slide";
    EXPECT_LT(held, 0.3 * slid) << "friction did not hold it: " << held << " vs " << slid;
    EXPECT_GT(stay.objectsFinal[0].z(), b.hi.z() - 0.5 * half) << "it sank";
  }
  if (tested == 0) GTEST_SKIP() << "no model of this plugin supports a resting object";
}

INSTANTIATE_TEST_SUITE_P(Plugins, ThinProbeConformance, ::testing::ValuesIn(plugins()),
                         [](const ::testing::TestParamInfo<std::string>& p) { return p.param; });
GTEST_ALLOW_UNINSTANTIATED_PARAMETERIZED_TEST(ThinProbeConformance);

}  // namespace
}  // namespace deform::harness
