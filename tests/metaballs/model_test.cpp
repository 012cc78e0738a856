// The metaballs model: rest, grasp, reset, divergence, and the paper's experiments as measured
// differences (Fig. 12: shape recovery with vs without the Laplacian constraint; Fig. 13: local
// volume preservation by eq. 12).
#include "metaballs_model.h"
#include "test_meshes.h"

#include <deform/phantom.h>
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

TEST(MetaballsModel, GraspedSphereFollowsTargetAndResetReproduces) {
  const SurfaceMesh s = test::banana(0.16, 0.035, 0.08, 4);
  Rig rig(s, {});
  const MatX3 x0 = rig.model.nodes();
  Eigen::Index g = 0;
  x0.col(0).maxCoeff(&g);
  auto run = [&]() {
    MatX3 last;
    StepInput in;
    in.dt = 1e-3;
    in.gravity = Vec3(0, 0, -9.81);
    GraspInput grasp;
    grasp.nodes = {int(g)};
    for (int i = 0; i < 100; ++i) {
      grasp.targets = x0.row(g);
      grasp.targets(0, 2) += 0.0002 * (i + 1);
      in.grasps = {grasp};
      EXPECT_EQ(rig.model.step(in), StepStatus::Ok);
      EXPECT_LE((rig.model.nodes().row(g) - grasp.targets.row(0)).norm(), 1e-15);
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

// The AVX-512 kernels and the scalar path give the same trajectory bit for bit (both stiffness
// modes, with gravity, a grasp and a point load).
TEST(MetaballsModel, SimdAndScalarStepsAgreeBitForBit) {
  const SurfaceMesh s = test::banana(0.16, 0.035, 0.08, 4);
  for (const char* mode : {"xpbd", "classic"}) {
    Rig rig(s, {{"stiffness_mode", std::string(mode)}});
    const MatX3 x0 = rig.model.nodes();
    Eigen::Index g = 0;
    x0.col(0).maxCoeff(&g);
    auto run = [&](bool simd) {
      rig.model.reset();
      rig.model.setSimd(simd);
      StepInput in;
      in.dt = 1e-3;
      in.gravity = Vec3(0, 0, -9.81);
      in.loads = {PointLoad{0, Vec3(0.5, 0, 0)}};
      GraspInput grasp;
      grasp.nodes = {int(g)};
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
  grasp.nodes = {0};
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
    const MatX3 x0 = rig.model.nodes();
    Eigen::Index g = 0;
    x0.col(0).maxCoeff(&g);
    StepInput in;
    in.dt = 1e-3;
    GraspInput grasp;
    grasp.nodes = {int(g)};
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

// Fig. 13: compress a section of the intestine with a grasp; with eq. (12) the volume enclosed by
// the skinned surface stays closer to its rest value than without.
TEST(MetaballsModel, Fig13VolumePreservationKeepsVolume) {
  const SurfaceMesh gut = makePhantom("intestine");
  const Real v0 = signedVolume(gut.V, gut.F);
  Real dev[2];
  for (int vp = 0; vp < 2; ++vp) {
    Rig rig(gut, {{"volume_preservation", bool(vp)}});
    const MatX3 x0 = rig.model.nodes();
    const Vec3 centre = x0.colwise().mean().transpose();
    // Grasp the spheres within 1.5 cm of the sphere nearest the centre, push them 1 cm down.
    const int c = nearestVertex(x0, centre);
    GraspInput grasp;
    for (Eigen::Index i = 0; i < x0.rows(); ++i)
      if ((x0.row(i) - x0.row(c)).norm() < 0.015) grasp.nodes.push_back(int(i));
    StepInput in;
    in.dt = 1e-3;
    for (int i = 0; i < 150; ++i) {
      grasp.targets.resize(Eigen::Index(grasp.nodes.size()), 3);
      for (size_t k = 0; k < grasp.nodes.size(); ++k) {
        grasp.targets.row(Eigen::Index(k)) = x0.row(grasp.nodes[k]);
        grasp.targets(Eigen::Index(k), 2) -= 0.01 * std::min(1.0, Real(i + 1) / 100);
      }
      in.grasps = {grasp};
      ASSERT_EQ(rig.model.step(in), StepStatus::Ok);
    }
    dev[vp] = std::abs(signedVolume(rig.model.surface(), gut.F) / v0 - 1);
  }
  std::printf("Fig. 13 |V/V0 - 1|: with eq. 12 %.3g, without %.3g\n", dev[1], dev[0]);
  EXPECT_LT(dev[1], dev[0]) << "with " << dev[1] << " without " << dev[0];
}

}  // namespace
}  // namespace metaballs
}  // namespace deform
