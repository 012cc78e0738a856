// The metaballs model: rest, grasp, reset, divergence, and the paper's experiments as measured
// differences (Fig. 12: shape recovery with vs without the Laplacian constraint; Fig. 13: local
// volume preservation by eq. 12).
#include "../support/grasp.h"
#include "../support/plate.h"
#include "../support/press.h"
#include "metaballs_model.h"
#include "test_meshes.h"

#include <deform/engine/interaction.h>
#include <deform/geometry/phantom.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>

namespace deform {

namespace metaballs {
namespace {

struct Rig {
  Organ organ;
  ParamValues params;
  Cache cache{std::filesystem::path()};
  MetaballsModel model;
  Rig(const SurfaceMesh& surface, std::map<std::string, ParamValue> overrides,
      const std::vector<Box>& fixed = {}) {
    organ.source = "test";
    organ.surface = surface;
    organ.fixed.boxes = fixed;
    params = ParamValues::defaults(metaballsParams());
    params.set("spheres", (long long)150);
    params.set("voxel_resolution", (long long)32);
    for (auto& [k, v] : overrides) params.set(k, v);
    model.init(ModelSetup{organ, params, cache, 1e-3, Vec3::Zero()});
  }
};

Real rmsToRest(const MatX3& a, const MatX3& b) {
  return std::sqrt((a - b).rowwise().squaredNorm().mean());
}

// A sliding plate (GraspInput::slideNormal): the spheres carrying the top stay free, their
// vertical coordinate held on the plate (one shift of them all, fitted through the skinning). The
// 10 cm cube, its bottom face fixed, pressed 2 mm in 0.1 s and held 0.1 s: against a bonded plate
// the top spreads out (0.43 mm at 150 spheres; 0.12 and 0.06 mm at 250 and 900) and a load along
// the plate slides it (tests/support/plate.h); on the plate either way within the skinning's
// residual (the sliding top 1.943 mm down, the bonded one 1.987 mm).
// The plates' forces (graspForces: the constraints' accumulated multipliers on the carrying
// spheres, g lambda / dt^2): bonded 1.28 N, sliding 1.76 N, reference_fem 1.20 / 1.16 N; both
// asserted within a factor 2 of it, positive, the sliding one without a tangential part. Unlike a
// continuum, this model needs more force under the sliding plate (settled after 0.6 s: 1.80 N
// against 1.31 N bonded, the fixed spheres' reaction computed the same way equal to either
// within 0.1%): the plate's spheres keep the radii and rotations of the closing while the tissue
// under them spreads, which stiffens the top layer. Not asserted (the continuum's order is).
TEST(MetaballsModel, ASlidingPlateSpreadsTheTopWhereABondedOneHoldsIt) {
  const testing::CubePress press = testing::cubePress(0.5);
  Rig rig(press.organ.surface, {}, press.organ.fixed.boxes);
  EXPECT_TRUE(rig.model.graspForces().empty());
  const Real travel = 0.002;
  const testing::PlateRun sliding =
      testing::pressByPlate(rig.model, rig.organ, true, travel, 100, 100);
  const testing::PlateRun bonded =
      testing::pressByPlate(rig.model, rig.organ, false, travel, 100, 100);
  std::printf(
      "metaballs: drop %.4f / %.4f mm, outward %.4f / %.4f mm, force %.4g / %.4g N, sliding "
      "tangential %.3g N (sliding / bonded)\n",
      1e3 * sliding.drop, 1e3 * bonded.drop, 1e3 * sliding.outward, 1e3 * bonded.outward,
      sliding.force, bonded.force, sliding.forceVector.head<2>().norm());
  ASSERT_TRUE(sliding.ok && bonded.ok);
  EXPECT_NEAR(sliding.drop, travel, 0.05 * travel);
  EXPECT_NEAR(bonded.drop, travel, 0.05 * travel);
  EXPECT_GT(sliding.outward, 0.1 * press.organ.material.poisson * travel / 2);
  EXPECT_GT(sliding.outward, 10 * std::abs(bonded.outward));
  EXPECT_GT(bonded.force, 1.20 / 2);
  EXPECT_LT(bonded.force, 1.20 * 2);
  EXPECT_GT(sliding.force, 1.16 / 2);
  EXPECT_LT(sliding.force, 1.16 * 2);
  EXPECT_LE(sliding.forceVector.head<2>().norm(), 1e-9 * sliding.force);
  testing::expectSlidingLetsTheTopSlide(rig.model, rig.organ, 0.01, 100, 1e-4, 1e-4, "metaballs");
}

TEST(MetaballsModel, RestStaysAtRestAndSkinningReproducesSurface) {
  const SurfaceMesh s = test::banana(0.16, 0.035, 0.08, 4);
  Rig rig(s, {});
  EXPECT_TRUE(rig.model.surface() == s.V);
  StepInput in;
  in.dt = 1e-3;
  for (int i = 0; i < 50; ++i) ASSERT_EQ(rig.model.step(in), StepStatus::Ok);
  // At rest the skinned surface is the input surface to round-off.
  EXPECT_LE((rig.model.surface() - s.V).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_LE((rig.model.nodes() - rig.model.metaballs().spheres.centers).cwiseAbs().maxCoeff(),
            1e-12);
  const Counts c = rig.model.counts();
  EXPECT_EQ(c.at("nodes"), c.at("spheres"));
  EXPECT_EQ(c.at("constraints"), c.at("links") + c.at("spheres"));
  EXPECT_GT(c.at("links"), 0);
  for (const char* k : {"pbd", "laplacian", "volume", "skinning"})
    EXPECT_TRUE(rig.model.phaseTimes().count(k)) << k;
  EXPECT_EQ(rig.model.numericCounters().at("spheres_outside_after_adjustment"), 0);
}

// A fixed slab along the bottom surface, too thin to contain a sphere centre (the stability
// sweep's cube with its bottom tenth fixed): the spheres carrying the fixed surface are fixed, so
// under gravity the cube sags instead of falling (it fell 0.7 m in 0.38 s and diverged).
TEST(MetaballsModel, AThinFixedSlabHoldsTheSpheresCarryingItsSurface) {
  const SurfaceMesh cube = makePhantom("cube", 0.5);
  const Box b = boundingBox(cube.V);
  const Vec3 m = Vec3::Constant(0.05 * b.diagonal());
  const Box slab{b.lo - m, Vec3(b.hi.x() + m.x(), b.hi.y() + m.y(), b.lo.z() + 0.01)};
  Rig rig(cube, {}, {slab});
  const Counts c = rig.model.counts();
  ASSERT_GT(c.at("fixed_spheres"), 0);
  int centresInSlab = 0;
  for (Eigen::Index i = 0; i < rig.model.nodes().rows(); ++i)
    centresInSlab += slab.contains(rig.model.nodes().row(i).transpose());
  EXPECT_LT(centresInSlab, c.at("fixed_spheres")) << "the slab alone holds fewer spheres";
  StepInput in;
  in.dt = 1e-3;
  in.gravity = Vec3(0, 0, -9.81);
  for (int s = 0; s < 400; ++s) ASSERT_EQ(rig.model.step(in), StepStatus::Ok) << "step " << s;
  const VecX dz = rig.model.surface().col(2) - cube.V.col(2);
  std::printf("metaballs on a 1 cm fixed slab: mean sag %.3g m, lowest %.3g m after 0.4 s\n",
              -dz.mean(), -dz.minCoeff());
  Real slabSag = 0;
  const std::vector<int> inSlab = fixedNodeIndices(cube.V, rig.organ.fixed, cube);
  for (int v : inSlab) slabSag -= dz(v) / Real(inSlab.size());
  std::printf("metaballs on a 1 cm fixed slab: mean sag of the slab's %zu vertices %.3g m\n",
              inSlab.size(), slabSag);
  // Free fall would be 0.5 g t^2 = 0.78 m. Metaballs at E = 5.5 kPa is soft (G2 calibrates it), so
  // the free part sags by centimetres; the fixed surface stays within a centimetre.
  EXPECT_GT(-dz.mean(), 0.0);
  EXPECT_LT(-dz.mean(), 0.1) << "the cube fell";
  EXPECT_LT(std::abs(slabSag), 0.01);
}

TEST(MetaballsModel, GraspedVertexFollowsTargetAndResetReproduces) {
  const SurfaceMesh s = test::banana(0.16, 0.035, 0.08, 4);
  Rig rig(s, {});
  const MatX3 x0 = rig.model.nodes();
  Eigen::Index g = 0;
  s.V.col(0).maxCoeff(&g);
  auto run = [&]() {
    MatX3 last;
    StepInput in;
    in.dt = 1e-3;
    in.gravity = Vec3(0, 0, -9.81);
    GraspInput grasp;
    grasp.vertices = {int(g)};
    for (int i = 0; i < 100; ++i) {
      grasp.targets = s.V.row(g);
      grasp.targets(0, 2) += 0.0002 * (i + 1);
      in.grasps = {grasp};
      EXPECT_EQ(rig.model.step(in), StepStatus::Ok);
      // The grasped surface vertex, carried by its skinning spheres, is on its target.
      EXPECT_LE((rig.model.surface().row(g) - grasp.targets.row(0)).norm(), 1e-6);
    }
    return MatX3(rig.model.surface());
  };
  const MatX3 first = run();
  EXPECT_GT((first - s.V).rowwise().norm().maxCoeff(), 0.005);  // the organ moved
  rig.model.reset();
  EXPECT_TRUE(rig.model.nodes() == x0);
  const MatX3 second = run();
  EXPECT_TRUE(first == second);  // bit for bit
}

// Markers through the spheres' skinning, as the surface: at rest they are the points; a marker on
// a surface vertex's spot follows that vertex, and after a reset the markers are back at rest.
TEST(MetaballsModel, MarkersAreSkinnedAsTheSurface) {
  const SurfaceMesh s = test::banana(0.16, 0.035, 0.08, 4);
  Rig rig(s, {});
  Eigen::Index g = 0;
  s.V.col(0).maxCoeff(&g);
  MatX3 pts(2, 3);
  pts.row(0) = s.V.row(g);                             // on the grasped vertex
  pts.row(1) = boundingBox(s.V).center().transpose();  // inside
  rig.model.bindMarkers(pts);
  EXPECT_LE((rig.model.markers() - pts).cwiseAbs().maxCoeff(), 1e-12);
  StepInput in;
  in.dt = 1e-3;
  GraspInput grasp;
  grasp.vertices = {int(g)};
  grasp.targets = s.V.row(g);
  grasp.targets(0, 2) += 0.01;
  in.grasps = {grasp};
  for (int i = 0; i < 50; ++i) ASSERT_EQ(rig.model.step(in), StepStatus::Ok);
  const MatX3 moved = rig.model.markers();
  EXPECT_LE((moved.row(0) - rig.model.surface().row(g)).norm(), 1e-9);
  EXPECT_GT(moved(0, 2) - pts(0, 2), 0.005);
  rig.model.reset();
  EXPECT_LE((rig.model.markers() - pts).cwiseAbs().maxCoeff(), 1e-12);
}

// A grasper smaller than the spheres (4 mm jaws on the liver) holds the surface vertices it
// closes on: before the skinning mapping it attached the sphere centres within its radius, and
// there were none. Grasp and lift 2 cm with gravity: the grasped vertices stay on their targets.
TEST(MetaballsModel, SmallGrasperHoldsTheSurfaceItClosesOn) {
  const SurfaceMesh liver = makePhantom("liver", 0.5);
  const Box b = boundingBox(liver.V);
  const Box pin{b.lo - Vec3::Constant(1),
                Vec3(b.lo.x() + 0.2 * b.size().x(), b.hi.y() + 1, b.hi.z() + 1)};
  Rig rig(liver, {}, {pin});
  Eigen::Index top = 0;
  liver.V.col(2).maxCoeff(&top);
  const Vec3 p = liver.V.row(top).transpose();
  int within = 0;
  for (Eigen::Index i = 0; i < rig.model.nodes().rows(); ++i)
    within += (rig.model.nodes().row(i).transpose() - p).norm() <= 0.004;
  EXPECT_EQ(within, 0);  // no sphere centre within the jaws
  GraspInput grasp = testing::surfaceGrasp(liver, p, 0.004, rig.model.surface());
  ASSERT_GE(grasp.vertices.size(), 1u);
  const MatX3 t0 = grasp.targets;
  StepInput in;
  in.dt = 1e-3;
  in.gravity = Vec3(0, 0, -9.81);
  Real worst = 0;
  for (int i = 0; i < 200; ++i) {
    grasp.targets = t0.rowwise() + Eigen::RowVector3d(0, 0, 0.02 * std::min(1.0, (i + 1) / 150.0));
    in.grasps = {grasp};
    ASSERT_EQ(rig.model.step(in), StepStatus::Ok);
    worst = std::max(worst, testing::graspResidual(rig.model.surface(), grasp));
  }
  std::printf("small grasp on the liver: %zu vertices, worst RMS residual %.3g mm\n",
              grasp.vertices.size(), worst * 1e3);
  EXPECT_LT(worst, 0.5e-3);
  // The organ followed: the spheres under the grasp rose.
  EXPECT_GT(rig.model.nodes().col(2).maxCoeff(),
            rig.model.metaballs().spheres.centers.col(2).maxCoeff() + 0.01);
}

// The method-comparison liver lift (2.2k vertices, 581 spheres asked, the scene's two fixed boxes,
// an 8 mm grasper near the bottom box): the grasp correction and eq. (12) used to feed each other
// through the carrying spheres' radii, and the surface grew by 2x every ~20 ms, to 0.1 m after
// 150 ms of a 7.5 mm lift. The organ moves by about the lift, nowhere by many times it.
TEST(MetaballsModel, GraspLiftNearAFixedRegionStaysBounded) {
  const SurfaceMesh liver = makePhantom("liver", 0.27);
  const std::vector<Box> fixed = {{Vec3(-0.11, -0.08, -0.05), Vec3(0.11, -0.035, 0.05)},
                                  {Vec3(-0.11, -0.08, -0.05), Vec3(0.11, 0.03, -0.032)}};
  Rig rig(liver, {{"spheres", 581LL}, {"voxel_resolution", 48LL}}, fixed);
  const Vec3 p(-0.0235, 0.0744, -0.0232);
  GraspInput grasp = testing::surfaceGrasp(liver, p, 0.008, rig.model.surface());
  ASSERT_GE(grasp.vertices.size(), 1u);
  const MatX3 t0 = grasp.targets;
  StepInput in;
  in.dt = 1e-3;
  const int steps = 150;
  const Real lift = 0.05 * steps * in.dt;  // 0.05 m/s, 7.5 mm
  Real worstResidual = 0;
  for (int i = 0; i < steps; ++i) {
    grasp.targets = t0.rowwise() + Eigen::RowVector3d(0, 0, 0.05 * (i + 1) * in.dt);
    in.grasps = {grasp};
    ASSERT_EQ(rig.model.step(in), StepStatus::Ok);
    worstResidual = std::max(worstResidual, testing::graspResidual(rig.model.surface(), grasp));
  }
  const Real largest = (rig.model.surface() - liver.V).rowwise().norm().maxCoeff();
  std::printf(
      "liver lift of %.3g mm near the fixed box: largest vertex motion %.3g mm, worst grasp "
      "residual %.3g mm\n",
      lift * 1e3, largest * 1e3, worstResidual * 1e3);
  EXPECT_LT(worstResidual, 0.5e-3);
  EXPECT_GT(largest, 0.5 * lift) << "the grasp lifted the organ";
  EXPECT_LT(largest, 3 * lift);
}

// A point force spread by the harness over a 1 cm patch reaches the spheres by W^T: the patch moves
// along the force.
TEST(MetaballsModel, PatchLoadMovesThePatchAlongTheForce) {
  const SurfaceMesh s = test::banana(0.16, 0.035, 0.08, 4);
  const Box b = boundingBox(s.V);
  Rig rig(s, {},
          {Box{b.lo - Vec3::Constant(1), Vec3(b.lo.x() + 0.03, b.hi.y() + 1, b.hi.z() + 1)}});
  Eigen::Index c = 0;
  s.V.col(0).maxCoeff(&c);
  const SurfacePatch patch = pressurePatch(s, int(c), 0.01);
  ASSERT_GT(patch.vertices.size(), 3u);
  PointLoad load;
  load.surfaceVertex = int(c);
  load.force = Vec3(0, 0.2, -0.5);
  load.vertices = patch.vertices;
  load.weights = patch.weights;
  StepInput in;
  in.dt = 1e-3;
  in.loads = {load};
  for (int i = 0; i < 100; ++i) ASSERT_EQ(rig.model.step(in), StepStatus::Ok);
  Vec3 u = Vec3::Zero();
  for (size_t k = 0; k < patch.vertices.size(); ++k)
    u += patch.weights[k] *
         (rig.model.surface().row(patch.vertices[k]) - s.V.row(patch.vertices[k])).transpose();
  EXPECT_GT(u.norm(), 1e-4);
  EXPECT_GT(u.dot(load.force.normalized()), 0.9 * u.norm());
}

// The AVX-512 kernels and the scalar path give the same trajectory bit for bit (both stiffness
// modes, with gravity, a grasp and a point load).
TEST(MetaballsModel, SimdAndScalarStepsAgreeBitForBit) {
  const SurfaceMesh s = test::banana(0.16, 0.035, 0.08, 4);
  for (const char* mode : {"xpbd", "classic"}) {
    Rig rig(s, {{"stiffness_mode", std::string(mode)}});
    const MatX3 x0 = s.V;
    Eigen::Index g = 0;
    x0.col(0).maxCoeff(&g);
    auto run = [&](bool simd) {
      rig.model.reset();
      rig.model.setSimd(simd);
      StepInput in;
      in.dt = 1e-3;
      in.gravity = Vec3(0, 0, -9.81);
      in.loads.resize(1);
      in.loads[0].surfaceVertex = 0;
      in.loads[0].force = Vec3(0.5, 0, 0);
      GraspInput grasp;
      grasp.vertices = {int(g)};
      for (int i = 0; i < 60; ++i) {
        grasp.targets = x0.row(g);
        grasp.targets(0, 1) += 0.0003 * (i + 1);
        in.grasps = {grasp};
        EXPECT_EQ(rig.model.step(in), StepStatus::Ok);
      }
      return MatX3(rig.model.surface());
    };
    const MatX3 a = run(true), b = run(false);
    EXPECT_TRUE(a == b) << mode;
    EXPECT_GT((a - s.V).cwiseAbs().maxCoeff(), 1e-3) << mode;
  }
}

TEST(MetaballsModel, NanTargetIsReportedAsDiverged) {
  Rig rig(test::banana(0.16, 0.035, 0.08, 3), {});
  StepInput in;
  in.dt = 1e-3;
  GraspInput grasp;
  grasp.vertices = {0};
  grasp.targets = MatX3::Constant(1, 3, std::numeric_limits<Real>::quiet_NaN());
  in.grasps = {grasp};
  EXPECT_EQ(rig.model.step(in), StepStatus::Diverged);
}

// Fig. 12: drag part of the liver, release, let it recover; with the Laplacian constraint the
// surface returns closer to its rest shape than without.
TEST(MetaballsModel, Fig12LaplacianImprovesShapeRecovery) {
  const SurfaceMesh liver = makePhantom("liver", 0.5);
  const Box b = boundingBox(liver.V);
  // Pin the left fifth of the organ (as its ligaments would).
  Box pin{b.lo - Vec3::Constant(1),
          Vec3(b.lo.x() + 0.2 * b.size().x(), b.hi.y() + 1, b.hi.z() + 1)};
  Real err[2];
  for (int lap = 0; lap < 2; ++lap) {
    Rig rig(liver,
            {{"laplacian", bool(lap)},
             {"stiffness_mode", std::string("classic")},
             {"stiffness", 0.5},
             {"laplacian_stiffness", 0.5}},
            {pin});
    const MatX3 x0 = liver.V;
    Eigen::Index g = 0;
    x0.col(0).maxCoeff(&g);
    StepInput in;
    in.dt = 1e-3;
    GraspInput grasp;
    grasp.vertices = {int(g)};
    for (int i = 0; i < 200; ++i) {  // drag 3 cm up and sideways
      grasp.targets = x0.row(g);
      grasp.targets.row(0) += (Real(i + 1) / 200) * Eigen::RowVector3d(0.0, 0.02, 0.02);
      in.grasps = {grasp};
      ASSERT_EQ(rig.model.step(in), StepStatus::Ok);
    }
    in.grasps.clear();
    for (int i = 0; i < 300; ++i) ASSERT_EQ(rig.model.step(in), StepStatus::Ok);
    err[lap] = rmsToRest(rig.model.surface(), liver.V);
  }
  std::printf("Fig. 12 rms to rest after release: with Laplacian %.3g m, without %.3g m\n", err[1],
              err[0]);
  EXPECT_LT(err[1], err[0]) << "with " << err[1] << " without " << err[0];
}

// Fig. 13 (paper: "the section of intestine dragged by a grasper becomes thinner" with the local
// volume preservation): the intestine phantom, the spheres farther than 5 cm from the middle of
// the tube pinned (the mesentery), a grasper closing around the middle of the tube (the surface
// vertices within 15 mm of its axis point: the tube's radius is 13.5 mm) drags them 3 cm out of
// the plane and holds. The rest of the organ stays near rest, so the change of the volume
// enclosed by the skinned surface is the dragged section's. With eq. (12) the stretched section
// thins and gains less volume than without; its skinned cross-section just outside the jaws is
// smaller. The carrying spheres in the jaws keep their radii of the closing (before they did not,
// and their radius factor fell to 0.16 at 950 spheres, the runaway of the grasp correction). The
// volume gains with / without eq. (12), cm^3: 6.55 / 6.86 at 850 spheres, 5.83 / 5.85 at 900, 5.10
// / 5.28 at 950; they are compared at each budget and summed.
struct Fig13Result {
  Real dV, v0;       // volume change and rest volume of the closed surface (m^3)
  Real sectionDisp;  // mean |v - c_center| over the surface vertices in the ring (m)
  Real sectionRest;  // the same at rest
  Real minFactor;    // smallest r / r_rest (eq. 12)
};
/// m, the ring around the tool whose cross-section fig13Drag measures: the dragged section just
/// outside the jaws (radius 15 mm). The carrying spheres in the jaws keep their radii of the
/// closing (the jaws, not eq. 12, shape the tissue between them); their linked spheres take the
/// factor.
constexpr Real kSectionInner = 0.015, kSectionOuter = 0.025;

Fig13Result fig13Drag(bool volumePreservation, long long spheres) {
  const SurfaceMesh gut = makePhantom("intestine");
  // First construction to find the spheres (deterministic: the second one is identical).
  ParamValues construction = ParamValues::defaults(metaballsParams());
  construction.set("spheres", spheres);
  const Metaballs mb = constructMetaballs(gut, constructionParams(construction));
  const MatX3& c0 = mb.spheres.centers;
  const int mid = nearestVertex(c0, boundingBox(gut.V).center());
  const Vec3 tool = c0.row(mid).transpose();
  std::vector<Box> pins;
  for (Eigen::Index i = 0; i < c0.rows(); ++i)
    if ((c0.row(i).transpose() - tool).norm() > 0.05)
      pins.push_back(Box{c0.row(i).transpose() - Vec3::Constant(1e-6),
                         c0.row(i).transpose() + Vec3::Constant(1e-6)});
  Rig rig(gut,
          {{"spheres", spheres},
           {"voxel_resolution", (long long)48},
           {"volume_preservation", volumePreservation}},
          pins);
  const MatX3 x0 = rig.model.nodes();
  EXPECT_TRUE(x0 == c0);
  GraspInput grasp;
  grasp.vertices = graspedSurfaceVertices(gut, tool, 0.015);
  EXPECT_GE(grasp.vertices.size(), 8u);
  StepInput in;
  in.dt = 1e-3;
  for (int i = 0; i < 400; ++i) {
    grasp.targets.resize(Eigen::Index(grasp.vertices.size()), 3);
    for (size_t k = 0; k < grasp.vertices.size(); ++k) {
      grasp.targets.row(Eigen::Index(k)) = gut.V.row(grasp.vertices[k]);
      grasp.targets(Eigen::Index(k), 2) += 0.03 * std::min(1.0, Real(i + 1) / 300);
    }
    in.grasps = {grasp};
    EXPECT_EQ(rig.model.step(in), StepStatus::Ok);
  }
  const Real minFactor = rig.model.radii().cwiseQuotient(rig.model.restRadii()).minCoeff();
  // Cross-section of the dragged section: the skinning offset |v - c_center| (eqs. 14-16).
  const Skinning& sk = rig.model.skinning();
  auto section = [&](const MatX3& centres, const MatX3& surf) {
    Real sum = 0;
    int cnt = 0;
    for (int v = 0; v < sk.numVertices; ++v) {
      const Real dist = (gut.V.row(v).transpose() - tool).norm();
      if (dist <= kSectionInner || dist > kSectionOuter) continue;
      Vec3 cc = Vec3::Zero();
      for (int s = 0; s < sk.count[size_t(v)]; ++s)
        cc += sk.weight[size_t(v * sk.slots + s)] *
              centres.row(sk.sphere[size_t(v * sk.slots + s)]).transpose();
      sum += (surf.row(v).transpose() - cc).norm();
      ++cnt;
    }
    return sum / std::max(cnt, 1);
  };
  const Real v0 = signedVolume(gut.V, gut.F);
  return {signedVolume(rig.model.surface(), gut.F) - v0, v0,
          section(rig.model.nodes(), rig.model.surface()), section(x0, gut.V), minFactor};
}

TEST(MetaballsModel, Fig13VolumePreservationThinsTheDraggedSection) {
  Real gainWith = 0, gainWithout = 0;
  for (long long spheres : {850LL, 900LL, 950LL}) {
    const Fig13Result with = fig13Drag(true, spheres), without = fig13Drag(false, spheres);
    std::printf(
        "Fig. 13 intestine, %lld spheres, 3 cm drag: volume change with eq. 12 %+.3g cm^3 "
        "(%+.2f%%), without %+.3g cm^3 (%+.2f%%); section offset 15-25 mm from the tool: rest %.3g "
        "mm, "
        "with %.3g mm, without %.3g mm; smallest radius factor %.4f\n",
        spheres, with.dV * 1e6, 100 * with.dV / with.v0, without.dV * 1e6,
        100 * without.dV / without.v0, with.sectionRest * 1e3, with.sectionDisp * 1e3,
        without.sectionDisp * 1e3, with.minFactor);
    // Without eq. (12) the stretched section keeps its radii and gains volume.
    EXPECT_GT(without.dV, 0) << spheres;
    // With it, the section thins: a smaller cross-section than without.
    EXPECT_LT(with.sectionDisp, without.sectionDisp) << spheres;
    EXPECT_LT(with.dV, without.dV) << spheres;
    EXPECT_LT(with.minFactor, 1.0) << spheres;
    EXPECT_EQ(without.minFactor, 1.0) << spheres;
    gainWith += with.dV;
    gainWithout += without.dV;
  }
  // And gains less volume.
  EXPECT_LT(std::abs(gainWith), std::abs(gainWithout));
}

}  // namespace
}  // namespace metaballs
}  // namespace deform
