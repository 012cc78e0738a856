// bullet_deformable: parameter mapping and model properties (rest, sag, stiffness, grasp, reset,
// no NaN).
#include "../support/plate.h"
#include "../support/press.h"
#include "bullet_deformable_model.h"
#include "test_support.h"

#include <deform/geometry/tet_mesher.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <numeric>

namespace deform::bullet_deformable {
namespace {

using deform::testing::bottomSlab;
using deform::testing::maxDisplacement;

constexpr Real kDt = 1e-3;

/// The liver phantom at resolution 0.12 tetrahedralised once (Gmsh runs in a child process),
/// coarse: Bullet's step costs ~17 us per tet here, and the properties below need no finer mesh.
const TetMesh& liverTets() {
  static const TetMesh mesh = [] {
    TetMeshOptions o;
    o.targetElements = 500;
    o.source = "phantom:liver";
    return tetrahedralize(makePhantom("liver", 0.12), o).mesh;
  }();
  return mesh;
}

std::vector<int> identitySurface() {
  std::vector<int> s(size_t(makePhantom("liver", 0.12).numVertices()));
  std::iota(s.begin(), s.end(), 0);
  return s;
}

Material material(Real young = 5500) {
  Material m;
  m.young = young;
  return m;
}

StepInput gravityInput() {
  return testing::gravityInput(kDt);
}

TEST(BulletDeformableKernels, LameParametersAndLumpedMass) {
  Material m;
  m.young = 5200;
  m.poisson = 0.3;
  const auto [mu, lambda] = lameParameters(m);
  EXPECT_NEAR(mu, 2000, 1e-9);
  EXPECT_NEAR(lambda, 3000, 1e-9);
  // Back to E and nu (Bullet's own conversion in btDeformableLinearElasticityForce).
  EXPECT_NEAR(mu * (3 * lambda + 2 * mu) / (lambda + mu), 5200, 1e-9);
  const TetMesh& t = liverTets();
  Real volume = 0;
  for (int e = 0; e < t.numTets(); ++e)
    volume +=
        tetVolume(t.V.row(t.T(e, 0)), t.V.row(t.T(e, 1)), t.V.row(t.T(e, 2)), t.V.row(t.T(e, 3)));
  EXPECT_NEAR(lumpedMasses(t, 1000).sum(), 1000 * volume, 1e-12);
}

class BulletDeformableForces : public ::testing::TestWithParam<ElasticForce> {
 protected:
  /// m on liverTets() with this test's elastic force, `fixed` pinned.
  void initModel(BulletDeformableModel& m, const std::vector<int>& fixed, Real young = 5500) {
    DeformableConfig c;
    c.force = GetParam();
    m.init(liverTets(), identitySurface(), material(young), c, kDt, fixed);
  }
};

TEST_P(BulletDeformableForces, RestStaysAtRestWithoutGravity) {
  // At rest F = Ds Dm^-1 = I up to rounding, so the elastic forces are rounding noise (~1e-16
  // relative) and the Krylov solve returns ~0. 60 steps must stay below 1e-9 m (measured and
  // printed below); a wrong Dm^-1, a wrong Lame mapping of the Neo-Hookean rest state
  // (P(I) != 0) or a mass/velocity mix-up moves the nodes by millimetres.
  const TetMesh& t = liverTets();
  BulletDeformableModel m;
  initModel(m, bottomSlab(t.V, 0.1));
  StepInput in;
  in.dt = kDt;
  for (int s = 0; s < 60; ++s) ASSERT_EQ(m.step(in), StepStatus::Ok);
  const Real drift = maxDisplacement(m.nodes(), t.V);
  std::printf("bullet_deformable rest drift after 60 steps: %.3g m\n", drift);
  EXPECT_LT(drift, 1e-9);
}

TEST_P(BulletDeformableForces, GravitySagsAFixedOrganAndFixedNodesStay) {
  const TetMesh& t = liverTets();
  const std::vector<int> fixed = bottomSlab(t.V, 0.15);
  BulletDeformableModel m;
  initModel(m, fixed);
  const StepInput in = gravityInput();
  for (int s = 0; s < 100; ++s) ASSERT_EQ(m.step(in), StepStatus::Ok);
  const VecX dz = m.surface().col(2) - t.V.topRows(m.surface().rows()).col(2);
  std::printf("bullet_deformable mean surface sag after 0.1 s: %.3g m\n", dz.mean());
  EXPECT_LT(dz.mean(), -1e-4);
  for (int i : fixed) EXPECT_EQ(m.nodes().row(i), t.V.row(i)) << i;
}

TEST_P(BulletDeformableForces, StifferMaterialSagsLess) {
  const TetMesh& t = liverTets();
  Real sag[2];
  for (int k = 0; k < 2; ++k) {
    BulletDeformableModel m;
    initModel(m, bottomSlab(t.V, 0.15), k == 0 ? 3000 : 30000);
    const StepInput in = gravityInput();
    for (int s = 0; s < 80; ++s) ASSERT_EQ(m.step(in), StepStatus::Ok);
    sag[k] = -(m.nodes().col(2) - t.V.col(2)).mean();
  }
  std::printf("bullet_deformable mean sag E=3 kPa: %.3g m, E=30 kPa: %.3g m\n", sag[0], sag[1]);
  EXPECT_GT(sag[1], 0.0);
  EXPECT_LT(sag[1], 0.5 * sag[0]);
}

TEST_P(BulletDeformableForces, GraspedNodesFollowTheirTargets) {
  const TetMesh& t = liverTets();
  BulletDeformableModel m;
  initModel(m, bottomSlab(t.V, 0.15));
  // Released: the node is dynamic again and no longer held at the target.
  testing::expectGraspFollowedThenReleased(m, t.V, kDt, &Model::nodes, 40);
}

TEST_P(BulletDeformableForces, PointForceMovesTheLoadedVertexAlongTheForce) {
  const TetMesh& t = liverTets();
  BulletDeformableModel m;
  initModel(m, bottomSlab(t.V, 0.15));
  testing::expectPointForceLiftsItsVertex(m, boundingBox(t.V), makePhantom("liver", 0.12).V, t.V,
                                          kDt);
}

TEST_P(BulletDeformableForces, ResetReproducesARunBitForBit) {
  const TetMesh& t = liverTets();
  BulletDeformableModel m;
  initModel(m, bottomSlab(t.V, 0.15));
  testing::expectResetReproducesARun(m, t.V, 40, 30, kDt, &Model::nodes);
}

TEST_P(BulletDeformableForces, NoNanOverAGraspLift) {
  const TetMesh& t = liverTets();
  BulletDeformableModel m;
  initModel(m, bottomSlab(t.V, 0.15));
  testing::expectNoNanOverAGraspLift(m, t.V, 100, 2e-4, kDt, &Model::nodes);  // 2 cm in 0.1 s
}

TEST_P(BulletDeformableForces, APressedProbeKeepsNodesOutPushesTheBodyAndFeelsTheTissue) {
  // As for bullet_softbody: no movable node ends a step inside the probe, the correction reaches
  // Bullet's body (nodes the probe never came near follow), the tissue pushes the probe up.
  const TetMesh& t = liverTets();
  const std::vector<int> fixed = bottomSlab(t.V, 0.15);
  BulletDeformableModel m;
  initModel(m, fixed);
  // Held 8 mm deep, the tissue pushes back with a finite force (not only round-off).
  testing::expectAPressedProbeIsPushedBack(m, t.V, fixed, kDt, 1e-3, "bullet_deformable");
}

INSTANTIATE_TEST_SUITE_P(Forces, BulletDeformableForces,
                         ::testing::Values(ElasticForce::NeoHookean,
                                           ElasticForce::LinearElasticity),
                         [](const ::testing::TestParamInfo<ElasticForce>& p) {
                           return p.param == ElasticForce::NeoHookean ? "NeoHookean"
                                                                      : "LinearElasticity";
                         });

/// The plate tests' cube tetrahedralised coarsely (500 target tets), its surface vertices the
/// first nodes.
TetMesh coarseCube(const testing::CubePress& press) {
  TetMeshOptions o;
  o.targetElements = 500;
  o.source = "phantom:cube";
  return tetrahedralize(press.organ.surface, o).mesh;
}

/// Surface vertex i is node i, for the first n.
std::vector<int> firstNodes(int n) {
  std::vector<int> surface(size_t(n), 0);
  std::iota(surface.begin(), surface.end(), 0);
  return surface;
}

// A sliding plate (GraspInput::slideNormal): the held nodes keep their mass, their position and
// velocity along the normal are set before and after Bullet's implicit step
// (bullet_peer_step.h); against a bonded plate the top spreads out and the plate needs less
// force (tests/support/plate.h). The cube tetrahedralised coarsely, its surface vertices the first
// nodes, its bottom face pinned.
TEST(BulletDeformableModel, ASlidingPlateSpreadsTheTopWhereABondedOneHoldsIt) {
  const testing::CubePress press = testing::cubePress(0.5);
  const TetMesh mesh = coarseCube(press);
  const std::vector<int> surface = firstNodes(press.organ.surface.numVertices());
  BulletDeformableModel m;
  m.init(mesh, surface, press.organ.material, DeformableConfig{}, kDt, bottomSlab(mesh.V, 1e-6));
  testing::expectSlidingSpreadsTheTopAndEasesThePlate(m, press.organ, 0.002, 100, 100,
                                                      "bullet_deformable");
}

// The plate's force (graspForces: bonded, the elastic and damping forces of Bullet's force object
// on the held nodes; sliding, the normal momentum the plate takes back from its nodes per step)
// on the same cube pressed 2 mm: reference_fem's on this cube is 1.20 N bonded, 1.16 N sliding;
// measured 1.21 / 1.04 N (Neo-Hookean), 1.19 / 1.05 N (linear). Asserted within a factor 2.
TEST(BulletDeformableModel, APlatesForceIsWhatTheTissueTransmitsToTheHeldNodes) {
  const testing::CubePress press = testing::cubePress(0.5);
  const TetMesh mesh = coarseCube(press);
  const std::vector<int> surface = firstNodes(press.organ.surface.numVertices());
  for (ElasticForce force : {ElasticForce::NeoHookean, ElasticForce::LinearElasticity}) {
    DeformableConfig c;
    c.force = force;
    BulletDeformableModel m;
    m.init(mesh, surface, press.organ.material, c, kDt, bottomSlab(mesh.V, 1e-6));
    EXPECT_TRUE(m.graspForces().empty());
    testing::expectPlateForcesNear(m, press.organ, 0.002, 100, 100, 1.20, 2.0,
                                   force == ElasticForce::NeoHookean
                                       ? "bullet_deformable neo_hookean"
                                       : "bullet_deformable linear_elasticity");
  }
}

// Interior markers (capability "markers") ride in Bullet's rest tets by their barycentric
// coordinates: at rest they are the points; with the bottom fixed and a bonded plate pressing the
// top 2 mm, the centre and a point off the axis at mid-height drop about half the travel.
TEST(BulletDeformableModel, MarkersAtMidHeightDropHalfThePlatesTravel) {
  const testing::CubePress press = testing::cubePress(0.5);
  const TetMesh mesh = coarseCube(press);
  BulletDeformableModel m;
  m.init(mesh, firstNodes(press.organ.surface.numVertices()), press.organ.material,
         DeformableConfig{}, kDt, bottomSlab(mesh.V, 1e-6));
  MatX3 markers(2, 3);
  markers << 0, 0, 0, 0.02, -0.02, 0.0;
  m.bindMarkers(markers);
  EXPECT_LT((m.markers() - markers).cwiseAbs().maxCoeff(), 1e-12);
  const Real travel = 0.002;
  ASSERT_TRUE(testing::pressByPlate(m, press.organ, false, travel, 100, 100).ok);
  const MatX3 moved = m.markers();
  for (Eigen::Index k = 0; k < 2; ++k)
    EXPECT_NEAR(markers(k, 2) - moved(k, 2), 0.5 * travel, 0.1 * travel) << "marker " << k;
}

TEST(BulletDeformableModel, TheRestFactorGivesBulletsStepInAFractionOfTheIterations) {
  // Nearly incompressible (nu 0.49), where Bullet's unpreconditioned CG needs hundreds of
  // iterations: a grasp lifts 6 top nodes for 40 steps and lets go for 20 (the held set changes
  // twice). Both preconditioners solve the same linear steps to Bullet's relative tolerance, so
  // the nodes agree to 0.1% of the motion (measured 1.2 um of 8 mm, the unpreconditioned
  // solves' own residual); the factor of the step's matrix at rest needs a tenth of the
  // iterations or fewer (measured 157 against 8,846). Every solve is counted, none at the cap.
  const TetMesh& t = liverTets();
  const auto run = [&](CgPreconditioning p) {
    DeformableConfig c;
    c.preconditioner = p;
    Material mat = material();
    mat.poisson = 0.49;
    BulletDeformableModel m;
    m.init(t, identitySurface(), mat, c, kDt, bottomSlab(t.V, 0.15));
    StepInput in = gravityInput();
    in.grasps.push_back(testing::topGrasp(t.V, 6, 0.0));
    for (int s = 0; s < 60; ++s) {
      if (s == 40) in.grasps.clear();
      if (!in.grasps.empty()) in.grasps[0].targets.col(2).array() += 2e-4;
      EXPECT_EQ(m.step(in), StepStatus::Ok);
    }
    return std::make_pair(MatX3(m.nodes()), m.numericCounters());
  };
  const auto [plain, plainCounts] = run(CgPreconditioning::None);
  const auto [factored, factoredCounts] = run(CgPreconditioning::RestFactor);
  std::printf(
      "bullet_deformable CG iterations over 60 steps: none %lld, rest_factor %lld; "
      "largest node difference %.3g m\n",
      plainCounts.at("cg_iterations"), factoredCounts.at("cg_iterations"),
      maxDisplacement(plain, factored));
  EXPECT_GT(maxDisplacement(plain, t.V), 1e-3);
  EXPECT_LT(maxDisplacement(plain, factored), 1e-3 * maxDisplacement(plain, t.V));
  EXPECT_EQ(plainCounts.at("cg_solves"), 60);
  EXPECT_EQ(factoredCounts.at("cg_solves"), 60);
  EXPECT_EQ(factoredCounts.at("cg_capped_solves"), 0);
  EXPECT_EQ(factoredCounts.at("unconverged_steps"), 0);
  EXPECT_LT(10 * factoredCounts.at("cg_iterations"), plainCounts.at("cg_iterations"));
}

TEST(BulletDeformableModel, ASolveThatReachesTheCapIsAnUnconvergedStep) {
  // Two CG iterations cannot solve a gravity step on this mesh: each of the 10 steps reaches the
  // cap, and the model says so (the harness then marks the run invalid).
  const TetMesh& t = liverTets();
  DeformableConfig c;
  c.preconditioner = CgPreconditioning::None;
  c.krylovIterations = 2;
  BulletDeformableModel m;
  m.init(t, identitySurface(), material(), c, kDt, bottomSlab(t.V, 0.15));
  for (int s = 0; s < 10; ++s) ASSERT_EQ(m.step(gravityInput()), StepStatus::Ok);
  const NumericCounters n = m.numericCounters();
  EXPECT_EQ(n.at("cg_solves"), 10);
  EXPECT_EQ(n.at("cg_iterations"), 20);
  EXPECT_EQ(n.at("cg_capped_solves"), 10);
  EXPECT_EQ(n.at("unconverged_steps"), 10);
}

}  // namespace
}  // namespace deform::bullet_deformable
