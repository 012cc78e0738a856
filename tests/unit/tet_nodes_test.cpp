// Surface vertex -> tet node map and tet mesh measures (core/include/deform/tet_nodes.h): the
// values every tet-based model (pbd, massspring, bullet_deformable) derives from a tet file.
#include <deform/error.h>
#include <deform/organ_tets.h>
#include <deform/tet_embedding.h>
#include <deform/tet_nodes.h>
#include <gtest/gtest.h>

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
