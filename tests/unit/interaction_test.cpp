// Interaction: keyframe interpolation, jaw state, grasp attach/follow/release, point forces and
// pin heads, probes, the focus point and the fixed region.
#include <deform/engine/interaction.h>
#include <deform/geometry/phantom.h>
#include <deform/sdk/contact.h>
#include <gtest/gtest.h>

#include "harness_test_models.h"

#include <algorithm>

namespace deform {
namespace {

using testing::FixedNodesModel;

KeyFrame kf(Real t, Vec3 p, bool closed) {
  return KeyFrame{t, p, closed};
}

std::vector<KeyFrame> liftTrajectory() {
  return {kf(0.0, Vec3(0, 0, 0), false), kf(0.1, Vec3(0, 0, 0), true),
          kf(0.6, Vec3(0, 0, 0.02), true), kf(0.8, Vec3(0, 0, 0.02), false)};
}

TEST(ToolPosition, PiecewiseLinearAndHeldAtTheEnds) {
  const std::vector<KeyFrame> k = {kf(0.2, Vec3(1, 0, 0), false), kf(0.4, Vec3(3, 2, 0), false),
                                   kf(1.0, Vec3(3, 2, 6), false)};
  EXPECT_EQ(toolPosition(k, 0.0), Vec3(1, 0, 0));
  EXPECT_EQ(toolPosition(k, 0.2), Vec3(1, 0, 0));
  EXPECT_TRUE(toolPosition(k, 0.3).isApprox(Vec3(2, 1, 0)));
  EXPECT_TRUE(toolPosition(k, 0.4).isApprox(Vec3(3, 2, 0)));
  EXPECT_TRUE(toolPosition(k, 0.5).isApprox(Vec3(3, 2, 1)));
  EXPECT_EQ(toolPosition(k, 5.0), Vec3(3, 2, 6));
}

TEST(JawClosed, StateOfTheLastKeyframeReached) {
  const auto k = liftTrajectory();
  EXPECT_FALSE(jawClosed(k, -1.0));
  EXPECT_FALSE(jawClosed(k, 0.05));
  EXPECT_TRUE(jawClosed(k, 0.1));
  EXPECT_TRUE(jawClosed(k, 0.7));
  EXPECT_FALSE(jawClosed(k, 0.8));
  EXPECT_FALSE(jawClosed({kf(0.5, Vec3::Zero(), true)}, 0.2)) << "open before the first frame";
}

Scene graspScene(Real radius) {
  Scene s;
  s.dt = 0.01;
  s.duration = 1.0;
  ToolSpec t;
  t.type = ToolType::Grasper;
  t.radius = radius;
  t.trajectory = liftTrajectory();
  s.tools.push_back(t);
  return s;
}

MatX3 lineOfNodes() {
  MatX3 n(4, 3);
  n << 0, 0, 0,     //
      0.004, 0, 0,  //
      0.006, 0, 0,  //
      0, 0.001, 0;
  return n;
}

/// The four points above as an organ surface (two triangles).
SurfaceMesh lineSurface(const Vec3& shift = Vec3::Zero()) {
  SurfaceMesh s;
  s.V = lineOfNodes().rowwise() + shift.transpose();
  s.F.resize(2, 3);
  s.F << 0, 1, 3, 1, 2, 3;
  return s;
}

TEST(Interaction, GraspHoldsRestSurfaceVerticesWithinRadiusFollowsAndReleases) {
  const Scene scene = graspScene(0.005);
  const SurfaceMesh rest = lineSurface();
  Interaction inter(scene, rest);
  FixedNodesModel model(rest.V);

  EXPECT_TRUE(inter.prepare(0.05, 0.01, model).grasps.empty()) << "jaws still open";

  // The set is picked on the REST surface (the same for every model), the targets start from
  // the model's own surface at the closing: vertex 2 has moved near the tool but is not held,
  // vertex 0 has sagged 1 mm and its target starts there.
  model.m_x.row(2) = Vec3(0.001, 0, 0).transpose();
  model.m_x.row(0) = Vec3(0, 0, -0.001).transpose();
  // Step count 10 at dt 0.01 lands on the closing keyframe, possibly a rounding error below it.
  StepInput in = inter.prepare(10 * 0.01, 0.01, model);
  ASSERT_EQ(in.grasps.size(), 1u);
  EXPECT_EQ(in.grasps[0].tool, 0);
  EXPECT_EQ(in.grasps[0].vertices, (std::vector<int>{0, 1, 3}));
  ASSERT_EQ(in.grasps[0].targets.rows(), 3);
  // The tool moves 0.02 m up between t = 0.1 and 0.6: 0.0004 m during the first step.
  EXPECT_NEAR(in.grasps[0].targets(0, 2), -0.001 + 0.0004, 1e-12);
  EXPECT_NEAR(in.grasps[0].targets(1, 0), 0.004, 1e-15);

  // Held vertices stay held when the model's surface moves away later.
  model.m_x.row(1) = Vec3(1, 1, 1).transpose();
  in = inter.prepare(0.35, 0.01, model);
  ASSERT_EQ(in.grasps.size(), 1u);
  EXPECT_EQ(in.grasps[0].vertices, (std::vector<int>{0, 1, 3}));
  EXPECT_NEAR(in.grasps[0].targets(1, 2), 0.02 * (0.36 - 0.1) / 0.5, 1e-12)
      << "targets are the positions at closing, translated by the tool";
  EXPECT_NEAR(in.grasps[0].targets(1, 0), 0.004, 1e-15);

  EXPECT_TRUE(inter.prepare(0.85, 0.01, model).grasps.empty()) << "released when the jaws open";
  EXPECT_TRUE(inter.emptyGrasps().empty());
  EXPECT_EQ(inter.graspTravel(), (std::vector<Real>{0.02}));
}

TEST(Interaction, APlateIsAGraspOfItsBoxsRestVerticesOnRestPlusOffset) {
  Scene scene;
  scene.dt = 0.01;
  scene.duration = 1.0;
  PlateSpec plate;
  plate.region.lo = Vec3(0.0035, -1, -1);
  plate.region.hi = Vec3(1, 1, 1);
  plate.trajectory = {kf(0.0, Vec3::Zero(), false), kf(1.0, Vec3(0, 0, -0.01), false)};
  scene.plates.push_back(plate);
  const SurfaceMesh rest = lineSurface();
  Interaction inter(scene, rest);
  ASSERT_EQ(inter.plateVertices().size(), 1u);
  EXPECT_EQ(inter.plateVertices()[0], (std::vector<int>{1, 2}));
  FixedNodesModel model(rest.V);
  // Bonded from the start, whatever the model's surface did: targets are rest + offset(t + dt).
  model.m_x.row(1) = Vec3(5, 5, 5).transpose();
  const StepInput in = inter.prepare(0.49, 0.01, model);
  ASSERT_EQ(in.grasps.size(), 1u);
  EXPECT_EQ(in.grasps[0].tool, 0) << "plates come after the scene's tools (none here)";
  EXPECT_EQ(in.grasps[0].vertices, (std::vector<int>{1, 2}));
  EXPECT_NEAR(in.grasps[0].targets(0, 0), 0.004, 1e-15);
  EXPECT_NEAR(in.grasps[0].targets(0, 2), -0.005, 1e-12);
  EXPECT_NEAR(in.grasps[0].targets(1, 0), 0.006, 1e-15);
  EXPECT_EQ(inter.graspTravel(), (std::vector<Real>{0.01}));
  EXPECT_TRUE(plateSurfaceVertices(rest.V, Box{Vec3::Constant(2), Vec3::Constant(3)}).empty());
  EXPECT_FALSE(in.grasps[0].sliding()) << "a bonded plate";
  EXPECT_EQ(slideAxis(in.grasps[0]), -1);
  // A sliding plate: the same vertices and targets, with its normal.
  scene.plates[0].contact = PlateContact::Sliding;
  scene.plates[0].normal = Vec3(0, 0, -1);
  Interaction sliding(scene, rest);
  const StepInput s = sliding.prepare(0.49, 0.01, model);
  ASSERT_EQ(s.grasps.size(), 1u);
  EXPECT_EQ(s.grasps[0].vertices, in.grasps[0].vertices);
  EXPECT_EQ(s.grasps[0].targets, in.grasps[0].targets);
  EXPECT_EQ(s.grasps[0].slideNormal, Vec3(0, 0, -1));
  EXPECT_EQ(slideAxis(s.grasps[0]), 2);
  std::vector<NodeGrasp> nodes;
  graspsOnNodes(s.grasps, {}, nodes);
  ASSERT_EQ(nodes.size(), 1u);
  EXPECT_TRUE(nodes[0].sliding()) << "the normal reaches the node grasps";
}

TEST(Interaction, SmallJawsHoldAtLeastTheNearestVertexAndResetForgets) {
  // No vertex within 0.1 mm of the closing point (the origin): the nearest one is held, so a
  // grasp that reaches the surface is never empty.
  const Scene scene = graspScene(0.0001);
  const SurfaceMesh rest = lineSurface(Vec3(0, 0.0003, 0));
  Interaction inter(scene, rest);
  FixedNodesModel model(rest.V);
  const StepInput in = inter.prepare(0.2, 0.01, model);
  ASSERT_EQ(in.grasps.size(), 1u);
  EXPECT_EQ(in.grasps[0].vertices, (std::vector<int>{0}));
  EXPECT_TRUE(inter.emptyGrasps().empty());
  EXPECT_EQ(graspedSurfaceVertices(rest.V, Vec3(0.0049, 0.0003, 0), 0.0012),
            (std::vector<int>{1, 2}));

  // After reset the grasp attaches again at the next prepare, from the model's surface then.
  inter.reset();
  model.m_x.row(0) = Vec3(0.5, 0, 0).transpose();
  const StepInput again = inter.prepare(0.3, 0.01, model);
  ASSERT_EQ(again.grasps.size(), 1u);
  EXPECT_EQ(again.grasps[0].vertices, (std::vector<int>{0}));
  EXPECT_NEAR(again.grasps[0].targets(0, 0), 0.5, 1e-15);
}

/// A flat square grid of n x n cells of side h in the z = 0 plane, centred at the origin.
SurfaceMesh flatGrid(int n, Real h) {
  SurfaceMesh s;
  s.V.resize((n + 1) * (n + 1), 3);
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i)
      s.V.row(j * (n + 1) + i) = Vec3((i - 0.5 * n) * h, (j - 0.5 * n) * h, 0).transpose();
  s.F.resize(2 * n * n, 3);
  int f = 0;
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 1, d = c + 1;
      s.F.row(f++) << a, b, d;
      s.F.row(f++) << a, d, c;
    }
  return s;
}

TEST(PressurePatch, ConsistentParaboloidMomentsOnAFineGrid) {
  // On a grid 10x finer than the radius the nodal shares reproduce the paraboloid's moments:
  // total 1, centroid at the centre, second moment integral rho^2 k / integral k = R^2 / 3
  // (up to the interpolation error of |x - c|^2, O(h^2)).
  const Real R = 0.01;
  const SurfaceMesh grid = flatGrid(40, R / 10);
  const int c = nearestVertex(grid.V, Vec3::Zero());
  const SurfacePatch p = pressurePatch(grid, c, R);
  ASSERT_EQ(p.vertices.front(), c);
  Real sum = 0, m2 = 0;
  Vec3 centroid = Vec3::Zero();
  for (size_t k = 0; k < p.vertices.size(); ++k) {
    const Vec3 x = grid.V.row(p.vertices[k]).transpose();
    EXPECT_GT(p.weights[k], 0);
    EXPECT_LT(x.norm(), R + 0.15 * R) << "support within R plus one cell";
    sum += p.weights[k];
    centroid += p.weights[k] * x;
    m2 += p.weights[k] * x.squaredNorm();
  }
  EXPECT_NEAR(sum, 1.0, 1e-12);
  EXPECT_LT(centroid.norm(), 1e-3 * R);
  EXPECT_NEAR(m2, R * R / 3, 0.03 * R * R / 3);

  // The same physical patch on a grid twice as coarse: the same second moment within 5%.
  const SurfaceMesh coarse = flatGrid(20, R / 5);
  const SurfacePatch q = pressurePatch(coarse, nearestVertex(coarse.V, Vec3::Zero()), R);
  Real m2c = 0;
  for (size_t k = 0; k < q.vertices.size(); ++k)
    m2c += q.weights[k] * coarse.V.row(q.vertices[k]).squaredNorm();
  EXPECT_NEAR(m2c, m2, 0.05 * m2);
}

TEST(Interaction, PointForceOnNearestRestVertexWithinItsWindow) {
  Scene scene;
  LoadSpec l;
  l.type = LoadType::PointForce;
  l.at = Vec3(0.09, 0.001, 0);  // nearest to vertex 1 of the tet
  l.force = Vec3(0, 0, 2);
  l.start = 0.2;
  l.end = 0.5;
  scene.loads.push_back(l);
  const SurfaceMesh rest = testing::tetSurface();
  Interaction inter(scene, rest);
  FixedNodesModel model(rest.V);
  EXPECT_EQ(inter.loadVertices(), (std::vector<int>{1}));
  EXPECT_TRUE(inter.prepare(0.1, 0.01, model).loads.empty());
  const StepInput in = inter.prepare(0.2, 0.01, model);
  ASSERT_EQ(in.loads.size(), 1u);
  EXPECT_EQ(in.loads[0].surfaceVertex, 1);
  EXPECT_EQ(in.loads[0].force, Vec3(0, 0, 2));
  // Spread over the 1 cm patch (the default radius) around vertex 1: on this 10 cm tetrahedron
  // almost all of it stays on vertex 1, the rest on its neighbours, summing to 1.
  ASSERT_FALSE(in.loads[0].vertices.empty());
  EXPECT_EQ(in.loads[0].vertices.front(), 1);
  Real sum = 0;
  for (Real w : in.loads[0].weights) sum += w;
  EXPECT_NEAR(sum, 1.0, 1e-12);
  EXPECT_GT(in.loads[0].weights.front(), 0.8);
  EXPECT_EQ(inter.prepare(0.49, 0.01, model).loads.size(), 1u);
  EXPECT_TRUE(inter.prepare(0.5, 0.01, model).loads.empty()) << "end is exclusive";
  EXPECT_EQ(inter.focusPoint(), rest.V.row(1).transpose());
}

TEST(Interaction, PinHeadIsASpringToTheKeyframedPin) {
  Scene scene;
  scene.gravity = Vec3(0, 0, -1);
  LoadSpec l;
  l.type = LoadType::PinHead;
  l.at = Vec3(0, 0, 0.1);
  l.stiffness = 100;
  l.path = {kf(0, Vec3(0, 0, 0.1), false), kf(1, Vec3(0, 0.02, 0.1), false)};
  scene.loads.push_back(l);
  const SurfaceMesh rest = testing::tetSurface();
  Interaction inter(scene, rest);
  FixedNodesModel model(rest.V);
  const StepInput in = inter.prepare(0.49, 0.01, model);
  EXPECT_EQ(in.gravity, Vec3(0, 0, -1));
  ASSERT_EQ(in.loads.size(), 1u);
  EXPECT_EQ(in.loads[0].surfaceVertex, 3);
  // pin at the end of the step (t = 0.5) is 0.01 m along y: f = 100 N/m * 0.01 m.
  EXPECT_TRUE(in.loads[0].force.isApprox(Vec3(0, 1.0, 0), 1e-12)) << in.loads[0].force.transpose();
}

TEST(Interaction, ProbeActsThroughTheContactWorldNotTheGraspInput) {
  Scene scene;
  ToolSpec probe;
  probe.type = ToolType::Probe;
  probe.radius = 0.01;
  probe.trajectory = {kf(0, Vec3(0, 0, 0.005), false)};
  scene.tools.push_back(probe);
  const SurfaceMesh rest = testing::tetSurface();
  Interaction inter(scene, rest);
  FixedNodesModel model(lineOfNodes());
  const StepInput in = inter.prepare(0.0, 0.01, model);
  EXPECT_TRUE(in.grasps.empty());
  ASSERT_NE(in.contact, nullptr);
  EXPECT_EQ(in.contact->numBodies(), 1);
  EXPECT_TRUE(in.contact->position(0).isApprox(Vec3(0, 0, 0.005)));
  // The four nodes within 1 cm of the tip centre are the ones the world reports.
  const std::vector<Contact> c = in.contact->query(lineOfNodes());
  EXPECT_EQ(c.size(), 4u);
  EXPECT_EQ(inter.instrumentWorld(), nullptr) << "a kinematic probe needs no ODE world";
}

TEST(Interaction, FocusPointFallsBackToGraspThenCentre) {
  const SurfaceMesh rest = testing::tetSurface();
  const Scene grasp = graspScene(0.01);
  EXPECT_EQ(Interaction(grasp, rest).focusPoint(), Vec3(0, 0, 0));
  Scene shifted = grasp;
  for (auto& k : shifted.tools[0].trajectory) k.pos += Vec3(0.3, 0, 0);
  EXPECT_EQ(Interaction(shifted, rest).focusPoint(), Vec3(0.3, 0, 0));
  const Scene none;
  EXPECT_TRUE(Interaction(none, rest).focusPoint().isApprox(Vec3(0.05, 0.05, 0.05)));
}

TEST(FixedNodes, BoxesAndNearestNodesToListedVertices) {
  const SurfaceMesh rest = testing::tetSurface();
  MatX3 nodes(5, 3);
  nodes << 0, 0, 0,      //
      0.1, 0, 0,         //
      0.01, 0.0, 0.095,  //
      0.0, 0.09, 0.0,    //
      -0.01, -0.01, -0.01;
  FixedRegion region;
  region.boxes.push_back(Box{Vec3(-0.02, -0.02, -0.02), Vec3(0.001, 0.001, 0.001)});
  region.surfaceVertices = {3, 2};  // rest (0,0,0.1) -> node 2; rest (0,0.1,0) -> node 3
  EXPECT_EQ(fixedNodeIndices(nodes, region, rest), (std::vector<int>{0, 2, 3, 4}));
  EXPECT_TRUE(fixedNodeIndices(nodes, FixedRegion{}, rest).empty());
}

TEST(RegionPatch, ConsistentAreaWeightsOverTheTrianglesInsideTheBox) {
  const SurfaceMesh cube = makePhantom("cube", 0.3);
  const Box top{Vec3(-1, -1, 0.05 - 1e-9), Vec3(1, 1, 1)};
  const SurfacePatch p = regionPatch(cube, top);
  ASSERT_FALSE(p.vertices.empty());
  EXPECT_TRUE(std::is_sorted(p.vertices.begin(), p.vertices.end()));
  Real sum = 0;
  Vec3 centroid = Vec3::Zero();
  for (size_t k = 0; k < p.vertices.size(); ++k) {
    EXPECT_NEAR(cube.V(p.vertices[k], 2), 0.05, 1e-12) << "only the top face is loaded";
    sum += p.weights[k];
    centroid += p.weights[k] * cube.V.row(p.vertices[k]).transpose();
  }
  EXPECT_NEAR(sum, 1.0, 1e-12);
  // A uniform traction's resultant acts at the face's centre.
  EXPECT_LT((centroid - Vec3(0, 0, 0.05)).norm(), 1e-12);
  // Corner vertices of the square face carry less than edge and interior ones.
  const int corner = nearestVertex(cube.V, Vec3(0.05, 0.05, 0.05));
  const int middle = nearestVertex(cube.V, Vec3(0, 0, 0.05));
  const auto weightOf = [&](int v) {
    const auto it = std::find(p.vertices.begin(), p.vertices.end(), v);
    return it == p.vertices.end() ? -1.0 : p.weights[size_t(it - p.vertices.begin())];
  };
  EXPECT_GT(weightOf(corner), 0);
  EXPECT_LT(weightOf(corner), weightOf(middle));
  EXPECT_TRUE(regionPatch(cube, Box{Vec3(-1, -1, 0.2), Vec3(1, 1, 1)}).vertices.empty());
}

}  // namespace
}  // namespace deform
