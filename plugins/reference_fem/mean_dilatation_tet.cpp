#include "mean_dilatation_tet.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include <limits>

namespace deform::reference_fem {

namespace {

Mat3 cofactor(const Mat3& F) {
  Mat3 H;
  H.col(0) = F.col(1).cross(F.col(2));
  H.col(1) = F.col(2).cross(F.col(0));
  H.col(2) = F.col(0).cross(F.col(1));
  return H;
}

Mat3 crossMatrix(const Vec3& w) {
  Mat3 W;
  W << 0, -w(2), w(1), w(2), 0, -w(0), -w(1), w(0), 0;
  return W;
}

/// D += s dH/dF (9x9 on vec(F), column-major): H = [F1 x F2, F2 x F0, F0 x F1], so column j of
/// dH is a cross product of the other two columns of F with those of dF.
void addCofactorDerivative(Real s, const Mat3& F, Mat9& D) {
  const Mat3 X0 = s * crossMatrix(F.col(0)), X1 = s * crossMatrix(F.col(1)),
             X2 = s * crossMatrix(F.col(2));
  D.block<3, 3>(0, 3) -= X2;
  D.block<3, 3>(0, 6) += X1;
  D.block<3, 3>(3, 0) += X2;
  D.block<3, 3>(3, 6) -= X0;
  D.block<3, 3>(6, 0) -= X1;
  D.block<3, 3>(6, 3) += X0;
}

/// The PSD projection of a symmetric 9x9 matrix; a Cholesky test first, as most points of a
/// solve are positive definite and then nothing changes.
Mat9 projectedIfNeeded(const Mat9& D) {
  const Mat9 S = 0.5 * (D + D.transpose());
  Eigen::LLT<Mat9> llt(S);
  if (llt.info() == Eigen::Success) return D;
  return projectPositiveSemiDefinite(S);
}

}  // namespace

MeanDilatationNeoHookean MeanDilatationNeoHookean::fromLame(const LameParameters& lame) {
  MeanDilatationNeoHookean m;
  m.kappa = lame.bulk();
  m.isochoric.lame.mu = lame.mu;
  // bulk() = lambda + 2 mu / 3 evaluates to exactly 0 with this lambda: the isochoric part alone.
  m.isochoric.lame.lambda = -(2.0 * lame.mu / 3.0);
  return m;
}

void evaluateMeanDilatationTet(const MeanDilatationNeoHookean& material,
                               const QuadraticTetRest& rest, const Mat3x10& x, TetEvalMode mode,
                               QuadraticTetEvaluation& out, bool projectSpd) {
  const Real w = rest.volume / 4.0;
  std::array<Mat3, 4> F;
  Real theta = 0, iso = 0;
  for (int q = 0; q < 4; ++q) {
    F[size_t(q)] = x * rest.gradients[size_t(q)].transpose();
    const Real psi = material.isochoric.energyDensity(F[size_t(q)]);  // +inf for J <= 0
    if (!std::isfinite(psi)) {
      out.energy = std::numeric_limits<Real>::infinity();
      return;
    }
    iso += w * psi;
    theta += 0.25 * F[size_t(q)].determinant();
  }
  out.energy = iso + 0.5 * rest.volume * material.kappa * (theta - 1) * (theta - 1);
  if (mode == TetEvalMode::Energy) return;
  const Real p = material.kappa * (theta - 1);  // the element's pressure (Pa)
  out.gradient.setZero();
  Vec30 b = Vec30::Zero();  // dtheta/dx
  if (mode == TetEvalMode::Stiffness) out.stiffness.setZero();
  for (int q = 0; q < 4; ++q) {
    const Mat3x10& G = rest.gradients[size_t(q)];
    const Mat3 H = cofactor(F[size_t(q)]);
    const Mat3x10 PG = (w * (material.isochoric.stress(F[size_t(q)]) + p * H)) * G;
    for (int a = 0; a < 10; ++a) out.gradient.segment<3>(3 * a) += PG.col(a);
    if (mode != TetEvalMode::Stiffness) continue;
    const Mat3x10 HG = 0.25 * H * G;  // dJ_q/dx_a / 4, column a
    for (int a = 0; a < 10; ++a) b.segment<3>(3 * a) += HG.col(a);
    Mat9 D = material.isochoric.stressDerivative(F[size_t(q)]);
    addCofactorDerivative(p, F[size_t(q)], D);
    if (projectSpd) D = projectedIfNeeded(D);
    // As in evaluateQuadraticTet: K(3 a + i, 3 b + k) += w sum_jl G(j, a) D(i + 3 j, k + 3 l)
    // G(l, b).
    Eigen::Matrix<Real, 9, 30> DG;
    for (int c = 0; c < 10; ++c)
      for (int k = 0; k < 3; ++k)
        DG.col(3 * c + k) = D.col(k) * G(0, c) + D.col(k + 3) * G(1, c) + D.col(k + 6) * G(2, c);
    for (int a = 0; a < 10; ++a)
      for (int i = 0; i < 3; ++i)
        out.stiffness.row(3 * a + i) +=
            w * (G(0, a) * DG.row(i) + G(1, a) * DG.row(i + 3) + G(2, a) * DG.row(i + 6));
  }
  if (mode == TetEvalMode::Stiffness)
    out.stiffness.noalias() += (rest.volume * material.kappa) * b * b.transpose();
}

}  // namespace deform::reference_fem
