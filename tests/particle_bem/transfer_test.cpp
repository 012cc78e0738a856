// Tests of the coarse -> fine surface transfer (guided_particles.h): the half-gradient Hermite
// blend with one-ring recovered gradients against the linear interpolation.
#include "../support/meshes.h"
#include "bem_assembly.h"
#include "guided_particles.h"
#include "triangle_distance.h"

#include <gtest/gtest.h>

#include <random>

namespace deform::particle_bem {
namespace {

using testing::icosphere;

// A flat n x n grid in z = 0 whose squares are all split along the same diagonal, so every
// interior vertex has a centrally symmetric one-ring of six triangles.
SurfaceMesh flatGrid(int n, Real h) {
  SurfaceMesh s;
  s.V.resize(n * n, 3);
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) s.V.row(j * n + i) << i * h, j * h, 0;
  s.F.resize(2 * (n - 1) * (n - 1), 3);
  int f = 0;
  for (int j = 0; j + 1 < n; ++j)
    for (int i = 0; i + 1 < n; ++i) {
      const int a = j * n + i, b = a + 1, c = a + n, d = c + 1;
      s.F.row(f++) << a, b, d;
      s.F.row(f++) << a, d, c;
    }
  return s;
}

using Field = Vec3 (*)(const Vec3&);

Vec3 quadratic(const Vec3& x) {
  return Vec3(3 * x[0] * x[0] + 0.5 * x[0] * x[1] - x[1], -2 * x[1] * x[1] + x[0] + 0.1,
              4 * x[0] * x[1] - x[0] * x[0] + 2 * x[1] * x[1]);
}

Vec3 linear(const Vec3& x) {
  return Vec3(0.3 * x[0] - 0.2 * x[1] + 0.01, 0.5 * x[1], -x[0] + 0.4 * x[1] + 0.02 * x[2]);
}

MatX3 sample(const MatX3& V, Field u) {
  MatX3 out(V.rows(), 3);
  for (Eigen::Index v = 0; v < V.rows(); ++v) out.row(v) = u(V.row(v).transpose()).transpose();
  return out;
}

// Random points inside the given triangles, as a SurfaceMap, and their positions.
SurfaceMap randomPoints(const SurfaceMesh& s, const std::vector<int>& triangles, int perTriangle,
                        MatX3& points) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<Real> U(0, 1);
  SurfaceMap m;
  const int n = int(triangles.size()) * perTriangle;
  m.triangle.resize(n);
  m.bary.resize(n, 3);
  points.resize(n, 3);
  for (int q = 0; q < n; ++q) {
    const int t = triangles[q / perTriangle];
    Real a = U(rng), b = U(rng);
    if (a + b > 1) {
      a = 1 - a;
      b = 1 - b;
    }
    m.triangle[q] = t;
    m.bary.row(q) << 1 - a - b, a, b;
    points.row(q) =
        (1 - a - b) * s.V.row(s.F(t, 0)) + a * s.V.row(s.F(t, 1)) + b * s.V.row(s.F(t, 2));
  }
  return m;
}

Real maxError(const MatX3& got, const MatX3& points, Field u) {
  Real e = 0;
  for (Eigen::Index v = 0; v < points.rows(); ++v)
    e = std::max(e, (got.row(v).transpose() - u(points.row(v).transpose())).norm());
  return e;
}

TEST(GradientTransfer, ExactForQuadraticFieldsWhereOneRingsAreSymmetric) {
  const int n = 8;
  const SurfaceMesh g = flatGrid(n, 0.01);
  // Triangles whose three vertices are interior (full one-rings).
  std::vector<int> inner;
  for (int f = 0; f < g.numFaces(); ++f) {
    bool ok = true;
    for (int k = 0; k < 3; ++k) {
      const int v = g.F(f, k), i = v % n, j = v / n;
      ok = ok && i > 0 && j > 0 && i < n - 1 && j < n - 1;
    }
    if (ok) inner.push_back(f);
  }
  ASSERT_GT(inner.size(), 20u);
  MatX3 points;
  const SurfaceMap map = randomPoints(g, inner, 5, points);
  GradientTransfer gt = makeGradientTransfer(g.V, g.F, map);
  const MatX3 nodal = sample(g.V, quadratic), zero = MatX3::Zero(points.rows(), 3);
  MatX3 lin, grad;
  interpolateDisplacement(map, g.F, zero, nodal, lin);
  interpolateDisplacement(map, g.F, zero, nodal, gt, grad);
  const Real linearError = maxError(lin, points, quadratic);
  EXPECT_GT(linearError, 1e-5);  // the linear interpolant does miss the curvature
  EXPECT_LT(maxError(grad, points, quadratic), 1e-12);
}

TEST(GradientTransfer, ReproducesLinearFieldsOnAFlatMeshEverywhere) {
  const SurfaceMesh g = flatGrid(6, 0.02);
  std::vector<int> all(g.numFaces());
  for (int f = 0; f < g.numFaces(); ++f) all[f] = f;
  MatX3 points;
  const SurfaceMap map = randomPoints(g, all, 4, points);
  GradientTransfer gt = makeGradientTransfer(g.V, g.F, map);
  std::vector<Mat3> D;
  recoverGradients(gt, g.F, sample(g.V, linear), D);
  Mat3 A;  // the field's gradient restricted to the plane z = 0
  A << 0.3, -0.2, 0, 0, 0.5, 0, -1, 0.4, 0;
  for (const Mat3& d : D) EXPECT_LT((d - A).norm(), 1e-12);
  MatX3 grad;
  interpolateDisplacement(map, g.F, MatX3::Zero(points.rows(), 3), sample(g.V, linear), gt, grad);
  EXPECT_LT(maxError(grad, points, linear), 1e-14);
}

Vec3 smooth(const Vec3& x) {
  return 1e-3 * Vec3(std::sin(20 * x[0]) + x[1] * 30, std::cos(25 * x[1]) * (1 + 10 * x[2]),
                     std::sin(15 * (x[0] + x[2])));
}

TEST(GradientTransfer, BeatsLinearOnACurvedSurfaceAndKeepsTheRestState) {
  // Coarse icosphere, "fine" vertices: a finer icosphere mapped by closest point, as the model.
  const SurfaceMesh coarse = icosphere(3, 0.05), fine = icosphere(5, 0.05);
  const TriangleGrid grid(coarse.V, coarse.F);
  const SurfaceMap map = mapToSurface(grid, fine.V);
  GradientTransfer gt = makeGradientTransfer(coarse.V, coarse.F, map);
  MatX3 out;
  interpolateDisplacement(map, coarse.F, fine.V, MatX3::Zero(coarse.numVertices(), 3), gt, out);
  EXPECT_EQ((out - fine.V).cwiseAbs().maxCoeff(), 0);  // at rest the fine surface is exact
  // Error of each transfer against the field at the fine vertices (mean over vertices).
  const MatX3 nodal = sample(coarse.V, smooth), exact = sample(fine.V, smooth);
  const MatX3 zero = MatX3::Zero(fine.numVertices(), 3);
  MatX3 lin, grad;
  interpolateDisplacement(map, coarse.F, zero, nodal, lin);
  interpolateDisplacement(map, coarse.F, zero, nodal, gt, grad);
  const Real eLin = (lin - exact).rowwise().norm().mean();
  const Real eGrad = (grad - exact).rowwise().norm().mean();
  EXPECT_GT(eLin, 0);
  EXPECT_LT(eGrad, 0.5 * eLin) << "linear " << eLin << ", gradient " << eGrad;
}

// transferRow is the transfer's matrix row: J u reproduces interpolateDisplacement for an
// arbitrary displacement, linear and gradient, and every row sums to 1.
TEST(TransferRow, IsTheRowOfTheTransferMatrix) {
  const SurfaceMesh coarse = icosphere(2, 0.05), fine = icosphere(4, 0.05);
  const SurfaceMap map = mapToSurface(TriangleGrid(coarse.V, coarse.F), fine.V);
  GradientTransfer gt = makeGradientTransfer(coarse.V, coarse.F, map);
  const MatX3 u = sample(coarse.V, smooth), zero = MatX3::Zero(fine.numVertices(), 3);
  MatX3 lin, grad;
  interpolateDisplacement(map, coarse.F, zero, u, lin);
  interpolateDisplacement(map, coarse.F, zero, u, gt, grad);
  int wide = 0;  // gradient rows reaching past their triangle (not at a coarse vertex)
  for (int v = 0; v < fine.numVertices(); v += 7) {
    for (const bool gradient : {false, true}) {
      const auto row = transferRow(map, coarse.F, gradient ? &gt : nullptr, v);
      Vec3 x = Vec3::Zero();
      Real sum = 0;
      for (const auto& [node, w] : row) {
        x += w * u.row(node).transpose();
        sum += w;
      }
      EXPECT_NEAR(sum, 1.0, 1e-12);
      EXPECT_LT((x - (gradient ? grad : lin).row(v).transpose()).norm(), 1e-15) << v;
      if (gradient) wide += row.size() > 3;  // the corners' one-rings
    }
  }
  EXPECT_GT(wide, 0);
}

// A point force spread as a pressure patch: the shares sum to 1 (the resultant is the force),
// only nodes whose support meets the patch carry load, on a flat symmetric grid the patch about a
// vertex is symmetric and its centre carries the largest share, and the shares do not depend on
// the mesh beyond its resolution (the centroid of the load is the patch centre on both grids).
TEST(PressurePatch, SharesSumToOneStayWithinTheRadiusAndCentreOnThePatch) {
  const Real R = 0.03;
  for (const int n : {21, 41}) {
    SCOPED_TRACE(n);
    const Real h = 0.2 / (n - 1);
    const SurfaceMesh s = flatGrid(n, h);
    const int mid = (n / 2) * n + n / 2;
    const Vec3 c = s.V.row(mid).transpose();
    const auto shares = pressurePatchShares(s, c, R);
    ASSERT_FALSE(shares.empty());
    Real sum = 0, centreShare = 0, largest = 0;
    Vec3 centroid = Vec3::Zero();
    for (const auto& [node, w] : shares) {
      EXPECT_GT(w, 0);
      // A node carries load only if one of its triangles comes within R of c.
      EXPECT_LT((s.V.row(node).transpose() - c).norm(), R + 1.5 * h) << node;
      sum += w;
      centroid += w * s.V.row(node).transpose();
      if (node == mid) centreShare = w;
      largest = std::max(largest, w);
    }
    EXPECT_NEAR(sum, 1.0, 1e-12);
    EXPECT_EQ(centreShare, largest);
    EXPECT_LT((centroid - c).norm(), 1e-3 * R) << "the load's centroid is the patch centre";
  }
  // A patch far smaller than the elements that catches no sample point: empty (the model falls
  // back to the closest triangle), never a division by zero.
  const SurfaceMesh coarse = flatGrid(3, 0.1);
  EXPECT_TRUE(pressurePatchShares(coarse, Vec3(0.1, 0.1, 0), 1e-4).empty());
  EXPECT_TRUE(pressurePatchShares(coarse, Vec3(0.1, 0.1, 0), 0.0).empty());
}

// The consistent patch tractions (PatchTraction::Consistent): the resultant is the force, the
// nodal loads int N_k t_h of the projected field are the patch's shares, and the projected field
// has the patch's spread. On a plane the paraboloid patch t = w / int w has second moment
// int |x - c|^2 t = R^2 / 3; on elements of 2/3 R the lumped form p_k = c_k / A_k spreads the
// load by about an element (larger moment), the consistent one keeps it.
TEST(PressurePatch, ConsistentTractionsKeepTheResultantAndThePatchSpread) {
  const Real R = 0.03, h = 0.02;
  const int n = 15;
  const SurfaceMesh s = flatGrid(n, h);
  const Vec3 c = s.V.row((n / 2) * n + n / 2).transpose();
  const auto shares = pressurePatchShares(s, c, R);
  const PatchProjection proj(s);
  ASSERT_TRUE(proj.ok());
  const VecX q = proj.tractionPerForce(shares);
  const VecX A = nodalAreas(s);
  VecX lumped = VecX::Zero(s.numVertices());
  for (const auto& [k, w] : shares) lumped[k] = w / A[k];
  EXPECT_NEAR(A.dot(q), 1.0, 1e-12);
  EXPECT_NEAR(A.dot(lumped), 1.0, 1e-12);
  const VecX loads = surfaceMassMatrix(s) * q;
  for (const auto& [k, w] : shares) EXPECT_NEAR(loads[k], w, 1e-12);
  // int |x - c|^2 sum_k p_k N_k over the grid (midpoint rule on 16 x 16 sub-triangles).
  const auto secondMoment = [&](const VecX& p) {
    Real m = 0;
    const int sub = 16;
    for (int f = 0; f < s.numFaces(); ++f) {
      const Vec3 v[3] = {s.V.row(s.F(f, 0)).transpose(), s.V.row(s.F(f, 1)).transpose(),
                         s.V.row(s.F(f, 2)).transpose()};
      const Real area = 0.5 * (v[1] - v[0]).cross(v[2] - v[0]).norm() / (sub * sub);
      for (int i = 0; i < sub; ++i)
        for (int j = 0; i + j < sub; ++j)
          for (int up = 0; up < (i + j < sub - 1 ? 2 : 1); ++up) {
            const Real b1 = (i + (up ? 2.0 : 1.0) / 3) / sub, b2 = (j + (up ? 2.0 : 1.0) / 3) / sub;
            const Real b0 = 1 - b1 - b2;
            const Vec3 x = b0 * v[0] + b1 * v[1] + b2 * v[2];
            const Real t = b0 * p[s.F(f, 0)] + b1 * p[s.F(f, 1)] + b2 * p[s.F(f, 2)];
            m += (x - c).squaredNorm() * t * area;
          }
    }
    return m;
  };
  const Real exact = R * R / 3, consistent = secondMoment(q), lump = secondMoment(lumped);
  EXPECT_LT(std::abs(consistent - exact), 0.1 * exact) << consistent << " vs " << exact;
  EXPECT_GT(lump, 1.3 * exact) << "the lumped form spreads the patch";
  EXPECT_LT(std::abs(consistent - exact), 0.5 * std::abs(lump - exact));
}

}  // namespace
}  // namespace deform::particle_bem
