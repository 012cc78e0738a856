// Model-level tests of PbdModel: rest stays rest, reset() reproduces a run bit for bit, grasped
// nodes follow their targets exactly, gravity sags a pinned organ (less when stiffer), the grasp
// reaction balances the weight of a hanging organ, tet input, and the parameter layer.
#include "pbd_model.h"
#include "../support/grasp.h"
#include "../support/meshes.h"
#include "../support/network_model.h"
#include "../support/plate.h"
#include "../support/press.h"

#include <gtest/gtest.h>

#include <cstdio>

namespace deform::pbd {
namespace {

using testing::ellipsoidOrgan;
using testing::maxDistance;
using testing::stepInput;
using testing::tetBoxOrgan;

TEST(PbdModel, CountsOfAClosedSurface) {
  const Organ o = ellipsoidOrgan();
  PbdModel m;
  PbdConfig cfg;
  cfg.bending = true;
  m.init(o, cfg);
  const Counts c = m.counts();
  const long long E = uniqueEdges(o.surface.F).rows();
  EXPECT_EQ(c.at("nodes"), o.surface.numVertices());
  EXPECT_EQ(c.at("elements"), o.surface.numFaces());
  EXPECT_EQ(c.at("distance_constraints"), E);
  EXPECT_EQ(c.at("bending_constraints"), E);  // closed: every edge is interior
  EXPECT_EQ(c.at("volume_constraints"), 1);
  EXPECT_EQ(c.at("constraints"), 2 * E + 1);
  // Mass = density * enclosed volume.
  EXPECT_NEAR(m.masses().sum(), 1000.0 * signedVolume(o.surface.V, o.surface.F), 1e-12);
}

TEST(PbdModel, RestWithoutGravityStaysAtRest) {
  for (StiffnessMode mode : {StiffnessMode::Xpbd, StiffnessMode::Classic}) {
    PbdModel m;
    PbdConfig cfg;
    cfg.mode = mode;
    const Organ o = ellipsoidOrgan();
    m.init(o, cfg);
    for (int s = 0; s < 100; ++s) ASSERT_EQ(m.step(stepInput(1e-3)), StepStatus::Ok);
    EXPECT_LT(maxDistance(m.surface(), o.surface.V), 1e-12);
  }
  PbdModel t;
  const Organ o = tetBoxOrgan();
  t.init(o, PbdConfig{});
  for (int s = 0; s < 100; ++s) ASSERT_EQ(t.step(stepInput(1e-3)), StepStatus::Ok);
  EXPECT_LT(maxDistance(t.nodes(), o.volume->V), 1e-12);
}

// A scripted run with gravity, a pinned box, a moving grasp and a point load.
std::vector<MatX3> scriptedRun(PbdModel& m, const Organ& o, int steps) {
  return testing::scriptedRun(m, o, steps, 1e-3, 1e-4);
}

TEST(PbdModel, ResetReproducesARunBitForBit) {
  Organ o = ellipsoidOrgan();
  o.fixed.boxes.push_back({Vec3(-1, -1, -1), Vec3(1, 1, -0.025)});
  PbdModel m;
  m.init(o, PbdConfig{});
  const std::vector<MatX3> a = scriptedRun(m, o, 60);
  m.reset();
  EXPECT_TRUE(m.surface() == o.surface.V);
  const std::vector<MatX3> b = scriptedRun(m, o, 60);
  for (size_t s = 0; s < a.size(); ++s) ASSERT_TRUE(a[s] == b[s]) << "step " << s;
  EXPECT_GT(maxDistance(a.back(), o.surface.V), 1e-4);  // the run did move the organ
}

TEST(PbdModel, GraspedNodeFollowsItsTargetExactly) {
  for (StiffnessMode mode : {StiffnessMode::Xpbd, StiffnessMode::Classic}) {
    const Organ o = ellipsoidOrgan();
    PbdModel m;
    PbdConfig cfg;
    cfg.mode = mode;
    m.init(o, cfg);
    const std::vector<int> nodes = {nearestVertex(o.surface.V, Vec3(0, 0, 0.03)),
                                    nearestVertex(o.surface.V, Vec3(0.01, 0, 0.03))};
    testing::expectGraspedNodesFollow(m, o, nodes, 40, 1e-3, 2e-4, 5e-4);
  }
}

// Mean z displacement of the free nodes after settling under gravity with the bottom pinned.
Real sagUnderGravity(Real young) {
  Organ o = ellipsoidOrgan(young);
  o.fixed.boxes.push_back({Vec3(-1, -1, -1), Vec3(1, 1, -0.025)});
  PbdModel m;
  PbdConfig cfg;
  cfg.damping = 20.0;
  m.init(o, cfg);
  for (int s = 0; s < 400; ++s)
    EXPECT_EQ(m.step(stepInput(1e-3, Vec3(0, 0, -9.81))), StepStatus::Ok);
  return (m.surface().col(2) - o.surface.V.col(2)).mean();
}

TEST(PbdModel, GravitySagsAPinnedOrganLessWhenStiffer) {
  const Real soft = sagUnderGravity(2e3), stiff = sagUnderGravity(2e4);
  EXPECT_LT(soft, 0.0);
  EXPECT_LT(stiff, 0.0);
  EXPECT_LT(std::abs(stiff), 0.5 * std::abs(soft));
}

// An organ hanging from a grasp: once still, the tissue pulls the grasp down with the weight of
// every node the grasp does not hold (momentum balance of the free nodes).
TEST(PbdModel, GraspReactionBalancesTheHangingWeight) {
  const Organ o = ellipsoidOrgan(2e4);
  PbdModel m;
  PbdConfig cfg;
  cfg.damping = 30.0;
  m.init(o, cfg);
  testing::expectGraspReactionBalancesTheWeight(m, o, 3000, 1e-3, 0.05);
}

TEST(PbdModel, TetInputSagsAndKeepsVolume) {
  Organ o = tetBoxOrgan();
  o.fixed.boxes.push_back({Vec3(-1, -1, -1), Vec3(0.001, 1, 1)});  // the x = 0 face
  PbdModel m;
  PbdConfig cfg;
  cfg.damping = 20.0;
  m.init(o, cfg);
  const Counts c = m.counts();
  EXPECT_EQ(c.at("nodes"), o.volume->numVertices());
  EXPECT_EQ(c.at("elements"), o.volume->numTets());
  EXPECT_EQ(c.at("volume_constraints"), o.volume->numTets());
  for (int s = 0; s < 300; ++s)
    ASSERT_EQ(m.step(stepInput(1e-3, Vec3(0, 0, -9.81))), StepStatus::Ok);
  // The free end of the cantilever drops; the pinned face stays.
  const int tip = nearestVertex(o.volume->V, Vec3(0.04, 0.015, 0.02));
  EXPECT_LT(m.nodes()(tip, 2) - o.volume->V(tip, 2), -1e-4);
  EXPECT_EQ(m.nodes().row(0), o.volume->V.row(0));
  const SurfaceMesh b = tetBoundary(*o.volume);
  EXPECT_NEAR(signedVolume(m.nodes(), b.F), signedVolume(o.volume->V, b.F),
              0.02 * signedVolume(o.volume->V, b.F));
  EXPECT_EQ(m.surface().rows(), o.surface.numVertices());
}

TEST(PbdModel, DivergenceIsReportedNotThrown) {
  const Organ o = ellipsoidOrgan();
  PbdModel m;
  m.init(o, PbdConfig{});
  StepInput in = stepInput(1e-3);
  in.loads.push_back(PointLoad::onVertex(0, Vec3(std::numeric_limits<Real>::quiet_NaN(), 0, 0)));
  EXPECT_EQ(m.step(in), StepStatus::Diverged);
}

TEST(PbdModel, ParametersAreReadAndBadChoicesRejected) {
  std::vector<ParamSpec> specs = paramSpecs();
  ParamValues p = ParamValues::defaults(specs);
  for (const ParamSpec& s : specs) EXPECT_TRUE(p.has(s.key)) << s.key;
  p.set("iterations", 7LL);
  p.set("stiffness_mode", std::string("classic"));
  p.set("bending", false);
  const PbdConfig c = configFromParams(p);
  EXPECT_EQ(c.iterations, 7);
  EXPECT_EQ(c.mode, StiffnessMode::Classic);
  EXPECT_FALSE(c.bending);

  const Organ o = ellipsoidOrgan();
  Cache cache{std::filesystem::path()};
  PbdModel m;
  m.init(ModelSetup{o, p, cache, 1e-3, Vec3::Zero()});
  EXPECT_EQ(m.counts().at("bending_constraints"), 0);

  p.set("stiffness_mode", std::string("stiff"));
  EXPECT_THROW(configFromParams(p), InputError);
  p.set("stiffness_mode", std::string("xpbd"));
  EXPECT_EQ(configFromParams(p).precision, Precision::Float32);  // the default
  p.set("precision", std::string("float64"));
  EXPECT_EQ(configFromParams(p).precision, Precision::Float64);
  p.set("precision", std::string("float16"));
  EXPECT_THROW(configFromParams(p), InputError);
}

// The single-precision solver follows the double one on a well-conditioned run (with bending:
// without it the membrane amplifies perturbations of 1e-9 m by ~1e6, see
// docs/notes/pbd-history.md, "Precision"): the float corrections carry ~2^-24 relative rounding per
// projection, so the two trajectories stay within 1e-3 of the displacement. Both paths are
// deterministic.
TEST(PbdModel, Float32TracksFloat64) {
  Organ o = ellipsoidOrgan();
  o.fixed.boxes.push_back({Vec3(-1, -1, -1), Vec3(1, 1, -0.025)});
  PbdConfig c32;
  c32.bending = true;
  PbdConfig c64 = c32;
  c64.precision = Precision::Float64;
  PbdModel a, b;
  a.init(o, c32);
  b.init(o, c64);
  const std::vector<MatX3> xa = scriptedRun(a, o, 100);
  const std::vector<MatX3> xb = scriptedRun(b, o, 100);
  Real diff = 0, disp = 0;
  for (size_t s = 0; s < xa.size(); ++s) {
    diff = std::max(diff, maxDistance(xa[s], xb[s]));
    disp = std::max(disp, maxDistance(xb[s], o.surface.V));
  }
  EXPECT_GT(disp, 1e-3);
  EXPECT_GT(diff, 0.0);  // the paths do differ (the float path was taken)
  EXPECT_LT(diff, 1e-3 * disp);
}

TEST(PbdModel, BadMaterialIsAnInputError) {
  Organ o = ellipsoidOrgan();
  o.material.young = -1;
  PbdModel m;
  EXPECT_THROW(m.init(o, PbdConfig{}), InputError);
}

/// network = volume at about 500 tets, damped at 20 / s: the pressed-cube tests' parameters.
ParamValues volumeNetworkParams() {
  ParamValues p = ParamValues::defaults(paramSpecs());
  p.set("network", std::string("volume"));
  p.set("volume_elements", 500LL);
  p.set("damping", 20.0);
  return p;
}

// network = volume: the surface tetrahedralised (its vertices kept as the first nodes), tet edges
// and volumes with compliances from E and nu; pressed, the cube drops as a solid does.
TEST(PbdModel, VolumeNetworkIsPressedLikeASolid) {
  const testing::CubePress press = testing::cubePress(0.5);
  const ParamValues p = volumeNetworkParams();
  PbdModel m;
  testing::initWithParams(m, press.organ, p);
  const Counts c = m.counts();
  EXPECT_GT(c.at("nodes"), press.organ.surface.numVertices());
  EXPECT_GT(c.at("elements"), 100);
  EXPECT_EQ(c.at("volume_constraints"), c.at("elements"));
  EXPECT_EQ(c.at("bending_constraints"), 0);
  testing::expectPressedLikeASolidWithMarkers(m, press, "volume PBD");
}

// A sliding plate (GraspInput::slideNormal): the held particles stay free along the plate and
// are projected onto its plane; against a bonded plate the top spreads out and the plate's force
// is lower (tests/support/plate.h).
TEST(PbdModel, ASlidingPlateSpreadsTheTopWhereABondedOneHoldsIt) {
  const testing::CubePress press = testing::cubePress(0.5);
  const ParamValues p = volumeNetworkParams();
  PbdModel m;
  testing::initWithParams(m, press.organ, p);
  testing::expectSlidingSpreadsTheTopAndEasesThePlate(m, press.organ, 0.002, 200, 400,
                                                      "volume PBD");
}

TEST(PbdModel, ASurfaceNetworkHasNoInteriorForMarkers) {
  PbdModel m;
  testing::expectNoMarkersAtDefaults(m, paramSpecs());
}

}  // namespace
}  // namespace deform::pbd
