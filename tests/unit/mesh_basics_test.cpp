#include <deform/sdk/mesh.h>
#include <deform/sdk/model.h>
#include <gtest/gtest.h>

#include <stdexcept>
#include <vector>

namespace deform {
namespace {

SurfaceMesh unitTetSurface() {
  SurfaceMesh m;
  m.V.resize(4, 3);
  m.V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1;
  m.F.resize(4, 3);
  m.F << 0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3;
  return m;
}

TEST(MeshBasics, TetSurfaceVolumeAndEdges) {
  const SurfaceMesh m = unitTetSurface();
  EXPECT_NEAR(signedVolume(m.V, m.F), 1.0 / 6.0, 1e-15);
  const MatX2i E = uniqueEdges(m.F);
  EXPECT_EQ(E.rows(), 6);
  const MatX2i EF = edgeFaces(m.F, E);
  for (Eigen::Index e = 0; e < E.rows(); ++e) {
    EXPECT_GE(EF(e, 0), 0);
    EXPECT_GE(EF(e, 1), 0);
    EXPECT_NE(EF(e, 0), EF(e, 1));
  }
}

TEST(MeshBasics, TetBoundaryOfOneTetIsOutward) {
  TetMesh t;
  t.V = unitTetSurface().V;
  t.T.resize(1, 4);
  t.T << 0, 1, 2, 3;
  ASSERT_GT(tetVolume(t.V.row(0), t.V.row(1), t.V.row(2), t.V.row(3)), 0);
  const SurfaceMesh b = tetBoundary(t);
  EXPECT_EQ(b.F.rows(), 4);
  EXPECT_NEAR(signedVolume(b.V, b.F), 1.0 / 6.0, 1e-15);
}

TEST(MeshBasics, NearestVerticesDeterministicTies) {
  MatX3 V(4, 3);
  V << 1, 0, 0, -1, 0, 0, 0, 2, 0, 0, 0, 0.5;
  const auto idx = nearestVertices(V, Vec3::Zero(), 3);
  ASSERT_EQ(idx.size(), 3u);
  EXPECT_EQ(idx[0], 3);
  EXPECT_EQ(idx[1], 0);  // tie between 0 and 1 broken by index
  EXPECT_EQ(idx[2], 1);
  EXPECT_EQ(nearestVertex(V, Vec3(0, 1.9, 0)), 2);
}

TEST(MeshBasics, RowsInBoxKeepTheBoundaryInAscendingOrder) {
  MatX3 V(4, 3);
  V << 1, 1, 1, 0.5, 0.5, 0.5, 2, 0, 0, 0, 0, 0;
  const Box b{Vec3::Zero(), Vec3::Ones()};
  EXPECT_EQ(rowsInBox(V, b), (std::vector<int>{0, 1, 3}));
  EXPECT_TRUE(rowsInBox(V, Box{Vec3::Constant(3), Vec3::Constant(4)}).empty());
}

TEST(ModelHelpers, FacesOnNodesAndInverseMasses) {
  MatX3i F(2, 3);
  F << 0, 1, 2, 2, 1, 3;
  EXPECT_EQ(facesOnNodes(F, {}), F);  // vertex i is node i
  MatX3i onNodes(2, 3);
  onNodes << 7, 5, 6, 6, 5, 4;
  EXPECT_EQ(facesOnNodes(F, {7, 5, 6, 4}), onNodes);
  EXPECT_THROW(facesOnNodes(F, {7, 5, 6}), std::out_of_range);
  VecX mass(4);
  mass << 2, 0, 4, 0.5;
  const VecX w = inverseMasses(mass, {2});
  EXPECT_EQ(w, (VecX(4) << 0.5, 0, 0, 2).finished());  // massless and fixed nodes immovable
}

}  // namespace
}  // namespace deform
