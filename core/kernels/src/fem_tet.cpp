#include <deform/kernels/fem_tet.h>

#include <Eigen/Dense>
#include <Eigen/SVD>

namespace deform {

namespace {

Mat3 basis(int k) {  // E with a single 1 at vec index k = i + 3 j
  Mat3 E = Mat3::Zero();
  E(k % 3, k / 3) = 1.0;
  return E;
}

Vec9 vec(const Mat3& A) {
  return Eigen::Map<const Vec9>(A.data());
}

/// J^{-2/3}: cbrt is several times cheaper than pow; pow's value (NaN, inf) for J <= 0.
Real jMinusTwoThirds(Real J) {
  if (!(J > 0)) return std::pow(J, -2.0 / 3.0);
  const Real c = std::cbrt(J);
  return 1.0 / (c * c);
}

/// Neo-Hookean d^2 psi / d sigma_i d sigma_j at singular values s (psi_i = mu a sigma_i +
/// c / sigma_i, a = J^{-2/3}, c = kappa (J - 1) J - mu/3 a I1; see fem_tet.h).
Mat3 singularValueHessian(Real mu, Real kappa, const Vec3& s, Real J, Real I1, Real a, Real c) {
  Mat3 H;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j)
      H(i, j) = -2.0 / 3.0 * mu * a * (s(i) / s(j) + s(j) / s(i)) +
                (2.0 / 9.0 * mu * a * I1 + kappa * (2.0 * J - 1.0) * J) / (s(i) * s(j)) +
                (i == j ? mu * a - c / (s(i) * s(i)) : 0.0);
  return H;
}

}  // namespace

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

LameParameters LameParameters::fromYoungPoisson(Real young, Real poisson) {
  LameParameters l;
  l.mu = young / (2.0 * (1.0 + poisson));
  l.lambda = young * poisson / ((1.0 + poisson) * (1.0 - 2.0 * poisson));
  return l;
}

Eigen::Matrix<Real, 3, 4> TetRest::gradients() const {
  Eigen::Matrix<Real, 3, 4> g;
  g.rightCols<3>() = Bm.transpose();
  g.col(0) = -(g.col(1) + g.col(2) + g.col(3));
  return g;
}

bool makeTetRest(const Vec3& X0, const Vec3& X1, const Vec3& X2, const Vec3& X3, TetRest& rest) {
  Mat3 Dm;
  Dm << X1 - X0, X2 - X0, X3 - X0;
  rest.volume = Dm.determinant() / 6.0;
  // Relative test: a sliver whose volume is round-off compared with its edges is degenerate.
  const Real scale = std::max({Dm.col(0).norm(), Dm.col(1).norm(), Dm.col(2).norm()});
  if (!(rest.volume > 1e-14 * scale * scale * scale)) {
    rest.volume = std::min<Real>(rest.volume, 0.0);
    return false;
  }
  rest.Bm = Dm.inverse();
  return true;
}

Mat3 deformationGradient(const TetRest& rest, const std::array<Vec3, 4>& x) {
  Mat3 Ds;
  Ds << x[1] - x[0], x[2] - x[0], x[3] - x[0];
  return Ds * rest.Bm;
}

void polarDecomposition(const Mat3& F, Mat3& R, Mat3& S) {
  Eigen::JacobiSVD<Mat3> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 U = svd.matrixU();
  const Mat3 V = svd.matrixV();
  if ((U * V.transpose()).determinant() < 0) U.col(2) = -U.col(2);
  R = U * V.transpose();
  S = R.transpose() * F;
  S = 0.5 * (S + S.transpose());
}

Mat9 projectPositiveSemiDefinite(const Mat9& A) {
  Eigen::SelfAdjointEigenSolver<Mat9> es(0.5 * (A + A.transpose()));
  Vec9 ev = es.eigenvalues().cwiseMax(0.0);
  return es.eigenvectors() * ev.asDiagonal() * es.eigenvectors().transpose();
}

// ---- linear -------------------------------------------------------------------------------

Real LinearMaterial::energyDensity(const Mat3& F) const {
  const Mat3 eps = 0.5 * (F + F.transpose()) - Mat3::Identity();
  const Real tr = eps.trace();
  return lame.mu * eps.squaredNorm() + 0.5 * lame.lambda * tr * tr;
}

Mat3 LinearMaterial::stress(const Mat3& F) const {
  const Mat3 eps = 0.5 * (F + F.transpose()) - Mat3::Identity();
  return 2.0 * lame.mu * eps + lame.lambda * eps.trace() * Mat3::Identity();
}

Mat9 LinearMaterial::stressDerivative(const Mat3& /*F*/) const {
  Mat9 D;
  for (int k = 0; k < 9; ++k) {
    const Mat3 dF = basis(k);
    D.col(k) = vec(lame.mu * (dF + dF.transpose()) + lame.lambda * dF.trace() * Mat3::Identity());
  }
  return D;
}

// ---- corotational -------------------------------------------------------------------------

Real CorotationalMaterial::energyDensity(const Mat3& F) const {
  Mat3 R, S;
  polarDecomposition(F, R, S);
  const Mat3 E = S - Mat3::Identity();
  const Real tr = E.trace();
  return lame.mu * E.squaredNorm() + 0.5 * lame.lambda * tr * tr;
}

Mat3 CorotationalMaterial::stress(const Mat3& F) const {
  Mat3 R, S;
  polarDecomposition(F, R, S);
  const Mat3 E = S - Mat3::Identity();
  return R * (2.0 * lame.mu * E + lame.lambda * E.trace() * Mat3::Identity());
}

Mat9 CorotationalMaterial::stressDerivative(const Mat3& F) const {
  Mat3 R, S;
  polarDecomposition(F, R, S);
  Mat9 D;
  if (tangent == CorotationalTangent::FixedRotation) {
    // dP = R C[R^T dF]: the Mueller-Gross tangent R K0 R^T at the element level.
    for (int k = 0; k < 9; ++k) {
      const Mat3 Y = R.transpose() * basis(k);
      D.col(k) =
          vec(R * (lame.mu * (Y + Y.transpose()) + lame.lambda * Y.trace() * Mat3::Identity()));
    }
    return D;
  }
  // Exact: dP = 2 mu dF + (lambda tr(S - I) - 2 mu) dR + lambda tr(R^T dF) R, with
  // dR = R [w]x, (tr(S) I - S) w = axial(Y - Y^T), Y = R^T dF.
  const Mat3 A = S.trace() * Mat3::Identity() - S;
  Eigen::FullPivLU<Mat3> lu(A);
  const bool invertible = lu.isInvertible();
  const Real c = lame.lambda * (S.trace() - 3.0) - 2.0 * lame.mu;
  for (int k = 0; k < 9; ++k) {
    const Mat3 dF = basis(k);
    const Mat3 Y = R.transpose() * dF;
    const Mat3 K = Y - Y.transpose();
    const Vec3 w = invertible ? Vec3(lu.solve(Vec3(K(2, 1), K(0, 2), K(1, 0)))) : Vec3::Zero();
    const Mat3 dR = R * crossMatrix(w);
    D.col(k) = vec(2.0 * lame.mu * dF + c * dR + lame.lambda * Y.trace() * R);
  }
  return D;
}

// ---- Neo-Hookean --------------------------------------------------------------------------

Real NeoHookeanMaterial::energyDensity(const Mat3& F) const {
  const Real J = F.determinant();
  if (!(J > 0)) return std::numeric_limits<Real>::infinity();
  const Real I1 = F.squaredNorm();
  return 0.5 * lame.mu * (jMinusTwoThirds(J) * I1 - 3.0) +
         0.5 * lame.bulk() * (J - 1.0) * (J - 1.0);
}

Mat3 NeoHookeanMaterial::stress(const Mat3& F) const {
  // P = mu J^{-2/3} F - mu/3 I1 J^{-5/3} H + kappa (J - 1) H, H = cof F = J F^{-T}.
  const Real J = F.determinant();
  const Real I1 = F.squaredNorm();
  const Mat3 H = cofactor(F);
  const Real a = jMinusTwoThirds(J);
  return lame.mu * a * F + (-lame.mu / 3.0 * I1 * a / J + lame.bulk() * (J - 1.0)) * H;
}

Mat9 NeoHookeanMaterial::stressDerivative(const Mat3& F) const {
  // P = mu a F + (b + c) H with a = J^{-2/3}, b = -mu/3 I1 J^{-5/3}, c = kappa (J - 1), so with
  // dJ = H : dF, dI1 = 2 F : dF and f = vec F, h = vec H:
  //   dP/dF = mu a I + alpha (f h^T + h f^T) + beta h h^T + (b + c) dH/dF,
  //   alpha = -2/3 mu J^{-5/3}, beta = 5/9 mu I1 J^{-8/3} + kappa,
  // and dH/dF maps dF's column l to H's column j by the cross-product matrices of F's columns
  // (H = [F1 x F2, F2 x F0, F0 x F1]).
  const Real J = F.determinant();
  const Real I1 = F.squaredNorm();
  const Mat3 H = cofactor(F);
  const Real kappa = lame.bulk(), mu = lame.mu;
  const Real a = jMinusTwoThirds(J);
  const Real a5 = a / J, a8 = a5 / J;
  const Real b = -mu / 3.0 * I1 * a5;
  const Real c = kappa * (J - 1.0);
  const Real alpha = -2.0 / 3.0 * mu * a5, beta = 5.0 / 9.0 * mu * I1 * a8 + kappa;
  const Vec9 f = vec(F), h = vec(H);
  Mat9 D = alpha * (f * h.transpose() + h * f.transpose()) + beta * h * h.transpose();
  D.diagonal().array() += mu * a;
  const Real s = b + c;
  addCofactorDerivative(s, F, D);
  return D;
}

Mat9 NeoHookeanMaterial::projectedStressDerivative(const Mat3& F) const {
  // The nine eigenvalues of dP/dF depend on the singular values alone (see the header): when
  // all of them are positive with a margin far above round-off, the projection changes nothing
  // and the exact tangent (closed form, no SVD) is returned. The singular values come from the
  // eigenvalues of F^T F (closed form); only the sign test uses them.
  if (const Real J = F.determinant(); J > 0) {
    Eigen::SelfAdjointEigenSolver<Mat3> ce;
    ce.computeDirect(F.transpose() * F, Eigen::EigenvaluesOnly);
    const Vec3 s = ce.eigenvalues().cwiseMax(0).cwiseSqrt();
    if (s.minCoeff() > 0) {
      const Real mu = lame.mu, kappa = lame.bulk();
      const Real I1 = F.squaredNorm();
      const Real a = jMinusTwoThirds(J);
      const Real c = kappa * (J - 1.0) * J - mu / 3.0 * a * I1;
      const Real margin = 1e-6 * (mu + kappa);
      bool positive = true;
      for (int i = 0; i < 3 && positive; ++i)
        for (int j = i + 1; j < 3 && positive; ++j)
          positive = mu * a - std::abs(c) / (s(i) * s(j)) >= margin;
      if (positive) {
        Eigen::SelfAdjointEigenSolver<Mat3> he;
        he.computeDirect(singularValueHessian(mu, kappa, s, J, I1, a, c), Eigen::EigenvaluesOnly);
        if (he.eigenvalues().minCoeff() >= margin) return stressDerivative(F);
      }
    }
  }
  Eigen::JacobiSVD<Mat3> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  const Vec3 s = svd.singularValues();
  const Real J = s.prod();
  if (!(J > 0) || !(s(2) > 0)) return projectPositiveSemiDefinite(stressDerivative(F));
  // det F > 0 with sigma >= 0 means det U det V = +1, so F = U Sigma V^T with psi(F) = psi(Sigma).
  const Mat3 U = svd.matrixU(), V = svd.matrixV();
  const Real mu = lame.mu, kappa = lame.bulk();
  const Real I1 = s.squaredNorm();
  const Real a = jMinusTwoThirds(J);
  const Real c = kappa * (J - 1.0) * J - mu / 3.0 * a * I1;
  const Mat3 H = singularValueHessian(mu, kappa, s, J, I1, a, c);
  Eigen::SelfAdjointEigenSolver<Mat3> es(H);
  Mat9 D = Mat9::Zero();
  auto add = [&](Real lambda, const Mat3& Q) {  // Q in the singular frame, |Q| = 1
    if (!(lambda > 0)) return;
    const Mat3 M = U * Q * V.transpose();
    const Vec9 q = vec(M);
    D.noalias() += lambda * q * q.transpose();
  };
  for (int k = 0; k < 3; ++k) add(es.eigenvalues()(k), Mat3(es.eigenvectors().col(k).asDiagonal()));
  const Real r = std::sqrt(0.5);
  for (int i = 0; i < 3; ++i)
    for (int j = i + 1; j < 3; ++j) {
      Mat3 twist = Mat3::Zero(), flip = Mat3::Zero();
      twist(i, j) = r;
      twist(j, i) = -r;
      flip(i, j) = flip(j, i) = r;
      add(mu * a + c / (s(i) * s(j)), twist);
      add(mu * a - c / (s(i) * s(j)), flip);
    }
  return D;
}

}  // namespace deform
