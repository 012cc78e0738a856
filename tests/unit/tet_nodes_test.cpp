// Surface vertex -> tet node map and tet mesh measures (core/include/deform/geometry/tet_nodes.h):
// the values every tet-based model (pbd, massspring, bullet_deformable) derives from a tet file.
#include <deform/geometry/organ_tets.h>
#include <deform/geometry/tet_embedding.h>
#include <deform/geometry/tet_nodes.h>
#include <deform/sdk/error.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <map>

namespace deform {
namespace {

/// A cube split into 5 tets, positively oriented (nodes 0..7, x fastest).
TetMesh fiveTetCube(Real side) {
  TetMesh m;
  m.V.resize(8, 3);
  for (int i = 0; i < 8; ++i) m.V.row(i) << side * (i & 1), side * ((i >> 1) & 1), side * (i >> 2);
  m.T.resize(5, 4);
  m.T << 0, 1, 2, 4,  //
      1, 3, 2, 7,     //
      1, 2, 4, 7,     //
      2, 4, 7, 6,     //
      1, 4, 5, 7;
  for (int t = 0; t < 5; ++t)
    if (tetVolume(m.V.row(m.T(t, 0)), m.V.row(m.T(t, 1)), m.V.row(m.T(t, 2)), m.V.row(m.T(t, 3))) <
        0)
      std::swap(m.T(t, 2), m.T(t, 3));
  return m;
}

TEST(TetMeasures, VolumesMassesAndEdgeSharesOfAFiveTetCube) {
  const Real side = 0.02, rho = 1000;
  const TetMesh m = fiveTetCube(side);
  const TetMeasures tm = measureTets(m, rho, "cube.msh");
  const Real v = side * side * side;
  EXPECT_NEAR(tm.tetVolume.sum(), v, 1e-18);
  EXPECT_NEAR(tm.tetVolume[2], v / 3, 1e-18) << "the central tet is a third of the cube";
  EXPECT_NEAR(tm.nodeMass.sum(), rho * v, 1e-15);
  // Corner 0 is in one corner tet (v/6): mass rho v / 24.
  EXPECT_NEAR(tm.nodeMass[0], rho * v / 24, 1e-15);
  // 12 cube edges + 6 face diagonals, each once, sorted, a < b.
  ASSERT_EQ(tm.edges.rows(), 18);
  for (Eigen::Index e = 0; e < tm.edges.rows(); ++e) {
    EXPECT_LT(tm.edges(e, 0), tm.edges(e, 1));
    if (e > 0) {
      EXPECT_TRUE(tm.edges(e - 1, 0) < tm.edges(e, 0) ||
                  (tm.edges(e - 1, 0) == tm.edges(e, 0) && tm.edges(e - 1, 1) < tm.edges(e, 1)));
    }
  }
  // Cube edge 0-1 belongs to the corner tet at 0 only: v / 6; face diagonal 1-2 to the corner
  // tets at 0 and 3 and the central one: v / 6 + v / 6 + v / 3.
  for (Eigen::Index e = 0; e < tm.edges.rows(); ++e) {
    if (tm.edges(e, 0) == 0 && tm.edges(e, 1) == 1) {
      EXPECT_NEAR(tm.edgeVolume[e], v / 6, 1e-18);
    }
    if (tm.edges(e, 0) == 1 && tm.edges(e, 1) == 2) {
      EXPECT_NEAR(tm.edgeVolume[e], 2 * v / 3, 1e-18);
    }
  }
}

TEST(TetMeasures, AnInvertedTetOrABadIndexIsAnInputErrorNamingTheTet) {
  TetMesh m = fiveTetCube(0.02);
  std::swap(m.T(0, 0), m.T(0, 1));  // inverted
  try {
    measureTets(m, 1000, "cube.msh");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    const std::string w = e.what();
    EXPECT_NE(w.find("cube.msh"), std::string::npos) << w;
    EXPECT_NE(w.find("tet 0"), std::string::npos) << w;
  }
  m = fiveTetCube(0.02);
  m.T(3, 2) = 8;
  EXPECT_THROW(measureTets(m, 1000, "cube.msh"), InputError);
}

TEST(TetMeasures, InvertedTetsCountsTheElementsTurnedInsideOut) {
  const TetMesh m = fiveTetCube(0.02);
  EXPECT_EQ(invertedTets(m.T, m.V), 0);
  // Corner 0 belongs to the corner tet (0, 1, 2, 4) only: pushed through the opposite face
  // (the plane x + y + z = side), that tet alone turns inside out.
  MatX3 x = m.V;
  x.row(0) = Vec3::Constant(0.02);
  EXPECT_EQ(invertedTets(m.T, x), 1);
  // Flattened onto that face (exactly: x1 - x0 = -(x2 - x0)): zero volume counts too.
  x.row(0) = Vec3(0.01, 0.01, 0);
  EXPECT_EQ(invertedTets(m.T, x), 1);
  // A mirror image of the whole cube inverts all five.
  x = m.V;
  x.col(0) *= -1;
  EXPECT_EQ(invertedTets(m.T, x), 5);
}

TEST(SurfaceVertexNodes, PrefixIdentityPermutedNodesAndAVertexOffTheMesh) {
  const TetMesh m = fiveTetCube(0.02);
  Organ organ;
  organ.source = "cube.msh";
  organ.surface.V = m.V.topRows(4);
  organ.surface.F.resize(2, 3);
  organ.surface.F << 0, 1, 2, 1, 3, 2;
  EXPECT_EQ(surfaceVertexNodes(organ, m.V), (std::vector<int>{0, 1, 2, 3}));
  // Surface vertices in another order than the nodes: found by position.
  organ.surface.V = m.V({7, 2, 5}, Eigen::all);
  EXPECT_EQ(surfaceVertexNodes(organ, m.V), (std::vector<int>{7, 2, 5}));
  // A vertex 1 mm from every node: an error naming the file and the vertex.
  organ.surface.V(1, 0) += 1e-3;
  try {
    surfaceVertexNodes(organ, m.V);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    const std::string w = e.what();
    EXPECT_NE(w.find("cube.msh"), std::string::npos) << w;
    EXPECT_NE(w.find("vertex 1"), std::string::npos) << w;
  }
}

// A uniform traction on the cube's top face, lumped the linear way (a third of each triangle's
// force on each corner), comes back as the quadratic faces' consistent load: nothing on the
// corners, a third of each triangle's force on each of its midside nodes, the total kept. A
// share on a node with no loaded triangle stays where it is.
TEST(QuadraticSurfaceLoad, UniformTractionGoesToTheMidsideNodes) {
  const TetMesh cube = fiveTetCube(1.0);
  const QuadraticTetNodes q = addMidsideNodes(cube);
  const QuadraticSurfaceLoad load(cube, [&q](int a, int b) { return q.edgeNode(a, b); });
  const Vec3 t(0.3, 0, -1);  // Pa on the 1 m^2 top face (nodes 4..7): its two triangles
  std::vector<std::pair<int, Vec3>> lumped;
  const SurfaceMesh boundary = tetBoundary(cube);
  for (int f = 0; f < boundary.numFaces(); ++f) {
    bool top = true;
    for (int k = 0; k < 3; ++k) top = top && boundary.F(f, k) >= 4;
    if (!top) continue;
    for (int k = 0; k < 3; ++k) lumped.emplace_back(boundary.F(f, k), t * 0.5 / 3);
  }
  ASSERT_EQ(lumped.size(), 6u);
  lumped.emplace_back(0, Vec3(0, 0, 2));  // a bottom corner alone: no loaded triangle
  std::map<int, Vec3> spread;
  Vec3 total = Vec3::Zero();
  for (const auto& [node, f] : load.spread(lumped)) {
    spread.try_emplace(node, Vec3::Zero()).first->second += f;
    total += f;
  }
  EXPECT_NEAR((total - (t + Vec3(0, 0, 2))).norm(), 0, 1e-12);
  EXPECT_NEAR((spread[0] - Vec3(0, 0, 2)).norm(), 0, 1e-12);
  for (int c = 4; c < 8; ++c) EXPECT_NEAR(spread[c].norm(), 0, 1e-12) << "corner " << c;
  // The top face's diagonal is shared by both triangles; its four sides by one each.
  int sides = 0, diagonals = 0;
  for (const auto& [node, f] : spread) {
    if (node < 8) continue;
    if ((f - t / 6).norm() < 1e-12) ++sides;
    if ((f - t / 3).norm() < 1e-12) ++diagonals;
  }
  EXPECT_EQ(sides, 4);
  EXPECT_EQ(diagonals, 1);
}

// A grasp of the cube's four top vertices holds the five midside nodes of the top face's two
// triangles at the midpoints of their edges; a grasp of the two ends of an edge, its midside.
TEST(GraspedPatchNodes, HoldsTheMidsideNodesOfGraspedTrianglesAndEdges) {
  const TetMesh cube = fiveTetCube(1.0);
  const QuadraticTetNodes q = addMidsideNodes(cube);
  const SurfaceMesh surface = tetBoundary(cube);
  std::vector<int> boundary;
  for (int n = 0; n < int(q.V.rows()); ++n) boundary.push_back(n);  // every node a candidate
  const GraspedPatchNodes patch(surface, {0, 1, 2, 3, 4, 5, 6, 7}, q.V, boundary);
  const auto top = patch.held({4, 5, 6, 7});
  ASSERT_EQ(top.size(), 5u);
  for (const auto& h : top) {
    EXPECT_GE(h.node, 8);
    EXPECT_NEAR(q.V(h.node, 2), 1.0, 1e-12);  // on the top face
    Vec3 x = Vec3::Zero();
    for (int k = 0; k < 3; ++k) x += h.weights(k) * q.V.row(h.vertices[size_t(k)]).transpose();
    EXPECT_NEAR((x - q.V.row(h.node).transpose()).norm(), 0, 1e-12);
  }
  // Two grasped vertices of a surface edge hold its midside node; two that share no edge,
  // nothing.
  const auto edge = patch.held({4, 5});
  ASSERT_EQ(edge.size(), 1u);
  EXPECT_NEAR((q.V.row(edge[0].node) - 0.5 * (q.V.row(4) + q.V.row(5))).norm(), 0, 1e-12);
  EXPECT_TRUE(patch.held({5, 6}).empty());
  // nodes(): the four vertices' own nodes and the five held, sorted, each once.
  std::vector<int> all = {4, 5, 6, 7};
  for (const auto& h : top) all.push_back(h.node);
  std::sort(all.begin(), all.end());
  EXPECT_EQ(patch.nodes({7, 5, 4, 6, 4}), all);
}

TEST(TetEmbedding, PointsFollowAnAffineMapExactlyLinearAndQuadratic) {
  const TetMesh m = fiveTetCube(0.02);
  MatX3 pts(4, 3);
  pts << 0.005, 0.006, 0.007,  //
      0.019, 0.001, 0.0185,    //
      0.01, 0.01, 0.01,        //
      0.03, 0.01, 0.01;        // outside the cube: extrapolated from the nearest tet
  const TetEmbedding e = embedInTets(m.V, m.T, pts);
  EXPECT_EQ(e.numOutside(), 1);
  EXPECT_GT(e.outside[3], 0);
  for (int p = 0; p < 3; ++p) {
    Real sum = 0;
    for (Real w : e.weights[size_t(p)]) {
      EXPECT_GE(w, -1e-9);
      sum += w;
    }
    EXPECT_NEAR(sum, 1, 1e-12);
  }
  // An affine deformation x -> A x + b moves every embedded point (outside ones too) exactly.
  Mat3 A;
  A << 1.1, 0.2, 0, -0.1, 0.9, 0.05, 0, 0.3, 1.2;
  const Vec3 b(0.001, -0.002, 0.003);
  const auto affine = [&](const MatX3& X) {
    MatX3 Y = (X * A.transpose()).rowwise() + b.transpose();
    return Y;
  };
  EXPECT_TRUE(embeddedPositions(e, affine(m.V), m.T).isApprox(affine(pts), 1e-12));
  // 10-node tets with straight sides: the midside nodes at the edge midpoints; a quadratic map
  // of the nodes is reproduced at the points as well.
  const QuadraticTetNodes q = addMidsideNodes(m);
  const auto quadratic = [](const MatX3& X) {
    MatX3 Y = X;
    for (Eigen::Index i = 0; i < X.rows(); ++i)
      Y(i, 2) += 3 * X(i, 0) * X(i, 1) + X(i, 0) * X(i, 0);
    return Y;
  };
  const MatX3 moved =
      embeddedPositionsQuadratic(e, quadratic(q.V), [&](int t, int a) { return q.elements(t, a); });
  EXPECT_TRUE(moved.topRows(3).isApprox(quadratic(pts).topRows(3), 1e-12));
  EXPECT_THROW(embedInTets(m.V, MatX4i(0, 4), pts), InputError);
}

}  // namespace
}  // namespace deform
