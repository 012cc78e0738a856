// reference_fem honours roller supports (FixedRegion::rollers): a cube on frictionless faces
// (bottom on z-rollers, two side faces on symmetry rollers) under a uniform traction on its top
// (interaction.h regionPatch) is compressed homogeneously, as the closed-form Neo-Hookean
// answer says; the roller nodes keep their held coordinate and slide along the others, and
// none of the roller boxes is clipped away by conform_fixed (they hold nodes).
#include "../support/fixtures.h"

#include <deform/engine/interaction.h>
#include <deform/engine/plugin_loader.h>
#include <deform/engine/scene.h>
#include <deform/geometry/phantom.h>
#include <deform/sdk/cache.h>
#include <deform/sdk/model.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>

using namespace deform;

namespace {

using deform::testing::loader;

using deform::testing::cache;

TEST(ReferenceFemRollers, FrictionlessCubeCompressesHomogeneously) {
  Organ o;
  o.source = "phantom:cube";
  o.surface = makePhantom("cube", 0.3);
  o.material.young = 5500;
  o.material.poisson = 0.3;
  const Real a = 0.05, e = 1e-6, m = 0.06;
  o.fixed.rollers = {{Box{Vec3(-m, -m, -a - e), Vec3(m, m, -a + e)}, 4},
                     {Box{Vec3(-a - e, -m, -m), Vec3(-a + e, m, m)}, 1},
                     {Box{Vec3(-m, -a - e, -m), Vec3(m, -a + e, m)}, 2}};
  const ModelInfo& info = loader().load("reference_fem");
  ASSERT_TRUE(info.has(Capability::RollerSupport));
  ParamValues p = ParamValues::defaults(info.params);
  p.set("elements", (long long)300);
  std::unique_ptr<Model> model = info.create();
  model->init(ModelSetup{o, p, cache(), 1.0, Vec3::Zero()});
  const Counts counts = model->counts();
  ASSERT_TRUE(counts.count("roller_dofs"));
  EXPECT_GT(counts.at("roller_dofs"), 0);
  EXPECT_EQ(counts.at("fixed_nodes"), 0) << "rollers pin no node fully";
  const MatX3 rest = model->nodes();

  // 2.2 N down on the top face: 220 Pa nominal, 4% of E.
  const SurfacePatch top = regionPatch(o.surface, Box{Vec3(-m, -m, a - e), Vec3(m, m, a + e)});
  ASSERT_FALSE(top.vertices.empty());
  StepInput in;
  in.dt = 1.0;
  PointLoad load;
  load.surfaceVertex = top.vertices.front();
  load.force = Vec3(0, 0, -2.2);
  load.vertices = top.vertices;
  load.weights = top.weights;
  in.loads.push_back(load);
  ASSERT_EQ(model->step(in), StepStatus::Ok);
  const MatX3& x = model->nodes();

  // Closed form (lateral Cauchy stress zero, psi = mu/2 (J^-2/3 I1 - 3) + kappa/2 (J - 1)^2).
  const double mu = 5500 / 2.6, kappa = 5500 / (3 * 0.4), P = -2.2 / (4 * a * a);
  double lo = 0.5, hi = 1.0, b = 1;
  for (int it = 0; it < 100; ++it) {
    const double s = 0.5 * (lo + hi);
    double blo = 0.5, bhi = 2;
    for (int k = 0; k < 100; ++k) {
      const double bb = 0.5 * (blo + bhi), J = s * bb * bb, I1 = s * s + 2 * bb * bb;
      (mu * std::pow(J, -5.0 / 3) * (bb * bb - I1 / 3) + kappa * (J - 1) < 0 ? blo : bhi) = bb;
    }
    b = 0.5 * (blo + bhi);
    const double J = s * b * b, I1 = s * s + 2 * b * b;
    const double nominal =
        (mu * std::pow(J, -5.0 / 3) * (s * s - I1 / 3) + kappa * (J - 1)) * b * b;
    (nominal < P ? lo : hi) = s;
  }
  const double stretch = 0.5 * (lo + hi);

  double worstHeld = 0, slid = 0;
  for (Eigen::Index n = 0; n < rest.rows(); ++n) {
    const Vec3 r = rest.row(n).transpose(), u = x.row(n).transpose() - r;
    if (std::abs(r.z() + a) < e) {
      worstHeld = std::max(worstHeld, std::abs(u.z()));
      slid = std::max(slid, std::abs(u.x()));  // the bottom slides outward
    }
    if (std::abs(r.x() + a) < e) worstHeld = std::max(worstHeld, std::abs(u.x()));
    if (std::abs(r.y() + a) < e) worstHeld = std::max(worstHeld, std::abs(u.y()));
    // Homogeneous below the middle (the top's nodal forces dent it locally): every node at
    // (b x, b y, stretch z) measured from the held corner.
    if (r.z() > 0) continue;
    const Vec3 want((b - 1) * (r.x() + a), (b - 1) * (r.y() + a), (stretch - 1) * (r.z() + a));
    EXPECT_LT((u - want).norm(), 0.02 * (1 - stretch) * 2 * a)
        << "node " << n << " at " << r.transpose();
  }
  EXPECT_EQ(worstHeld, 0.0) << "a roller let its held axis move";
  EXPECT_NEAR(slid, (b - 1) * 2 * a, 0.02 * (b - 1) * 2 * a) << "the bottom did not slide";
}

// A bonded plate (scene "plates", handed over as a grasp by the interaction) pressing a cube
// with nu = 0 bonded to its base: every point moves down in proportion to its height (no lateral
// strain, so the bonded faces do not constrain anything) and the plate feels E A strain. Linear
// elasticity, linear tets: exact (but for the 1 um slab that conform_fixed clips off with the
// fixed box), at the interior markers too.
TEST(ReferenceFemPlates, BondedPlateOnANuZeroCubeIsUniaxialAtTheMarkers) {
  const Real a = 0.05, e = 1e-6, m = 0.06, E = 5500, press = 0.001;
  Organ o;
  o.source = "phantom:cube";
  o.surface = makePhantom("cube", 0.3);
  o.material.young = E;
  o.material.poisson = 0.0;
  o.fixed.boxes = {Box{Vec3(-m, -m, -m), Vec3(m, m, -a + e)}};
  Scene scene;
  scene.dt = 1.0;
  scene.duration = 1.0;
  scene.gravity = Vec3::Zero();
  PlateSpec plate;
  plate.region = Box{Vec3(-m, -m, a - e), Vec3(m, m, m)};
  plate.trajectory = {KeyFrame{0.0, Vec3::Zero(), false}, KeyFrame{1.0, Vec3(0, 0, -press), false}};
  scene.plates.push_back(plate);
  Interaction interaction(scene, o.surface);

  const ModelInfo& info = loader().load("reference_fem");
  ASSERT_TRUE(info.has(Capability::Markers));
  ParamValues p = ParamValues::defaults(info.params);
  p.set("elements", (long long)300);
  p.set("element_order", (long long)1);
  p.set("material", std::string("linear"));
  std::unique_ptr<Model> model = info.create();
  model->init(ModelSetup{o, p, cache(), 1.0, Vec3::Zero()});
  MatX3 markers(3, 3);
  markers << 0.01, -0.02, 0.0,  //
      -0.03, 0.025, 0.03,       //
      0.0, 0.0, -0.045;
  model->bindMarkers(markers);
  EXPECT_TRUE(model->markers().isApprox(markers, 1e-12)) << "at rest, the markers are the points";
  const StepInput in = interaction.prepare(0.0, 1.0, *model);
  ASSERT_EQ(in.grasps.size(), 1u);
  ASSERT_EQ(model->step(in), StepStatus::Ok);
  const MatX3 x = model->markers();
  for (Eigen::Index i = 0; i < markers.rows(); ++i) {
    const Vec3 want(0, 0, -press * (markers(i, 2) + a) / (2 * a));
    const Vec3 got = (x.row(i) - markers.row(i)).transpose();
    // 1e-4 of the travel: conform_fixed clips the 1 um slab of the fixed box off the cube.
    EXPECT_LT((got - want).norm(), 1e-4 * press) << "marker " << i << ": " << got.transpose();
  }
  const std::vector<Vec3> f = model->graspForces();
  ASSERT_EQ(f.size(), 1u);
  // The tissue pushes the plate up with E A strain = E (2a)^2 press / (2a).
  EXPECT_NEAR(f[0].z(), E * 2 * a * press, 1e-4 * E * 2 * a * press);
  EXPECT_LT(std::hypot(f[0].x(), f[0].y()), 1e-9);
}

}  // namespace
