#include <deform/geometry/kdtree.h>
#include <deform/sdk/mesh.h>
#include <gtest/gtest.h>

#include <random>

namespace deform {
namespace {

TEST(KdTree3, KnnAndRadiusEqualBruteForce) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<Real> u(0, 1);
  MatX3 pts(500, 3);
  for (Eigen::Index i = 0; i < pts.rows(); ++i) pts.row(i) << u(rng), u(rng), u(rng);
  // Duplicates test the tie-breaking by index.
  pts.row(10) = pts.row(20);
  const KdTree3 tree(pts);
  std::vector<int> idx;
  std::vector<Real> d2;
  for (int q = 0; q < 50; ++q) {
    const Vec3 p = q == 0 ? Vec3(pts.row(20).transpose()) : Vec3(u(rng), u(rng), u(rng));
    tree.knn(p, 7, idx, &d2);
    EXPECT_EQ(idx, nearestVertices(pts, p, 7));
    for (size_t k = 0; k < idx.size(); ++k)
      EXPECT_DOUBLE_EQ(d2[k], (pts.row(idx[k]).transpose() - p).squaredNorm());
    const Real r = 0.2;
    tree.radius(p, r, idx);
    std::vector<int> brute;
    for (Eigen::Index i = 0; i < pts.rows(); ++i)
      if ((pts.row(i).transpose() - p).norm() <= r) brute.push_back(int(i));
    std::vector<int> sorted = idx;
    std::sort(sorted.begin(), sorted.end());
    EXPECT_EQ(sorted, brute);
    for (size_t k = 1; k < idx.size(); ++k)
      EXPECT_LE((pts.row(idx[k - 1]).transpose() - p).norm(),
                (pts.row(idx[k]).transpose() - p).norm());
    EXPECT_EQ(tree.nearest(p), nearestVertex(pts, p));
  }
  KdTree3 empty;
  EXPECT_EQ(empty.nearest(Vec3::Zero()), -1);
  empty.knn(Vec3::Zero(), 3, idx);
  EXPECT_TRUE(idx.empty());
}

}  // namespace
}  // namespace deform
