#include "pbd_constraints.h"

#include <algorithm>

namespace deform::pbd {

namespace {

// Volume and gradient of a closed surface in one pass over the triangles.
Real volumeAndGradient(const MatX3& x, const MatX3i& F, MatX3& grad) {
  grad.setZero(x.rows(), 3);
  Real six = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const int a = F(f, 0), b = F(f, 1), c = F(f, 2);
    const Vec3 xa = x.row(a), xb = x.row(b), xc = x.row(c);
    const Vec3 bc = xb.cross(xc);
    six += xa.dot(bc);
    grad.row(a) += bc;
    grad.row(b) += xc.cross(xa);
    grad.row(c) += xa.cross(xb);
  }
  grad /= 6.0;
  return six / 6.0;
}

bool volumeMultiplier(const MatX3& x, const VecX& w, const MatX3i& F, Real restVolume,
                      Real alphaTilde, Real k, Real& lambda, MatX3& grad, Real& dl) {
  const Real vol = volumeAndGradient(x, F, grad);
  Real denom = 0;
  for (Eigen::Index i = 0; i < x.rows(); ++i) denom += w[i] * grad.row(i).squaredNorm();
  // Gradients are ~ area; a vanishing denominator means every particle is immovable or the
  // surface collapsed.
  if (!(denom > 0) || !std::isfinite(denom)) return false;
  dl = multiplierUpdate(vol - restVolume, denom, alphaTilde, k, lambda);
  lambda += dl;
  return true;
}

}  // namespace

// Three passes per chunk (gather, arithmetic, scatter) so that the middle pass, with its square
// root and division, runs on contiguous arrays and vectorises; this is exact because the
// constraints of one colour touch disjoint particles.
long long projectDistanceColour(Real* x, const Real* w, const DistanceBatch& batch, size_t begin,
                                size_t end) {
  constexpr size_t kChunk = 32;
  constexpr Real kTiny = tol::kDegenerateLength * tol::kDegenerateLength;
  alignas(64) Real d0[kChunk], d1[kChunk], d2[kChunk], s[kChunk];
  long long degenerate = 0;
  for (size_t c0 = begin; c0 < end; c0 += kChunk) {
    const size_t n = std::min(kChunk, end - c0);
    const int* a = batch.a + c0;
    const int* b = batch.b + c0;
    for (size_t k = 0; k < n; ++k) {
      const Real* xa = x + 3 * a[k];
      const Real* xb = x + 3 * b[k];
      d0[k] = xa[0] - xb[0];
      d1[k] = xa[1] - xb[1];
      d2[k] = xa[2] - xb[2];
    }
    const Real* rest = batch.rest + c0;
    const Real* at = batch.alphaTilde + c0;
    const Real* scale = batch.scale + c0;
    Real* __restrict lambda = batch.lambda + c0;
    for (size_t k = 0; k < n; ++k) {
      // Branch-free so that it vectorises: a degenerate constraint gets dl = 0.
      const Real len2 = d0[k] * d0[k] + d1[k] * d1[k] + d2[k] * d2[k];
      const Real ok = len2 > kTiny ? 1.0 : 0.0;
      const Real len = std::sqrt(std::max(len2, kTiny));
      const Real dl = ok * (scale[k] * (rest[k] - len - at[k] * lambda[k]));
      lambda[k] += dl;
      s[k] = dl / len;
      degenerate += static_cast<long long>(1.0 - ok);
    }
    for (size_t k = 0; k < n; ++k) {
      Real* xa = x + 3 * a[k];
      Real* xb = x + 3 * b[k];
      const Real sa = w[a[k]] * s[k], sb = w[b[k]] * s[k];
      xa[0] += sa * d0[k];
      xa[1] += sa * d1[k];
      xa[2] += sa * d2[k];
      xb[0] -= sb * d0[k];
      xb[1] -= sb * d1[k];
      xb[2] -= sb * d2[k];
    }
  }
  return degenerate;
}

bool projectSurfaceVolume(const MatX3& x, const VecX& w, const MatX3i& F, Real restVolume,
                          Real alphaTilde, Real k, Real& lambda, MatX3& grad, MatX3& dx) {
  Real dl = 0;
  if (!volumeMultiplier(x, w, F, restVolume, alphaTilde, k, lambda, grad, dl)) return false;
  dx.resize(x.rows(), 3);
  for (Eigen::Index i = 0; i < x.rows(); ++i) dx.row(i) = (w[i] * dl) * grad.row(i);
  return true;
}

bool projectSurfaceVolumeInPlace(MatX3& x, const VecX& w, const MatX3i& F, Real restVolume,
                                 Real alphaTilde, Real k, Real& lambda, MatX3& grad) {
  Real dl = 0;
  if (!volumeMultiplier(x, w, F, restVolume, alphaTilde, k, lambda, grad, dl)) return false;
  for (Eigen::Index i = 0; i < x.rows(); ++i) x.row(i) += (w[i] * dl) * grad.row(i);
  return true;
}

}  // namespace deform::pbd
