// Tests of the BEM kernels: Kelvin solutions, quadrature, assembly, M, the loss ratio.
#include "../support/meshes.h"
#include "bem_accuracy.h"
#include "bem_assembly.h"
#include "bem_kelvin.h"
#include "sph_elasticity.h"

#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <random>

namespace deform::particle_bem {
namespace {

using testing::icosphere;

TEST(Kelvin, TractionKernelIsStressOfDisplacementKernelTimesNormal) {
  const Real E = 5000, nu = 0.3;
  const KelvinKernel K(E, nu);
  Real lambda, mu;
  lame(E, nu, lambda, mu);
  std::mt19937 rng(1);
  std::normal_distribution<Real> g(0, 0.03);
  for (int t = 0; t < 10; ++t) {
    const Vec3 r(g(rng), g(rng), g(rng));  // y - x with x = 0
    const Vec3 n = Vec3(g(rng), g(rng), g(rng)).normalized();
    const Mat3 T = K.traction(r, n);
    const Real h = 1e-6 * r.norm();
    for (int i = 0; i < 3; ++i) {  // unit force along i at x: u_k(y) = U*_ik(y)
      Mat3 grad;                   // grad(k, l) = d u_k / d y_l
      for (int l = 0; l < 3; ++l) {
        const Vec3 dp = K.displacement(r + h * Vec3::Unit(l)).row(i).transpose();
        const Vec3 dm = K.displacement(r - h * Vec3::Unit(l)).row(i).transpose();
        grad.col(l) = (dp - dm) / (2 * h);
      }
      const Mat3 eps = 0.5 * (grad + grad.transpose());
      const Mat3 sigma = lambda * eps.trace() * Mat3::Identity() + 2 * mu * eps;
      const Vec3 traction = sigma * n;
      EXPECT_LT((T.row(i).transpose() - traction).norm(), 1e-6 * traction.norm() + 1e-9)
          << "force direction " << i;
    }
  }
}

TEST(Kelvin, DisplacementKernelSolvesNavierAwayFromSource) {
  // Equilibrium: div sigma(U*) = 0 for y != x, checked with the traction kernel on a small cube:
  // the net traction on the faces of a cube not containing the source vanishes.
  const KelvinKernel K(5000, 0.3);
  const Vec3 c(0.02, -0.01, 0.015);
  const Real a = 0.002;
  std::vector<Real> x, w;
  gaussLegendre01(8, x, w);
  Vec3 net = Vec3::Zero(), scale = Vec3::Zero();
  for (int axis = 0; axis < 3; ++axis)
    for (int side : {-1, 1}) {
      const Vec3 n = side * Vec3::Unit(axis);
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      for (int p = 0; p < 8; ++p)
        for (int q = 0; q < 8; ++q) {
          Vec3 y = c + 0.5 * a * n;
          y[u] += a * (x[p] - 0.5);
          y[v] += a * (x[q] - 0.5);
          const Vec3 t = K.traction(y, n).row(0).transpose() * w[p] * w[q] * a * a;
          net += t;
          scale += t.cwiseAbs();
        }
    }
  EXPECT_LT(net.norm(), 1e-8 * scale.norm());
}

Real monomialIntegral(int a, int b) {  // over (0,0),(1,0),(0,1)
  return std::tgamma(a + 1) * std::tgamma(b + 1) / std::tgamma(a + b + 3);
}

TEST(Quadrature, SevenPointRuleExactToDegreeFive) {
  Real worstDegree6 = 0;
  for (int a = 0; a <= 6; ++a)
    for (int b = 0; a + b <= 6; ++b) {
      Real sum = 0;
      for (const TrianglePoint& p : gaussTriangle7())
        sum += p.w * 0.5 * std::pow(p.l1, a) * std::pow(p.l2, b);
      const Real err = std::abs(sum - monomialIntegral(a, b));
      if (a + b <= 5)
        EXPECT_LT(err, 1e-15) << a << " " << b;
      else
        worstDegree6 = std::max(worstDegree6, err);
    }
  EXPECT_GT(worstDegree6, 1e-6);  // a degree-5 rule, not more
}

TEST(Quadrature, DuffyRuleIntegratesInverseDistanceFromVertex) {
  // int over (0,0),(1,0),(0,1) of 1/|y| dA = int_0^{pi/2} dtheta / (cos + sin) = sqrt2 ln(1+sqrt2).
  Real sum = 0;
  for (const TrianglePoint& p : duffyTriangle(6)) sum += p.w * 0.5 / std::hypot(p.l1, p.l2);
  EXPECT_NEAR(sum, std::sqrt(2.0) * std::log(1 + std::sqrt(2.0)), 2e-5);  // smooth in (s, t)
  Real poly = 0;
  for (const TrianglePoint& p : duffyTriangle(6)) poly += p.w * 0.5 * p.l1 * p.l1 * p.l2;
  EXPECT_NEAR(poly, monomialIntegral(2, 1), 1e-15);
}

// Interior solid angle of the polyhedral cone at vertex i: for a convex vertex it is the area
// of the spherical polygon of its edge directions, 2 pi - sum over its edges of the angle between
// the two adjacent outward face normals.
Real vertexSolidAngle(const SurfaceMesh& s, int i) {
  const MatX2i E = uniqueEdges(s.F);
  const MatX2i EF = edgeFaces(s.F, E);
  Real sum = 0;
  for (int e = 0; e < E.rows(); ++e) {
    if (E(e, 0) != i && E(e, 1) != i) continue;
    Vec3 n[2];
    for (int k = 0; k < 2; ++k) {
      const int f = EF(e, k);
      const Vec3 a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
      n[k] = (b - a).cross(c - a).normalized();
    }
    sum += std::acos(std::clamp(n[0].dot(n[1]), Real(-1), Real(1)));
  }
  return 2 * M_PI - sum;
}

TEST(BemAssembly, UnmodifiedOffDiagonalSumMatchesJumpCoefficient) {
  // A rigid translation has no traction, so int_Gamma T*(x, y) dGamma_y = -c(x); on a smooth
  // surface c = I/2. The unassembled self-part int N_i T* over the flat triangles around x has
  // dr/dn = 0 (r lies in each triangle's plane): only the antisymmetric (r_,i n_j - r_,j n_i)
  // term remains there, so it has zero trace. trace(T*) = -(3 / 4 pi) dr/dn / r^2 is three
  // times Laplace's double-layer kernel, so trace(sum_{j != i} H_ij) = -3 Omega_i / (4 pi) with
  // Omega_i the interior solid angle of the discrete vertex (Gauss), which differs from 2 pi by
  // O(h / R) on a faceted sphere. And as the mesh is refined, sum_{j != i} H_ij -> -I/2.
  Real worst[2] = {0, 0};
  for (int level : {2, 3}) {
    const SurfaceMesh s = icosphere(level, 0.05);
    BemQuadrature q;
    q.rigidBodyDiagonal = false;
    const BemMatrices bem = assembleBem(s, 5000, 0.3, q);
    const int n = s.numVertices();
    for (int i = 0; i < n; i += 7) {
      Mat3 sum = Mat3::Zero();
      for (int j = 0; j < n; ++j)
        if (j != i) sum += bem.H.block<3, 3>(3 * i, 3 * j);
      EXPECT_TRUE(bem.H.block(3 * i, 3 * i, 3, 3).isZero(0));
      EXPECT_NEAR(sum.trace(), -3 * vertexSolidAngle(s, i) / (4 * M_PI), 2e-4) << i;
      worst[level - 2] =
          std::max(worst[level - 2], (sum + 0.5 * Mat3::Identity()).cwiseAbs().maxCoeff());
    }
  }
  std::cout << "max |sum_{j!=i} H_ij + I/2|: 162 vertices " << worst[0] << ", 642 vertices "
            << worst[1] << "\n";
  EXPECT_LT(worst[1], 0.6 * worst[0]);  // first-order convergence to -I/2
  EXPECT_LT(worst[1], 0.08);
}

TEST(BemAssembly, RigidRotationIsNearlyInNullSpace) {
  // The rigid-body trick makes translations exact; rotations are not enforced and so test
  // the off-diagonal integration.
  const SurfaceMesh s = icosphere(3, 0.05);
  const BemMatrices bem = assembleBem(s, 5000, 0.3);
  VecX u(3 * s.numVertices());
  for (int j = 0; j < s.numVertices(); ++j)
    u.segment<3>(3 * j) = Vec3(0.3, -0.5, 0.8).cross(s.V.row(j).transpose());
  VecX t(3 * s.numVertices());
  for (int j = 0; j < s.numVertices(); ++j) t.segment<3>(3 * j) = Vec3(1, 2, 3);
  EXPECT_LT((bem.H * u).norm(), 2e-3 * (bem.H.cwiseAbs() * u.cwiseAbs()).norm());
  EXPECT_LT((bem.H * t).norm(), 1e-12 * (bem.H.cwiseAbs() * t.cwiseAbs()).norm());
}

TEST(BemSolve, SphereUnderUniformPressureMatchesLame) {
  // Solid sphere of radius a under external pressure p: the uniform stress sigma = -p I
  // satisfies equilibrium and sigma n = -p n on r = a. Hooke: eps = ((1+nu) sigma - nu tr(sigma)
  // I) / E = -p (1 - 2 nu) / E I, so u = eps x and u_r(a) = -p a (1 - 2 nu) / E. The load is
  // self-equilibrated and there is no fixed node: rigid motions are removed by the bordered
  // system (u orthogonal to rigid modes), which the exact solution satisfies.
  const Real a = 0.05, E = 5000, nu = 0.3, p = 100;
  const SurfaceMesh s = icosphere(3, a);
  const BemMatrices bem = assembleBem(s, E, nu);
  VecX t(3 * s.numVertices());
  for (int j = 0; j < s.numVertices(); ++j)
    t.segment<3>(3 * j) = -p * s.V.row(j).transpose().normalized();
  const VecX u = solveBem(bem, s, {}, t);
  const Real expected = -p * a * (1 - 2 * nu) / E;
  Real mean = 0, worst = 0;
  for (int j = 0; j < s.numVertices(); ++j) {
    const Vec3 e = s.V.row(j).transpose().normalized();
    const Real ur = u.segment<3>(3 * j).dot(e);
    mean += ur / s.numVertices();
    worst = std::max(worst, std::abs(ur - expected) / std::abs(expected));
  }
  EXPECT_NEAR(mean, expected, 0.02 * std::abs(expected));
  EXPECT_LT(worst, 0.02);
  std::cout << "Lame sphere (642 vertices): mean u_r error "
            << std::abs(mean - expected) / std::abs(expected) << ", worst " << worst << "\n";
}

TEST(DeformationMatrix, ReciprocityAndGravitySag) {
  // Betti: the displacement at i under a force at j equals (transposed) that at j under a force
  // at i. A force f at node j is the traction f / A_j, so M_ij / A_j ~ (M_ji / A_i)^T.
  const SurfaceMesh s = testing::ellipsoid(2, Vec3(0.06, 0.04, 0.03));
  Box bottom;
  bottom.lo = Vec3(-1, -1, -1);
  bottom.hi = Vec3(1, 1, -0.02);
  const std::vector<int> fixed = rowsInBox(s.V, bottom);
  ASSERT_GE(fixed.size(), 3u);
  const DeformationMatrix dm = computeDeformationMatrix(
      assembleBem(s, 5000, 0.3), s, vertexNormals(s.V, s.F), fixed, 5000, 0.3, 1000);
  const VecX A = nodalAreas(s);
  int top = 0;
  for (int j = 0; j < s.numVertices(); ++j)
    if (s.V(j, 2) > s.V(top, 2)) top = j;
  int side = 0;
  for (int j = 0; j < s.numVertices(); ++j)
    if (s.V(j, 0) > s.V(side, 0)) side = j;
  const Mat3 Mij = dm.M.block<3, 3>(3 * top, 3 * side) / A[side];
  const Mat3 Mji = dm.M.block<3, 3>(3 * side, 3 * top) / A[top];
  EXPECT_LT((Mij - Mji.transpose()).norm(), 0.1 * Mij.norm());
  // Fixed rows are zero; gravity along -z moves the top down.
  for (int j : fixed) EXPECT_EQ(dm.M.row(3 * j).norm(), 0.0);
  const Vec3 gTop = dm.gravity.middleRows<3>(3 * top) * Vec3(0, 0, -9.81);
  EXPECT_LT(gTop[2], 0);
  EXPECT_GT(-gTop[2], 10 * std::abs(gTop[0]));
  // A downward force at the top moves the top down.
  const Vec3 uTop = dm.M.block<3, 3>(3 * top, 3 * top) * Vec3(0, 0, -100);
  EXPECT_LT(uTop[2], 0);
}

TEST(LossRatio, SameMeshIsZeroAndRefinementIsSmall) {
  const SurfaceMesh coarse = icosphere(2, 0.05), fine = icosphere(3, 0.05);
  LossRatioCase c;
  c.center = Vec3(0, 0, 0.05);
  c.radius = 0.04;
  c.traction = Vec3(0, 0, -200);
  c.fixedBox.lo = Vec3(-1, -1, -1);
  c.fixedBox.hi = Vec3(1, 1, -0.04);
  Material m;
  const LossRatioResult same = bemLossRatio(coarse, coarse, m, c);
  EXPECT_LT(same.ratio, 1e-12);
  const LossRatioResult r = bemLossRatio(coarse, fine, m, c);
  EXPECT_GT(r.ratio, 1e-4);  // different meshes do differ
  EXPECT_LT(r.ratio, 0.15);
  EXPECT_GT(r.maxFineDisplacement, 0);
  // The gradient transfer (the default, as the model) loses less than the linear one when the
  // fine solution goes to the coarse vertices and back; both are reported.
  EXPECT_GT(r.roundTripLinear, 0);
  EXPECT_LT(r.roundTripGradient, r.roundTripLinear);
  EXPECT_EQ(r.ratio, r.ratioGradientTransfer);
  EXPECT_GT(r.displacementRatio, 0.8);
  EXPECT_LT(r.displacementRatio, 1.2);
}

TEST(TractionField, UniformFieldEqualsGTimesNodalValues) {
  // A constant traction is its own linear interpolant, so int U* t equals G p with p = t at
  // every node, up to the two quadratures (the field one subdivides further).
  const SurfaceMesh s = icosphere(2, 0.05);
  const Real E = 5000, nu = 0.4;
  const BemMatrices bem = assembleBem(s, E, nu);
  const Vec3 t(30, -10, 70);
  VecX p(3 * s.numVertices());
  for (int j = 0; j < s.numVertices(); ++j) p.segment<3>(3 * j) = t;
  const VecX gp = bem.G * p;
  const VecX b = integrateTractionField(
      s, E, nu, [&](const Vec3&) { return t; }, 0.005);
  EXPECT_LT((b - gp).norm(), 2e-3 * gp.norm());
  // A field that vanishes on the lower half contributes nothing from the lower elements only:
  // b changes when the field does (not a constant function of its argument).
  const VecX half = integrateTractionField(
      s, E, nu, [&](const Vec3& x) { return x[2] > 0 ? t : Vec3::Zero(); }, 0.005);
  EXPECT_GT((half - b).norm(), 0.2 * b.norm());
}

TEST(FixedFractions, SphereBelowEquatorHasHalfTheArea) {
  const SurfaceMesh s = icosphere(3, 0.05);
  Box box;
  box.lo = Vec3::Constant(-1);
  box.hi = Vec3(1, 1, 0.0);
  const VecX phi = fixedFractions(s, box);
  const VecX A = nodalAreas(s);
  Real inside = 0;
  for (int j = 0; j < s.numVertices(); ++j) {
    EXPECT_GE(phi[j], 0);
    EXPECT_LE(phi[j], 1);
    if (s.V(j, 2) < -0.01) {
      EXPECT_EQ(phi[j], 1);
    }
    if (s.V(j, 2) > 0.01) {
      EXPECT_EQ(phi[j], 0);
    }
    inside += phi[j] * A[j];
  }
  EXPECT_NEAR(inside / A.sum(), 0.5, 0.01);
}

TEST(PartialConstraints, ReduceToClampsAndMoveContinuously) {
  const SurfaceMesh s = icosphere(2, 0.05);
  const Real E = 5000, nu = 0.4;
  const BemMatrices bem = assembleBem(s, E, nu);
  VecX p = VecX::Zero(3 * s.numVertices());
  std::vector<int> fixed;
  VecX phi = VecX::Zero(s.numVertices());
  for (int j = 0; j < s.numVertices(); ++j) {
    if (s.V(j, 2) < -0.03) {
      fixed.push_back(j);
      phi[j] = 1;
    }
    if (s.V(j, 2) > 0.03) p.segment<3>(3 * j) = Vec3(0, 0, -100);
  }
  const VecX rhs = bem.G * p;
  const VecX clamped = solveBemRhs(bem, s, fixed, rhs);
  const VecX partial = solveBemPartial(bem, s, phi, E, rhs);
  EXPECT_LT((partial - clamped).norm(), 1e-9 * clamped.norm());
  // One more node, nearly clamped (phi -> 1) or barely touched (phi -> 0), approaches the
  // clamped / free limits.
  int edge = -1;
  for (int j = 0; j < s.numVertices(); ++j)
    if (phi[j] == 0 && (edge < 0 || s.V(j, 2) < s.V(edge, 2))) edge = j;
  std::vector<int> more = fixed;
  more.push_back(edge);
  const VecX clampedMore = solveBemRhs(bem, s, more, rhs);
  VecX phiNear = phi;
  phiNear[edge] = 1 - 1e-6;
  const VecX nearly = solveBemPartial(bem, s, phiNear, E, rhs);
  EXPECT_GT((clampedMore - clamped).norm(), 1e-3 * clamped.norm());
  EXPECT_LT((nearly - clampedMore).norm(), 1e-3 * (clampedMore - clamped).norm());
  phiNear[edge] = 1e-6;
  const VecX barely = solveBemPartial(bem, s, phiNear, E, rhs);
  EXPECT_LT((barely - clamped).norm(), 1e-3 * (clampedMore - clamped).norm());
}

}  // namespace
}  // namespace deform::particle_bem
