#include "mean_dilatation_tet.h"

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

#include <limits>

namespace deform::reference_fem {

namespace {

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
    addPointStiffness(D, G, w, out.stiffness);
  }
  if (mode == TetEvalMode::Stiffness)
    out.stiffness.noalias() += (rest.volume * material.kappa) * b * b.transpose();
}

}  // namespace deform::reference_fem
