#include "hex_element.h"

#include "rotation_step.h"

#include <Eigen/Cholesky>
#include <Eigen/SVD>

#include <cmath>

namespace deform::fem_hex {

namespace {

const Real kGauss = 1.0 / std::sqrt(3.0);

template <class Fn>
void forEachGaussPoint(const Vec3& size, Fn&& fn) {
  const Real detJ = size.prod() / 8.0;  // weights are all 1
  for (int g = 0; g < 8; ++g) {
    const Vec3i c = hexCorner(g);
    const Vec3 xi = kGauss * (2 * c.cast<Real>() - Vec3::Ones());
    fn(hexShapeGradients(size, xi), detJ);
  }
}

Mat3 stress(const Mat3& gradU, Real lambda, Real mu) {
  const Mat3 eps = 0.5 * (gradU + gradU.transpose());
  return lambda * eps.trace() * Mat3::Identity() + 2 * mu * eps;
}

}  // namespace

Eigen::Vector2d lameParameters(Real E, Real nu) {
  return {E * nu / ((1 + nu) * (1 - 2 * nu)), E / (2 * (1 + nu))};
}

Mat38 hexShapeGradients(const Vec3& size, const Vec3& xi) {
  Mat38 G;
  for (int a = 0; a < 8; ++a) {
    const Vec3 s = 2 * hexCorner(a).cast<Real>() - Vec3::Ones();
    const Vec3 f = (Vec3::Ones() + s.cwiseProduct(xi));
    // dN/dxi_d = s_d / 8 * prod_{e != d} f_e, and dxi_d/dx_d = 2 / size_d.
    G(0, a) = s.x() / 8.0 * f.y() * f.z() * 2.0 / size.x();
    G(1, a) = s.y() / 8.0 * f.x() * f.z() * 2.0 / size.y();
    G(2, a) = s.z() / 8.0 * f.x() * f.y() * 2.0 / size.z();
  }
  return G;
}

Eigen::Matrix<Real, 8, 1> hexTrilinearWeights(const Vec3& t) {
  Eigen::Matrix<Real, 8, 1> w;
  for (int a = 0; a < 8; ++a) {
    const Vec3i c = hexCorner(a);
    w[a] = (c.x() ? t.x() : 1 - t.x()) * (c.y() ? t.y() : 1 - t.y()) * (c.z() ? t.z() : 1 - t.z());
  }
  return w;
}

Mat24 hexStiffness(const Vec3& size, Real young, Real poisson) {
  const Eigen::Vector2d lm = lameParameters(young, poisson);
  Eigen::Matrix<Real, 6, 6> D = Eigen::Matrix<Real, 6, 6>::Zero();
  D.topLeftCorner<3, 3>().setConstant(lm[0]);
  D.topLeftCorner<3, 3>().diagonal().array() += 2 * lm[1];
  D.bottomRightCorner<3, 3>().diagonal().setConstant(lm[1]);  // engineering shear strains
  Mat24 K = Mat24::Zero();
  forEachGaussPoint(size, [&](const Mat38& G, Real w) {
    Eigen::Matrix<Real, 6, 24> B = Eigen::Matrix<Real, 6, 24>::Zero();
    for (int a = 0; a < 8; ++a) {
      const Real gx = G(0, a), gy = G(1, a), gz = G(2, a);
      B(0, 3 * a) = gx;
      B(1, 3 * a + 1) = gy;
      B(2, 3 * a + 2) = gz;
      B(3, 3 * a) = gy;  // gamma_xy
      B(3, 3 * a + 1) = gx;
      B(4, 3 * a + 1) = gz;  // gamma_yz
      B(4, 3 * a + 2) = gy;
      B(5, 3 * a) = gz;  // gamma_zx
      B(5, 3 * a + 2) = gx;
    }
    K.noalias() += w * B.transpose() * D * B;
  });
  return 0.5 * (K + K.transpose());
}

namespace {

/// Strain-displacement rows of one column of displacement gradients g = d(phi)/dx for the
/// component `axis` (engineering shear strains, the order of elasticityMatrix).
void strainColumn(Eigen::Matrix<Real, 6, 1>& col, const Vec3& g, int axis) {
  col.setZero();
  col(axis) = g(axis);
  // gamma_xy (row 3), gamma_yz (row 4), gamma_zx (row 5) take the other two derivatives.
  const int shear[3][2] = {{3, 5}, {3, 4}, {5, 4}};  // rows touched by component axis
  const int along[3][2] = {{1, 2}, {0, 2}, {0, 1}};  // the derivative each row takes
  for (int k = 0; k < 2; ++k) col(shear[axis][k]) = g(along[axis][k]);
}

Eigen::Matrix<Real, 6, 6> elasticityMatrix(Real young, Real poisson) {
  const Eigen::Vector2d lm = lameParameters(young, poisson);
  Eigen::Matrix<Real, 6, 6> D = Eigen::Matrix<Real, 6, 6>::Zero();
  D.topLeftCorner<3, 3>().setConstant(lm[0]);
  D.topLeftCorner<3, 3>().diagonal().array() += 2 * lm[1];
  D.bottomRightCorner<3, 3>().diagonal().setConstant(lm[1]);
  return D;
}

}  // namespace

Mat24 hexStiffnessIncompatible(const Vec3& size, Real young, Real poisson) {
  const Eigen::Matrix<Real, 6, 6> D = elasticityMatrix(young, poisson);
  using Mat6x24 = Eigen::Matrix<Real, 6, 24>;
  using Mat6x9 = Eigen::Matrix<Real, 6, 9>;
  Mat24 Kuu = Mat24::Zero();
  Eigen::Matrix<Real, 24, 9> Kua = Eigen::Matrix<Real, 24, 9>::Zero();
  Eigen::Matrix<Real, 9, 9> Kaa = Eigen::Matrix<Real, 9, 9>::Zero();
  const Real w = size.prod() / 8.0;  // 2x2x2 Gauss, unit weights, detJ = V / 8
  for (int gp = 0; gp < 8; ++gp) {
    const Vec3 xi = kGauss * (2 * hexCorner(gp).cast<Real>() - Vec3::Ones());
    const Mat38 G = hexShapeGradients(size, xi);
    Mat6x24 B;
    Eigen::Matrix<Real, 6, 1> col;
    for (int a = 0; a < 8; ++a)
      for (int i = 0; i < 3; ++i) {
        strainColumn(col, G.col(a), i);
        B.col(3 * a + i) = col;
      }
    // Mode k (1 - xi_k^2): gradient -2 xi_k (2 / size_k) along axis k only.
    Mat6x9 Ba;
    for (int k = 0; k < 3; ++k) {
      Vec3 g = Vec3::Zero();
      g(k) = -4.0 * xi(k) / size(k);
      for (int i = 0; i < 3; ++i) {
        strainColumn(col, g, i);
        Ba.col(3 * k + i) = col;
      }
    }
    Kuu.noalias() += w * B.transpose() * D * B;
    Kua.noalias() += w * B.transpose() * D * Ba;
    Kaa.noalias() += w * Ba.transpose() * D * Ba;
  }
  const Mat24 K = Kuu - Kua * Kaa.ldlt().solve(Kua.transpose());
  return 0.5 * (K + K.transpose());
}

Real hexStrainEnergy(const Vec3& size, Real young, Real poisson, const Mat38& u) {
  const Eigen::Vector2d lm = lameParameters(young, poisson);
  Real W = 0;
  forEachGaussPoint(size, [&](const Mat38& G, Real w) {
    const Mat3 gradU = u * G.transpose();  // du_i/dx_j = sum_a u_a,i dN_a/dx_j
    const Mat3 eps = 0.5 * (gradU + gradU.transpose());
    W += 0.5 * w * (eps.cwiseProduct(stress(gradU, lm[0], lm[1]))).sum();
  });
  return W;
}

Mat38 hexElasticForce(const Vec3& size, Real young, Real poisson, const Mat38& u) {
  const Eigen::Vector2d lm = lameParameters(young, poisson);
  Mat38 f = Mat38::Zero();
  forEachGaussPoint(size, [&](const Mat38& G, Real w) {
    const Mat3 gradU = u * G.transpose();
    f.noalias() -= w * stress(gradU, lm[0], lm[1]) * G;
  });
  return f;
}

Mat3 hexCentreGradient(const Vec3& size, const Mat38& x) {
  return x * hexShapeGradients(size, Vec3::Zero()).transpose();
}

namespace {

/// The scalar lane of rotation_step.h.
using Lane = simd::ScalarLanes<double>;

Quat rotationFromSvd(const Mat3& F) {
  // The maximiser of tr(R^T F) over proper rotations: R = U diag(1, 1, det(U V^T)) V^T.
  const Eigen::JacobiSVD<Mat3> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 U = svd.matrixU();
  if ((U * svd.matrixV().transpose()).determinant() < 0) U.col(2) = -U.col(2);
  Quat q(Mat3(U * svd.matrixV().transpose()));
  q.normalize();
  return q;
}

}  // namespace

RotationExtraction extractRotationInfo(const Mat3& F, Quat& q, int maxIterations, Real tolerance) {
  RotationExtraction out;
  if (!F.allFinite() || !q.coeffs().allFinite()) return out;  // converged stays false
  // The step's arithmetic is rotation_step.h's, shared with the batch paths (rotation_batch.h).
  double qw = q.w(), qx = q.x(), qy = q.y(), qz = q.z();
  for (; out.iterations < maxIterations; ++out.iterations) {
    const auto s = rotation::rotationStep<Lane>(F.data(), qw, qx, qy, qz);
    double omega[3] = {s.omega[0], s.omega[1], s.omega[2]};
    double w = s.w;
    if (!(w > tolerance)) {
      out.converged = std::isfinite(w);
      break;
    }
    // After a Newton step of size w the angle left is at most about (||F|| / lambda_min(H)) w^2
    // (quadratic convergence); with ||F|| <= tr(A) near the maximum, lambda_max(H) <= tr(H) =
    // 2 tr(A) and lambda_min(H) >= det / lambda_max^2, that factor is at most 4 tr(A)^3 / det.
    // Where the step after this one would be below the tolerance, it is not taken: one
    // evaluation of g and H less per element and time step in the usual warm-started case.
    const bool last = s.newton && rotation::isLastStep<Lane>(w, s.trA, s.det, tolerance);
    if (w > 1) {  // a Newton step beyond a radian is outside its quadratic model
      for (double& o : omega) o /= w;
      w = 1;
    }
    // Near convergence (the usual case when warm-started) the first-order quaternion of the
    // axis-angle update avoids sin/cos; the fixed point omega = 0 is the same either way.
    if (w < 1e-3) {
      rotation::rotateAndNormalise<Lane>(1.0, 0.5 * omega[0], 0.5 * omega[1], 0.5 * omega[2], qw,
                                         qx, qy, qz);
    } else {
      const double sinHalf = std::sin(0.5 * w) / w;
      rotation::rotateAndNormalise<Lane>(std::cos(0.5 * w), sinHalf * omega[0], sinHalf * omega[1],
                                         sinHalf * omega[2], qw, qx, qy, qz);
    }
    if (last) {
      ++out.iterations;
      out.converged = true;
      break;
    }
  }
  q = Quat(qw, qx, qy, qz);
  if (!out.converged && out.iterations >= maxIterations) {
    // Far from the warm start (or a maximum too flat for Newton's step): the exact rotation.
    q = rotationFromSvd(F);
    out.svd = true;
    out.converged = q.coeffs().allFinite();
  }
  return out;
}

Mat3 rotationMatrixOf(const Quat& q) {
  Mat3 R;
  rotation::rotationMatrix<Lane>(q.w(), q.x(), q.y(), q.z(), R.data());
  return R;
}

int extractRotation(const Mat3& F, Quat& q, int maxIterations, Real tolerance) {
  return extractRotationInfo(F, q, maxIterations, tolerance).iterations;
}

Mat38 hexCorotationalForce(const Mat24& K0, const Mat3& R, const Mat38& x, const Mat38& X) {
  Mat38 local = R.transpose() * x - X;
  Vec24 f = -K0 * Eigen::Map<const Vec24>(local.data());
  Mat38 out = R * Eigen::Map<const Mat38>(f.data());
  return out;
}

}  // namespace deform::fem_hex
