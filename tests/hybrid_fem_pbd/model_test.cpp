// Hybrid FEM+PBD model: rest state, control nodes, loads, linearity, grasp, cut, reset.
#include <deform/mesh_check.h>
#include <deform/phantom.h>
#include <gtest/gtest.h>

#include <set>

#include "hybrid_model.h"

namespace deform::hybrid {
namespace {

Cache& testCache() {
  static Cache c(Cache::defaultDir());
  return c;
}

Organ phantomOrgan(const std::string& name, double resolution) {
  Organ o;
  o.source = "phantom:" + name;
  o.surface = makePhantom(name, resolution);
  o.material = Material{5500, 0.3, 1000};
  const Box b = boundingBox(o.surface.V);
  Box fixed;
  fixed.lo = b.lo - Vec3::Constant(0.01);
  fixed.hi = Vec3(b.hi.x() + 0.01, b.hi.y() + 0.01, b.lo.z() + 0.1 * b.size().z());
  o.fixed.boxes.push_back(fixed);
  return o;
}

// The surface vertex with the largest z nearest the vertical axis through the centre.
int topVertex(const SurfaceMesh& s) {
  const Box b = boundingBox(s.V);
  return nearestVertex(s.V, Vec3(b.center().x(), b.center().y(), b.hi.z()));
}

StepInput input(int load = -1, Vec3 force = Vec3::Zero()) {
  StepInput in;
  in.dt = 1e-3;
  if (load >= 0) in.loads.push_back({load, force});
  return in;
}

Real maxDistance(const MatX3& a, const MatX3& b) {
  return (a.topRows(b.rows()) - b).rowwise().norm().maxCoeff();
}

class HybridModelTest : public ::testing::Test {
 protected:
  void SetUp() override {
    organ = phantomOrgan("cube", 0.5);
    model.init(organ, HybridConfig(), &testCache());
  }
  Organ organ;
  HybridModel model;
};

TEST_F(HybridModelTest, CountsAndHybridMeshStructure) {
  const Counts c = model.counts();
  EXPECT_EQ(c.at("nodes"), organ.surface.numVertices());
  EXPECT_GT(c.at("tets"), 0);
  EXPECT_LT(c.at("coarse_vertices"), c.at("nodes"));
  EXPECT_EQ(c.at("control_nodes"), c.at("coarse_vertices"));
  EXPECT_GT(c.at("constraints"), c.at("nodes"));
  // The boundary of MV is the coarse surface, and its nodes are exactly the control nodes.
  const HybridMesh& m = model.hybridMesh();
  const SurfaceMesh boundary = tetBoundary(m.volume);
  std::set<int> bnodes;
  for (Eigen::Index f = 0; f < boundary.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) bnodes.insert(boundary.F(f, k));
  EXPECT_EQ(static_cast<int>(bnodes.size()), m.coarseSurface.numVertices());
  for (int v : bnodes) EXPECT_LT(v, m.coarseSurface.numVertices());
  for (int c2 = 0; c2 < m.coarseSurface.numVertices(); ++c2) {
    EXPECT_EQ((m.volume.V.row(c2) - organ.surface.V.row(m.coarseToFine[c2])).norm(), 0.0);
    EXPECT_EQ(model.controlOf()[m.coarseToFine[c2]], c2);
  }
}

TEST_F(HybridModelTest, AtRestNothingMoves) {
  for (int s = 0; s < 30; ++s) ASSERT_EQ(model.step(input()), StepStatus::Ok);
  EXPECT_LE(maxDistance(model.surface(), organ.surface.V), 1e-12);
}

TEST_F(HybridModelTest, ControlNodesFollowTheVolumeMeshEveryStep) {
  const int top = topVertex(organ.surface);
  for (int s = 0; s < 40; ++s) {
    ASSERT_EQ(model.step(input(top, Vec3(0, 0, 2.0))), StepStatus::Ok);
    for (size_t i = 0; i < model.controlOf().size(); ++i) {
      const int c = model.controlOf()[i];
      if (c < 0) continue;
      ASSERT_EQ((model.surface().row(i) - model.volumePositions().row(c)).norm(), 0.0)
          << "step " << s << " node " << i;
    }
  }
  EXPECT_GT(maxDistance(model.surface(), organ.surface.V), 1e-4);
}

TEST_F(HybridModelTest, NoNaNUnder20N) {
  const int top = topVertex(organ.surface);
  for (const Real fz : {20.0, -20.0}) {
    model.reset();
    for (int s = 0; s < 300; ++s) ASSERT_EQ(model.step(input(top, Vec3(0, 0, fz))), StepStatus::Ok);
    EXPECT_TRUE(model.surface().allFinite());
    EXPECT_LT(maxDistance(model.surface(), organ.surface.V), 1.0);
  }
}

TEST_F(HybridModelTest, PointLoadMovesAlongTheForceAndScalesLinearly) {
  // A fine node that is not a control node, so both the FEM (through the shape functions) and
  // the PBD prediction see the load.
  const int top = topVertex(organ.surface);
  int load = top;
  for (int v : nearestVertices(organ.surface.V, organ.surface.V.row(top), 20))
    if (model.controlOf()[v] < 0) {
      load = v;
      break;
    }
  ASSERT_LT(model.controlOf()[load], 0);
  const Vec3 dir = Vec3(0.2, -0.1, 1.0).normalized();
  auto settle = [&](Real f) {
    model.reset();
    for (int s = 0; s < 400; ++s) model.step(input(load, f * dir));
    return MatX3(model.surface() - organ.surface.V);
  };
  const MatX3 u1 = settle(0.05), u2 = settle(0.1);
  const Vec3 d1 = u1.row(load).transpose(), d2 = u2.row(load).transpose();
  EXPECT_GT(d1.dot(dir), 0.5 * d1.norm());
  EXPECT_GT(d1.norm(), 1e-5);
  EXPECT_NEAR(d2.norm() / d1.norm(), 2.0, 0.1);
  // The FEM part (control nodes) is exactly linear.
  Real num = 0, den = 0;
  for (size_t i = 0; i < model.controlOf().size(); ++i) {
    if (model.controlOf()[i] < 0) continue;
    num += (u2.row(i) - 2 * u1.row(i)).norm();
    den += u2.row(i).norm();
  }
  EXPECT_LT(num, 1e-9 * den + 1e-15);
  // The surface near the load moves with it: mean displacement of the 10 nearest along dir.
  Real along = 0;
  for (int v : nearestVertices(organ.surface.V, organ.surface.V.row(load), 10))
    along += u1.row(v).dot(dir.transpose());
  EXPECT_GT(along, 0);
}

TEST_F(HybridModelTest, GravitySagsTheOrganAsABodyForce) {
  StepInput in = input();
  in.gravity = Vec3(0, 0, -9.81);
  for (int s = 0; s < 200; ++s) ASSERT_EQ(model.step(in), StepStatus::Ok);
  const int top = topVertex(organ.surface);
  EXPECT_LT(model.surface()(top, 2) - organ.surface.V(top, 2), -1e-4);
  // Linear FEM: doubling g doubles every control node's displacement.
  const MatX3 u1 = model.volumePositions() - model.hybridMesh().volume.V;
  model.reset();
  in.gravity *= 2;
  model.step(in);
  const MatX3 u2 = model.volumePositions() - model.hybridMesh().volume.V;
  EXPECT_LT((u2 - 2 * u1).norm(), 1e-9 * u2.norm());
}

TEST_F(HybridModelTest, GraspMovesTheGraspedRegion) {
  const int top = topVertex(organ.surface);
  GraspInput g;
  g.nodes = nearestVertices(organ.surface.V, organ.surface.V.row(top), 6);
  g.targets = MatX3(g.nodes.size(), 3);
  for (size_t k = 0; k < g.nodes.size(); ++k)
    g.targets.row(k) = organ.surface.V.row(g.nodes[k]) + Vec3(0, 0, 0.005).transpose();
  StepInput in = input();
  in.grasps.push_back(g);
  for (int s = 0; s < 50; ++s) ASSERT_EQ(model.step(in), StepStatus::Ok);
  for (size_t k = 0; k < g.nodes.size(); ++k)
    EXPECT_LT((model.surface().row(g.nodes[k]) - g.targets.row(k)).norm(), 1e-12);
  // A node just outside the grasp is lifted too (through MV and the surface constraints).
  const int outside = nearestVertices(organ.surface.V, organ.surface.V.row(top), 12).back();
  EXPECT_GT(model.surface()(outside, 2) - organ.surface.V(outside, 2), 1e-4);
}

TEST_F(HybridModelTest, ResetReproducesBitForBit) {
  const int top = topVertex(organ.surface);
  for (int s = 0; s < 25; ++s) model.step(input(top, Vec3(0.3, 0, -1.0)));
  const MatX3 first = model.surface();
  model.reset();
  EXPECT_EQ(maxDistance(model.surface(), organ.surface.V), 0.0);
  for (int s = 0; s < 25; ++s) model.step(input(top, Vec3(0.3, 0, -1.0)));
  EXPECT_EQ((model.surface() - first).norm(), 0.0);
}

CutPath topCut(const SurfaceMesh& s) {
  const Box b = boundingBox(s.V);
  CutPath p;
  const Real z = b.hi.z();
  p.points = {Vec3(b.center().x() - 0.02, b.center().y() - 0.005, z),
              Vec3(b.center().x() + 0.021, b.center().y() + 0.004, z)};
  p.depth = 0.002;
  return p;
}

TEST_F(HybridModelTest, CutKeepsAValidSurfaceAtRest) {
  const int n0 = organ.surface.numVertices();
  model.cut(topCut(organ.surface));
  const CutReport& r = model.lastCut();
  ASSERT_TRUE(r.applied) << r.reason;
  EXPECT_GT(r.edgePoints, 0);
  EXPECT_EQ(model.surface().rows(), n0 + r.newVertices);
  EXPECT_EQ((model.surface().topRows(n0) - organ.surface.V).norm(), 0.0);
  SurfaceMesh cutSurface{model.surface(), model.surfaceFaces()};
  ASSERT_EQ(cutSurface.F.rows(), organ.surface.numFaces() + r.newFaces);
  const MeshReport rep = validateSurface(cutSurface);
  // The only defects are the cut's open boundary (2 lips per cut edge) and, before the cut
  // opens, the duplicated path vertices sitting on their originals.
  for (const MeshIssue& i : rep.issues) {
    if (i.defect == MeshDefect::DuplicateVertices) {
      EXPECT_EQ(i.count, static_cast<int>(r.duplicates.size()));
      continue;
    }
    EXPECT_EQ(i.defect, MeshDefect::BoundaryEdges) << i.message;
    EXPECT_EQ(i.count, 2 * (static_cast<int>(r.path.size()) - 1));
  }
  EXPECT_FALSE(rep.has(MeshDefect::NonManifoldEdges));
  EXPECT_FALSE(rep.has(MeshDefect::DegenerateTriangles));
  // Duplicated control points are released.
  for (const auto& [v, copy] : r.duplicates) {
    EXPECT_LT(model.controlOf()[v], 0);
    EXPECT_LT(model.controlOf()[copy], 0);
  }
  // With no load the cut surface stays at rest (new rest lengths consistent).
  for (int s = 0; s < 50; ++s) ASSERT_EQ(model.step(input()), StepStatus::Ok);
  EXPECT_LE(maxDistance(model.surface(), model.restSurface()), 1e-9);
  // A load near the cut opens nothing wrong: still finite, reset restores the uncut surface.
  for (int s = 0; s < 50; ++s) model.step(input(r.path[1], Vec3(0, 0.5, 0.5)));
  EXPECT_TRUE(model.surface().allFinite());
  model.reset();
  EXPECT_EQ(model.surface().rows(), n0);
  EXPECT_EQ(model.surfaceFaces().rows(), 0);
}

TEST(HybridModelLiver, BuildsAndStaysFiniteUnderLargeLoads) {
  Organ organ = phantomOrgan("liver", 0.25);
  HybridModel model;
  model.init(organ, HybridConfig(), &testCache());
  const int top = topVertex(organ.surface);
  for (int s = 0; s < 200; ++s) ASSERT_EQ(model.step(input(top, Vec3(0, 0, -20))), StepStatus::Ok);
  EXPECT_TRUE(model.surface().allFinite());
  const Vec3 d = (model.surface().row(top) - organ.surface.V.row(top)).transpose();
  EXPECT_LT(d.z(), 0);
}

}  // namespace
}  // namespace deform::hybrid
