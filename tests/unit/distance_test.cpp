#include <deform/geometry/distance.h>
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "../metaballs/test_meshes.h"

namespace deform {
namespace {

// Generalised winding number (sum of signed solid angles / 4 pi), brute force.
Real windingNumber(const SurfaceMesh& m, const Vec3& p) {
  Real w = 0;
  for (int f = 0; f < m.numFaces(); ++f) {
    const Vec3 a = m.V.row(m.F(f, 0)).transpose() - p, b = m.V.row(m.F(f, 1)).transpose() - p,
               c = m.V.row(m.F(f, 2)).transpose() - p;
    const Real la = a.norm(), lb = b.norm(), lc = c.norm();
    w += 2 * std::atan2(a.dot(b.cross(c)),
                        la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb);
  }
  return w / (4 * M_PI);
}

TEST(Distance, ClosestPointOnTriangleMatchesDenseSampling) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<Real> u(-1, 1);
  for (int trial = 0; trial < 200; ++trial) {
    const Vec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng)), c(u(rng), u(rng), u(rng));
    const Vec3 p(2 * u(rng), 2 * u(rng), 2 * u(rng));
    const TriangleClosestPoint cp = closestPointOnTriangle(p, a, b, c);
    EXPECT_NEAR(cp.dist2, (p - cp.point).squaredNorm(), 1e-12);
    Real best = 1e30;
    const int n = 200;
    for (int i = 0; i <= n; ++i)
      for (int j = 0; j <= n - i; ++j) {
        const Vec3 q = a + (b - a) * (Real(i) / n) + (c - a) * (Real(j) / n);
        best = std::min(best, (p - q).norm());
      }
    // The exact distance is never larger than any sample's and close to the best one.
    EXPECT_LE(std::sqrt(cp.dist2), best + 1e-12);
    EXPECT_NEAR(std::sqrt(cp.dist2), best, 0.02);
  }
}

TEST(Distance, BvhEqualsBruteForceAndSignMatchesWindingNumber) {
  const SurfaceMesh m = metaballs::test::banana(0.2, 0.03, 0.1, 3);
  const MeshDistance dist(m);
  std::mt19937 rng(3);
  std::uniform_real_distribution<Real> u(-0.12, 0.12);
  int inside = 0;
  for (int trial = 0; trial < 300; ++trial) {
    const Vec3 p(u(rng), 0.4 * u(rng), 0.4 * u(rng));
    Real brute = 1e30;
    for (int f = 0; f < m.numFaces(); ++f)
      brute = std::min(brute, closestPointOnTriangle(p, m.V.row(m.F(f, 0)), m.V.row(m.F(f, 1)),
                                                     m.V.row(m.F(f, 2)))
                                  .dist2);
    const MeshDistance::Result r = dist.closest(p);
    EXPECT_DOUBLE_EQ(r.distance, std::sqrt(brute));
    const bool in = windingNumber(m, p) > 0.5;
    inside += in ? 1 : 0;
    EXPECT_EQ(dist.inside(p), in) << p.transpose();
    EXPECT_NEAR(std::abs(dist.signedDistance(p)), r.distance, 1e-15);
  }
  EXPECT_GT(inside, 10);  // the sample really probes both sides
  EXPECT_LT(inside, 290);
}

TEST(Distance, SignAtVerticesAndEdgesOfAConvexMesh) {
  // Points just inside/outside along the vertex normals: the closest feature is a vertex, where a
  // face-normal sign test alone can fail.
  const SurfaceMesh m = testing::icosphere(1);
  const MeshDistance dist(m);
  for (int i = 0; i < m.numVertices(); ++i) {
    const Vec3 v = m.V.row(i);
    EXPECT_TRUE(dist.inside(0.999 * v));
    EXPECT_FALSE(dist.inside(1.001 * v));
  }
}

}  // namespace
}  // namespace deform
