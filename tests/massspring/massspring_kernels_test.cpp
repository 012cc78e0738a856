// Spring kernels against finite differences (force = -dE/dx, stiffness = -df/dx), damping acts
// along the axis only, degenerate springs are refused, and the van Gelder rule gives a regular
// triangulated sheet the intended membrane stiffness E t (and the network's Poisson ratio 1/3).
#include "../support/finite_difference.h"
#include "../support/meshes.h"
#include "massspring_model.h"

#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>

#include <random>

namespace deform::massspring {
namespace {

Vec3 randomVec(std::mt19937& rng, Real s = 1.0) {
  std::uniform_real_distribution<Real> u(-s, s);
  return Vec3(u(rng), u(rng), u(rng));
}

TEST(SpringKernel, ForceIsMinusEnergyGradient) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 20; ++trial) {
    const Vec3 xa = randomVec(rng), xb = randomVec(rng);
    const Real k = 10.0 + trial, rest = (xa - xb).norm() * (trial % 2 ? 0.7 : 1.4);
    Vec3 fa;
    ASSERT_TRUE(springForce(xa, xb, Vec3::Zero(), Vec3::Zero(), k, 0.0, rest, fa));
    const Real eps = 1e-6;
    const VecX dEa = testing::numericGradient(
        xa, eps, [&](const Vec3& y) { return springEnergy(y, xb, k, rest); });
    const VecX dEb = testing::numericGradient(
        xb, eps, [&](const Vec3& y) { return springEnergy(xa, y, k, rest); });
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(fa[c], -dEa(c), 1e-6 * k);
      EXPECT_NEAR(-fa[c], -dEb(c), 1e-6 * k);  // f_b = -f_a
    }
  }
}

TEST(SpringKernel, StiffnessIsMinusForceJacobian) {
  std::mt19937 rng(12);
  for (int trial = 0; trial < 20; ++trial) {
    const Vec3 xa = randomVec(rng), xb = randomVec(rng);
    const Real k = 5.0, rest = (xa - xb).norm() * (trial % 2 ? 0.6 : 1.5);  // stretched/compressed
    Mat3 K;
    ASSERT_TRUE(springStiffness(xa, xb, k, rest, false, K));
    const Real eps = 1e-6;
    const auto forceOnA = [&](const Vec3& a, const Vec3& b) {
      Vec3 f;
      springForce(a, b, Vec3::Zero(), Vec3::Zero(), k, 0.0, rest, f);
      return f;
    };
    const MatX dfa_dxa =
        testing::centralDifferences(xa, eps, [&](const Vec3& y) { return forceOnA(y, xb); });
    const MatX dfa_dxb =
        testing::centralDifferences(xb, eps, [&](const Vec3& y) { return forceOnA(xa, y); });
    for (int c = 0; c < 3; ++c) {
      EXPECT_LT((dfa_dxa.col(c) + K.col(c)).norm(), 1e-6 * k);  // df_a/dx_a = -K
      EXPECT_LT((dfa_dxb.col(c) - K.col(c)).norm(), 1e-6 * k);  // df_a/dx_b = K
    }
    // The clamped form equals the exact one when stretched and is positive semidefinite always.
    Mat3 Kp;
    ASSERT_TRUE(springStiffness(xa, xb, k, rest, true, Kp));
    if ((xa - xb).norm() >= rest) {
      EXPECT_LT((Kp - K).norm(), 1e-12);
    }
    Eigen::SelfAdjointEigenSolver<Mat3> es(Kp);
    EXPECT_GE(es.eigenvalues().minCoeff(), -1e-12);
    if ((xa - xb).norm() < rest) {
      EXPECT_LT(Eigen::SelfAdjointEigenSolver<Mat3>(K).eigenvalues().minCoeff(), 0.0);
    }
  }
}

TEST(SpringKernel, DampingActsAlongTheAxisOnly) {
  const Vec3 xa(0, 0, 0), xb(1, 0, 0);
  Vec3 fa;
  // Relative velocity across the axis: no damping force.
  ASSERT_TRUE(springForce(xa, xb, Vec3::Zero(), Vec3(0, 3, 1), 2.0, 0.5, 1.0, fa));
  EXPECT_EQ(fa.norm(), 0.0);
  // b moving away along the axis: a is pulled towards b with c * |v|.
  ASSERT_TRUE(springForce(xa, xb, Vec3::Zero(), Vec3(2, 0, 0), 2.0, 0.5, 1.0, fa));
  EXPECT_NEAR(fa.x(), 1.0, 1e-15);
  EXPECT_DOUBLE_EQ(springDamping(1.0, 4.0, 2.0, 2.0), 4.0);  // 2 sqrt(4 * 1)
}

TEST(SpringKernel, DegenerateSpringIsRefused) {
  const Vec3 x(1, 2, 3);
  Vec3 f;
  Mat3 K;
  EXPECT_FALSE(springForce(x, x, Vec3::Zero(), Vec3::Zero(), 1.0, 1.0, 0.5, f));
  EXPECT_EQ(f.norm(), 0.0);
  EXPECT_FALSE(springStiffness(x, x, 1.0, 0.5, true, K));
}

// A sheet of equilateral triangles under an affine stretch. For a uniform strain eps the
// linearised spring network is exactly in equilibrium in the interior (each node is a centre of
// symmetry), so the load holding the right boundary divided by t H eps (H = height between the
// first and last rows) must be the membrane's plane-stress modulus:
//   uniaxial stress (lateral strain -nu eps, nu = 1/3): E,
//   uniaxial strain (no lateral strain):                E / (1 - nu^2) = 9E/8.
// The only error is geometric nonlinearity, O(eps) relative: with eps = 1e-5 we allow 1e-3.
struct SheetForces {
  Real boundaryForce = 0;  // N, x-force on the last node of each row
  Real maxInterior = 0;    // N, largest net force on a node not on the boundary
  Real springScale = 0;    // N, k eps a of an interior horizontal spring
};

SheetForces stretchSheet(Real lateral, Real eps, Real young, Real t, int rows, int cols, Real a) {
  Organ o;
  o.source = "test:sheet";
  o.surface = testing::equilateralSheet(rows, cols, a);
  o.material.young = young;
  MassSpringConfig cfg;
  cfg.thickness = t;
  cfg.bendingRatio = 0.0;
  cfg.dampingRatio = 0.0;
  MassSpringModel m;
  m.init(o, cfg);
  EXPECT_EQ(m.counts().at("bending_springs"), 0);
  MatX3 x = o.surface.V;
  x.col(0) *= 1.0 + eps;
  x.col(1) *= 1.0 + lateral * eps;
  MatX3 f;
  m.springForces(x, MatX3::Zero(x.rows(), 3), f);
  SheetForces out;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const int i = r * cols + c;
      // The load that holds the stretch is minus the springs' pull on the boundary nodes.
      if (c == cols - 1) out.boundaryForce -= f(i, 0);
      if (r > 0 && r < rows - 1 && c > 0 && c < cols - 1)
        out.maxInterior = std::max(out.maxInterior, f.row(i).norm());
    }
  }
  out.springScale = young * t * std::sqrt(3.0) / 2.0 * eps * a;
  return out;
}

TEST(VanGelderRule, RegularSheetHasTheIntendedMembraneStiffness) {
  const Real E = 5500.0, t = 0.002, a = 0.004, eps = 1e-5;
  const int rows = 9, cols = 12;
  const Real H = (rows - 1) * a * std::sqrt(3.0) / 2.0;
  const SheetForces stress = stretchSheet(-1.0 / 3.0, eps, E, t, rows, cols, a);
  EXPECT_NEAR(stress.boundaryForce / (t * H * eps), E, 1e-3 * E);
  EXPECT_LT(stress.maxInterior, 1e-3 * stress.springScale);
  const SheetForces strain = stretchSheet(0.0, eps, E, t, rows, cols, a);
  EXPECT_NEAR(strain.boundaryForce / (t * H * eps), 9.0 / 8.0 * E, 1e-3 * E);
  EXPECT_LT(strain.maxInterior, 1e-3 * strain.springScale);
}

}  // namespace
}  // namespace deform::massspring
