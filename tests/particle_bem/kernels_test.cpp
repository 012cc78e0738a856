// Tests of the particle_bem kernels other than the BEM: distance queries, the distance field,
// spatial hashing, lattice sampling, MLS elasticity, quadric decimation.
#include "../support/meshes.h"
#include "distance_field.h"
#include "physics_points.h"
#include "spatial_hash.h"
#include "sph_elasticity.h"
#include "surface_decimation.h"
#include "triangle_distance.h"

#include <gtest/gtest.h>

#include <random>

namespace deform::particle_bem {
namespace {

using testing::icosphere;

TEST(TriangleDistance, ClosestPointMatchesDenseSampling) {
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(0.2, 0.9, 0.1);
  std::mt19937 rng(3);
  std::uniform_real_distribution<Real> u(-1, 2);
  for (int t = 0; t < 50; ++t) {
    const Vec3 p(u(rng), u(rng), u(rng));
    const TriangleClosestPoint cp = closestPointOnTriangle(p, a, b, c);  // core's, with bary
    const Vec3 q = cp.point, bary = cp.bary;
    EXPECT_NEAR((bary[0] * a + bary[1] * b + bary[2] * c - q).norm(), 0, 1e-12);
    EXPECT_NEAR(bary.sum(), 1, 1e-12);
    EXPECT_GE(bary.minCoeff(), 0);
    // Exactly zero weights off the feature: the grid's sign test relies on the feature.
    const int zeros = int((bary.array() == 0).count());
    const bool vertex = cp.feature == TriangleFeature::VertexA ||
                        cp.feature == TriangleFeature::VertexB ||
                        cp.feature == TriangleFeature::VertexC;
    EXPECT_EQ(zeros, cp.feature == TriangleFeature::Face ? 0 : vertex ? 2 : 1);
    Real best = 1e30;
    for (int i = 0; i <= 200; ++i)
      for (int j = 0; i + j <= 200; ++j) {
        const Vec3 y = a + (b - a) * (i / 200.0) + (c - a) * (j / 200.0);
        best = std::min(best, (y - p).norm());
      }
    EXPECT_LE((q - p).norm(), best + 1e-12);
    EXPECT_GE((q - p).norm(), best - 0.01);
  }
}

TEST(TriangleDistance, DegenerateTriangleBarycentricsReproduceThePoint) {
  // Collinear corners: core falls back to the nearest edge; the weights must still give the point.
  const Vec3 a(0, 0, 0), b(1, 0, 0), c(2, 0, 0), p(1.5, 0.3, 0);
  const TriangleClosestPoint cp = closestPointOnTriangle(p, a, b, c);
  EXPECT_NEAR((cp.point - Vec3(1.5, 0, 0)).norm(), 0, 1e-12);
  EXPECT_NEAR((cp.bary[0] * a + cp.bary[1] * b + cp.bary[2] * c - cp.point).norm(), 0, 1e-12);
  EXPECT_NEAR(cp.bary.sum(), 1, 1e-12);
}

TEST(DistanceField, SphereSignedDistance) {
  const SurfaceMesh s = icosphere(4, 0.05);
  const TriangleGrid grid(s.V, s.F);
  const SignedDistanceField sdf(grid, 32, 0.01);
  std::mt19937 rng(5);
  std::uniform_real_distribution<Real> u(-0.055, 0.055);
  for (int t = 0; t < 200; ++t) {
    const Vec3 p(u(rng), u(rng), u(rng));
    const Real exact = p.norm() - 0.05;
    // Exact to the facets (chord error ~ 0.05 (1 - cos(0.08)) ~ 2e-4) at the grid nodes;
    // trilinear interpolation between them adds O(h^2 / r).
    EXPECT_NEAR(grid.signedDistance(p), exact, 3e-4);
    EXPECT_NEAR(sdf.value(p), exact, 1.5e-3);
    if (std::abs(exact) > 3e-3) {
      EXPECT_EQ(sdf.value(p) < 0, exact < 0);
    }
  }
  Vec3 p(0.0, 0.0, 0.03);
  EXPECT_TRUE(sdf.pushOut(p, 0.0));
  EXPECT_NEAR(p.norm(), 0.05, 2e-3);
  EXPECT_GT(sdf.gradient(Vec3(0.04, 0, 0)).dot(Vec3::UnitX()), 0.9);
}

TEST(SpatialHash, PairsMatchBruteForce) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<Real> u(-1, 1);
  MatX3 P(400, 3);
  for (int i = 0; i < 400; ++i) P.row(i) = Vec3(u(rng), u(rng), u(rng)).transpose();
  SpatialHash h(0.2, 97);  // small table: many collisions, still correct
  h.build(P);
  std::vector<std::pair<int, int>> pairs;
  h.pairsWithin(0.2, pairs);
  std::sort(pairs.begin(), pairs.end());
  std::vector<std::pair<int, int>> brute;
  for (int i = 0; i < 400; ++i)
    for (int j = i + 1; j < 400; ++j)
      if ((P.row(i) - P.row(j)).norm() < 0.2) brute.emplace_back(i, j);
  EXPECT_EQ(pairs, brute);
  EXPECT_GT(brute.size(), 100u);
}

TEST(PhysicsPoints, LatticeInsideSphereNearTargetCount) {
  const SurfaceMesh s = icosphere(3, 0.05);
  const TriangleGrid grid(s.V, s.F);
  const SignedDistanceField sdf(grid, 32, 0.01);
  const PhysicsPoints pts = sampleLatticeInside(sdf, s.V, signedVolume(s.V, s.F), 500, 0.0);
  EXPECT_NEAR(double(pts.points.rows()), 500.0, 50.0);
  for (Eigen::Index i = 0; i < pts.points.rows(); ++i) EXPECT_LT(pts.points.row(i).norm(), 0.05);
}

// A cubic lattice block for the MLS tests.
MatX3 block(int n, Real s) {
  MatX3 P(n * n * n, 3);
  int r = 0;
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) P.row(r++) = Vec3(i * s, j * s, k * s).transpose();
  return P;
}

TEST(MlsElasticity, RestHasNoForce) {
  const MatX3 X = block(6, 0.01);
  const MlsElasticity m = initMlsElasticity(X, 0.02, VecX::Constant(X.rows(), 1e-6), 5000, 0.3);
  std::vector<Mat3> F;
  mlsDeformationGradients(m, X, X, F);
  MatX3 f;
  mlsForces(m, F, f);
  EXPECT_LT(f.cwiseAbs().maxCoeff(), 1e-12);
}

TEST(MlsElasticity, UniaxialStretchGivesHookeanStress) {
  const Real E = 5000, nu = 0.3, e = 0.01;
  const MatX3 X = block(6, 0.01);
  const MlsElasticity m = initMlsElasticity(X, 0.02, VecX::Constant(X.rows(), 1e-6), E, nu);
  MatX3 x = X;
  x.col(0) *= 1 + e;
  std::vector<Mat3> F;
  mlsDeformationGradients(m, X, x, F);
  // Independent Hooke law (eq. 1) for the Green strain E_xx = ((1+e)^2 - 1)/2, others zero:
  // S_xx = E (1 - nu) / ((1 + nu)(1 - 2 nu)) E_xx, S_yy = S_zz = E nu / ((1 + nu)(1 - 2 nu)) E_xx.
  const Real Exx = 0.5 * ((1 + e) * (1 + e) - 1);
  const Real Sxx = E * (1 - nu) / ((1 + nu) * (1 - 2 * nu)) * Exx;
  const Real Syy = E * nu / ((1 + nu) * (1 - 2 * nu)) * Exx;
  for (size_t i = 0; i < F.size(); ++i) {
    const Mat3 S = hookeStress(F[i], m.lambda, m.mu);
    EXPECT_NEAR(S(0, 0), Sxx, 1e-6 * Sxx);
    EXPECT_NEAR(S(1, 1), Syy, 1e-6 * Sxx);
    EXPECT_NEAR(S(0, 1), 0, 1e-6 * Sxx);
  }
  // Homogeneous strain: no net force on particles whose whole support is inside the block.
  MatX3 f;
  mlsForces(m, F, f);
  const Real edgeForce = f.cwiseAbs().maxCoeff();
  EXPECT_GT(edgeForce, 0);
  for (Eigen::Index i = 0; i < X.rows(); ++i) {
    const Vec3 p = X.row(i);
    if ((p.array() > 0.015).all() && (p.array() < 0.035).all()) {
      EXPECT_LT(f.row(i).norm(), 1e-9 * edgeForce) << i;
    }
  }
}

TEST(MlsElasticity, ForcesAreMinusEnergyGradientAndConserveMomentum) {
  const MatX3 X = block(4, 0.01);
  const MlsElasticity m = initMlsElasticity(X, 0.02, VecX::Constant(X.rows(), 1e-6), 5000, 0.3);
  std::mt19937 rng(11);
  std::normal_distribution<Real> g(0, 1e-3);
  MatX3 x = X;
  for (Eigen::Index i = 0; i < x.rows(); ++i) x.row(i) += Vec3(g(rng), g(rng), g(rng)).transpose();
  std::vector<Mat3> F;
  mlsDeformationGradients(m, X, x, F);
  MatX3 f;
  mlsForces(m, F, f);
  EXPECT_LT(f.colwise().sum().norm(), 1e-10 * f.cwiseAbs().maxCoeff());
  // Angular momentum: sum x_i x f_i = 0 for a rotation-invariant energy.
  Vec3 torque = Vec3::Zero();
  for (Eigen::Index i = 0; i < x.rows(); ++i)
    torque += x.row(i).transpose().cross(f.row(i).transpose());
  EXPECT_LT(torque.norm(), 1e-9 * f.cwiseAbs().maxCoeff() * 0.03);
  const Real h = 1e-7;
  for (int i : {0, 21, 42}) {
    for (int k = 0; k < 3; ++k) {
      MatX3 xp = x, xm = x;
      xp(i, k) += h;
      xm(i, k) -= h;
      std::vector<Mat3> Fp, Fm;
      mlsDeformationGradients(m, X, xp, Fp);
      mlsDeformationGradients(m, X, xm, Fm);
      const Real fd = -(mlsEnergy(m, Fp) - mlsEnergy(m, Fm)) / (2 * h);
      EXPECT_NEAR(f(i, k), fd, 1e-5 * f.cwiseAbs().maxCoeff() + 1e-4 * std::abs(fd));
    }
  }
}

TEST(SurfaceDecimation, KeepsClosedManifoldAndShape) {
  const SurfaceMesh fine = testing::ellipsoid(4, Vec3(0.08, 0.05, 0.03));  // 2562 vertices
  DecimationStats st;
  const SurfaceMesh c = decimateQuadric(fine, 300, &st);
  EXPECT_EQ(c.numVertices(), 300);
  EXPECT_EQ(c.numFaces(), 2 * 300 - 4);  // Euler: closed genus 0
  EXPECT_EQ(testing::badEdges(c), 0);
  EXPECT_NEAR(signedVolume(c.V, c.F) / signedVolume(fine.V, fine.F), 1.0, 0.03);
  // Every coarse vertex stays near the fine surface.
  const TriangleGrid g(fine.V, fine.F);
  for (int v = 0; v < c.numVertices(); ++v) EXPECT_LT(g.closest(c.V.row(v)).distance, 2e-3);
}

}  // namespace
}  // namespace deform::particle_bem
