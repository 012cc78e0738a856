// Element kernels: forces against finite differences of the energy, stiffness against finite
// differences of the forces, rigid-motion invariance, rest equilibrium, patch tests.
#include <deform/kernels/fem_tet.h>

#include "../support/finite_difference.h"

#include <Eigen/Dense>

#include <gtest/gtest.h>

#include <random>
#include <vector>

using namespace deform;
using deform::testing::centralDifferences;
using deform::testing::numericGradient;

namespace {

struct RandomTet {
  TetRest rest;
  std::array<Vec3, 4> X, x;
};

/// A random well-shaped tet (edge ~ 1 cm) and a random deformation of it: F ~ I + 0.25 * noise,
/// kept with det F > 0.3 so that every material is smooth there.
RandomTet randomTet(std::mt19937& rng) {
  std::uniform_real_distribution<Real> u(-1, 1);
  RandomTet t;
  for (;;) {
    t.X = {Vec3(0, 0, 0), Vec3(0.01, 0, 0), Vec3(0, 0.01, 0), Vec3(0, 0, 0.01)};
    for (auto& p : t.X) p += 0.003 * Vec3(u(rng), u(rng), u(rng));
    if (makeTetRest(t.X[0], t.X[1], t.X[2], t.X[3], t.rest) && t.rest.volume > 5e-8) break;
  }
  for (;;) {
    Mat3 F = Mat3::Identity();
    for (int i = 0; i < 9; ++i) F.data()[i] += 0.25 * u(rng);
    if (F.determinant() < 0.3) continue;
    const Vec3 shift(u(rng), u(rng), u(rng));
    for (int a = 0; a < 4; ++a)
      t.x[a] = F * t.X[a] + 0.01 * shift + 1e-4 * Vec3(u(rng), u(rng), u(rng));
    if (deformationGradient(t.rest, t.x).determinant() > 0.3) break;
  }
  return t;
}

/// The four corners as one vector of 12 coordinates, and back.
Vec12 flat(const std::array<Vec3, 4>& x) {
  Vec12 v;
  for (int a = 0; a < 4; ++a) v.segment<3>(3 * a) = x[size_t(a)];
  return v;
}
std::array<Vec3, 4> corners(const Vec12& v) {
  return {v.segment<3>(0), v.segment<3>(3), v.segment<3>(6), v.segment<3>(9)};
}

const LameParameters kLame = LameParameters::fromYoungPoisson(5500, 0.45);

template <class M>
void checkDerivatives(const M& mat, const char* name) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 20; ++trial) {
    const RandomTet t = randomTet(rng);
    TetEvaluation e;
    evaluateTet(mat, t.rest, t.x, TetEvalMode::Stiffness, e);
    const Real h = 1e-7;  // m, on ~1 cm tets
    const auto evaluated = [&](const Vec12& y) {
      TetEvaluation ey;
      evaluateTet(mat, t.rest, corners(y), TetEvalMode::Gradient, ey);
      return ey;
    };
    const VecX gFd =
        numericGradient(flat(t.x), h, [&](const Vec12& y) { return evaluated(y).energy; });
    const MatX kFd =
        centralDifferences(flat(t.x), h, [&](const Vec12& y) { return evaluated(y).gradient; });
    EXPECT_LE((gFd - e.gradient).norm(), 1e-6 * e.gradient.norm()) << name << " trial " << trial;
    EXPECT_LE((kFd - e.stiffness).norm(), 1e-6 * e.stiffness.norm()) << name << " trial " << trial;
  }
}

}  // namespace

TEST(TetElement, LameFromYoungPoisson) {
  const LameParameters l = LameParameters::fromYoungPoisson(1000, 0.25);
  EXPECT_DOUBLE_EQ(l.mu, 400);
  EXPECT_DOUBLE_EQ(l.lambda, 400);
  EXPECT_NEAR(l.bulk(), 1000.0 / (3 * (1 - 0.5)), 1e-9);
}

TEST(TetElement, LinearDerivativesMatchFiniteDifferences) {
  checkDerivatives(LinearMaterial{kLame}, "linear");
}
TEST(TetElement, NeoHookeanDerivativesMatchFiniteDifferences) {
  checkDerivatives(NeoHookeanMaterial{kLame}, "neo_hookean");
}
TEST(TetElement, CorotationalExactTangentMatchesFiniteDifferences) {
  checkDerivatives(CorotationalMaterial{kLame, CorotationalTangent::Exact}, "corotational");
}

TEST(TetElement, CorotationalForceIsEnergyGradientAndFixedRotationTangentExactAtRigidStates) {
  // The force (Mueller-Gross f = -R K0 (R^T x - X)) is the exact gradient of the corotated
  // energy; the R K0 R^T tangent omits dR and equals the exact tangent only at rigid states.
  std::mt19937 rng(3);
  const CorotationalMaterial fixed{kLame, CorotationalTangent::FixedRotation};
  const CorotationalMaterial exact{kLame, CorotationalTangent::Exact};
  for (int trial = 0; trial < 10; ++trial) {
    RandomTet t = randomTet(rng);
    TetEvaluation ef, ee;
    evaluateTet(fixed, t.rest, t.x, TetEvalMode::Stiffness, ef);
    evaluateTet(exact, t.rest, t.x, TetEvalMode::Stiffness, ee);
    EXPECT_LE((ef.gradient - ee.gradient).norm(), 1e-12 * ee.gradient.norm());
    // A deformed state: the two tangents differ (so the comparison below can fail).
    EXPECT_GT((ef.stiffness - ee.stiffness).norm(), 1e-3 * ee.stiffness.norm());
    const Mat3 R = Eigen::AngleAxis<Real>(0.3 + trial, Vec3(1, 2, 3 - trial).normalized()).matrix();
    for (int a = 0; a < 4; ++a) t.x[a] = R * t.X[a] + Vec3(0.1, -0.2, 0.05);
    evaluateTet(fixed, t.rest, t.x, TetEvalMode::Stiffness, ef);
    evaluateTet(exact, t.rest, t.x, TetEvalMode::Stiffness, ee);
    EXPECT_LE((ef.stiffness - ee.stiffness).norm(), 1e-9 * ee.stiffness.norm());
  }
}

TEST(TetElement, RigidMotionGivesZeroForceAndEnergy) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 10; ++trial) {
    RandomTet t = randomTet(rng);
    const Mat3 R =
        Eigen::AngleAxis<Real>(0.7 * (trial + 1), Vec3(trial, 1, -2).normalized()).matrix();
    const Vec3 c(0.3, -0.1, 2.0);
    for (int a = 0; a < 4; ++a) t.x[a] = R * t.X[a] + c;
    // Force scale of a 10% strain on this tet, for the tolerance.
    const Real scale = kLame.mu * 0.1 * std::cbrt(t.rest.volume) * std::cbrt(t.rest.volume);
    TetEvaluation e;
    evaluateTet(CorotationalMaterial{kLame}, t.rest, t.x, TetEvalMode::Gradient, e);
    EXPECT_LE(e.gradient.norm(), 1e-10 * scale);
    EXPECT_LE(std::abs(e.energy), 1e-12 * scale * 0.01);
    evaluateTet(NeoHookeanMaterial{kLame}, t.rest, t.x, TetEvalMode::Gradient, e);
    EXPECT_LE(e.gradient.norm(), 1e-10 * scale);
    EXPECT_LE(std::abs(e.energy), 1e-12 * scale * 0.01);
    // The linear material is not rotation invariant: a finite rotation produces force.
    evaluateTet(LinearMaterial{kLame}, t.rest, t.x, TetEvalMode::Gradient, e);
    EXPECT_GT(e.gradient.norm(), 1e-3 * scale);
  }
}

TEST(TetElement, RestStateIsEquilibriumAndSmallStrainTangentsAgree) {
  std::mt19937 rng(5);
  const RandomTet t = randomTet(rng);
  TetEvaluation l, c, n;
  evaluateTet(LinearMaterial{kLame}, t.rest, t.X, TetEvalMode::Stiffness, l);
  evaluateTet(CorotationalMaterial{kLame}, t.rest, t.X, TetEvalMode::Stiffness, c);
  evaluateTet(NeoHookeanMaterial{kLame}, t.rest, t.X, TetEvalMode::Stiffness, n);
  EXPECT_LE(l.gradient.norm(), 1e-12);
  EXPECT_LE(c.gradient.norm(), 1e-12);
  EXPECT_LE(n.gradient.norm(), 1e-12);
  // All three linearise to the same small-strain elasticity with these mu, lambda.
  EXPECT_LE((c.stiffness - l.stiffness).norm(), 1e-9 * l.stiffness.norm());
  EXPECT_LE((n.stiffness - l.stiffness).norm(), 1e-9 * l.stiffness.norm());
}

TEST(TetElement, NeoHookeanInvertedIsInfiniteEnergyNotNaN) {
  std::mt19937 rng(1);
  RandomTet t = randomTet(rng);
  std::swap(t.x[2], t.x[3]);  // inverted
  TetEvaluation e;
  evaluateTet(NeoHookeanMaterial{kLame}, t.rest, t.x, TetEvalMode::Gradient, e);
  EXPECT_TRUE(std::isinf(e.energy));
  EXPECT_GT(e.energy, 0);
  t.x[3] = t.x[0];  // flat: J = 0 up to round-off (either sign)
  evaluateTet(NeoHookeanMaterial{kLame}, t.rest, t.x, TetEvalMode::Energy, e);
  EXPECT_FALSE(std::isnan(e.energy));
  EXPECT_GT(e.energy, 1e6 * kLame.mu * t.rest.volume);
}

TEST(TetElement, ProjectionGivesPositiveSemiDefinite) {
  Mat9 A = Mat9::Random();
  A = A + A.transpose();
  const Mat9 P = projectPositiveSemiDefinite(A);
  Eigen::SelfAdjointEigenSolver<Mat9> es(P);
  EXPECT_GE(es.eigenvalues().minCoeff(), -1e-12);
  EXPECT_LT(Eigen::SelfAdjointEigenSolver<Mat9>(A).eigenvalues().minCoeff(), 0);  // was indefinite
}

TEST(TetElement, NeoHookeanAnalyticProjectionEqualsNumericalProjection) {
  // Stretches, compressions (indefinite: negative twist eigenvalues) and repeated singular
  // values (the identity, a uniform scaling, a uniaxial stretch), each rotated on both sides.
  const NeoHookeanMaterial nh{kLame};
  std::mt19937 rng(11);
  std::uniform_real_distribution<Real> u(-1, 1);
  const std::vector<Vec3> stretches = {Vec3(1, 1, 1),       Vec3(0.8, 0.8, 0.8),
                                       Vec3(1.3, 1, 1),     Vec3(0.6, 1.1, 1.1),
                                       Vec3(0.5, 0.9, 1.7), Vec3(1.2, 0.95, 0.7)};
  int indefinite = 0;
  for (const Vec3& st : stretches)
    for (int rep = 0; rep < 5; ++rep) {
      const Mat3 R1 = Eigen::Quaternion<Real>(u(rng), u(rng), u(rng), u(rng)).normalized().matrix();
      const Mat3 R2 = Eigen::Quaternion<Real>(u(rng), u(rng), u(rng), u(rng)).normalized().matrix();
      const Mat3 F = R1 * st.asDiagonal() * R2;
      const Mat9 D = nh.stressDerivative(F);
      if (Eigen::SelfAdjointEigenSolver<Mat9>(D).eigenvalues().minCoeff() < -1e-9 * kLame.mu)
        ++indefinite;
      const Mat9 expected = projectPositiveSemiDefinite(D);
      EXPECT_LE((nh.projectedStressDerivative(F) - expected).norm(), 1e-9 * expected.norm())
          << "stretches " << st.transpose();
    }
  EXPECT_GT(indefinite, 0);  // the projection was exercised, not only the identity
}

TEST(TetElement, PolarDecompositionIsProperRotation) {
  std::mt19937 rng(9);
  std::uniform_real_distribution<Real> u(-1, 1);
  for (int i = 0; i < 50; ++i) {
    Mat3 F;
    for (int k = 0; k < 9; ++k) F.data()[k] = u(rng);
    Mat3 R, S;
    polarDecomposition(F, R, S);
    EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
    EXPECT_LE((R.transpose() * R - Mat3::Identity()).norm(), 1e-12);
    EXPECT_LE((R * S - F).norm(), 1e-12);
    EXPECT_LE((S - S.transpose()).norm(), 1e-14);
  }
}
