#include "pbd_constraints.h"

#include <deform/simd_rows.h>

#include <algorithm>

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#define DEFORM_PBD_HAVE_AVX2_PATH 1
#endif

namespace deform::pbd {

namespace {

// Volume and gradient of a closed surface in one pass over the triangles. The gradient uses
// one cross product per triangle: around a vertex a of a closed surface the terms x_a x x_b of
// the fan telescope away, so dV/dx_a = (1/6) sum_T (x_b x x_c) = (1/6) sum_T N_T with
// N_T = (x_b - x_a) x (x_c - x_a) (a third of the area-weighted normals), and
// V = (1/6) sum_T x_a . N_T. stride: doubles per particle in x and grad (3 or 4).
Real volumeAndGradient(const Real* x, Eigen::Index n, int stride, const MatX3i& F, Real* grad) {
  std::fill(grad, grad + n * stride, 0.0);
  Real six = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Real* xa = x + stride * F(f, 0);
    const Real* xb = x + stride * F(f, 1);
    const Real* xc = x + stride * F(f, 2);
    const Real u0 = xb[0] - xa[0], u1 = xb[1] - xa[1], u2 = xb[2] - xa[2];
    const Real v0 = xc[0] - xa[0], v1 = xc[1] - xa[1], v2 = xc[2] - xa[2];
    const Real N0 = u1 * v2 - u2 * v1, N1 = u2 * v0 - u0 * v2, N2 = u0 * v1 - u1 * v0;
    six += xa[0] * N0 + xa[1] * N1 + xa[2] * N2;
    for (int k = 0; k < 3; ++k) {
      Real* g = grad + stride * F(f, k);
      g[0] += N0;
      g[1] += N1;
      g[2] += N2;
    }
  }
  for (Eigen::Index i = 0; i < n * stride; ++i) grad[i] /= 6.0;
  return six / 6.0;
}

bool volumeMultiplier(const Real* x, Eigen::Index n, int stride, const Real* w, const MatX3i& F,
                      Real restVolume, Real alphaTilde, Real k, Real& lambda, Real* grad,
                      Real& dl) {
  const Real vol = volumeAndGradient(x, n, stride, F, grad);
  Real denom = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const Real* g = grad + stride * i;
    denom += w[i] * (g[0] * g[0] + g[1] * g[1] + g[2] * g[2]);
  }
  // Gradients are ~ area; a vanishing denominator means every particle is immovable or the
  // surface collapsed.
  if (!(denom > 0) || !std::isfinite(denom)) return false;
  dl = multiplierUpdate(vol - restVolume, denom, alphaTilde, k, lambda);
  lambda += dl;
  return true;
}

// x += dl * w * grad, row by row.
void applyVolumeCorrection(Real* x, Eigen::Index n, int stride, const Real* w, const Real* grad,
                           Real dl) {
  for (Eigen::Index i = 0; i < n; ++i) {
    const Real s = w[i] * dl;
    for (int k = 0; k < 3; ++k) x[stride * i + k] += s * grad[stride * i + k];
  }
}

}  // namespace

namespace {

// One constraint on padded positions, the scalar reference of the SIMD path below.
inline long long projectPaddedOne(Real* x4, const DistanceBatch& batch, size_t i) {
  constexpr Real kTiny = tol::kDegenerateLength * tol::kDegenerateLength;
  Real* xa = x4 + 4 * static_cast<size_t>(batch.a[i]);
  Real* xb = x4 + 4 * static_cast<size_t>(batch.b[i]);
  const Real d0 = xa[0] - xb[0], d1 = xa[1] - xb[1], d2 = xa[2] - xb[2];
  const Real len2 = d0 * d0 + d1 * d1 + d2 * d2;
  const bool ok = len2 > kTiny;
  const Real len = std::sqrt(std::max(len2, kTiny));
  const Real dl =
      ok ? batch.scale[i] * (batch.rest[i] - len - batch.alphaTilde[i] * batch.lambda[i]) : 0.0;
  batch.lambda[i] += dl;
  const Real s = dl / len;
  const Real sa = batch.wa[i] * s, sb = batch.wb[i] * s;
  xa[0] += sa * d0;
  xa[1] += sa * d1;
  xa[2] += sa * d2;
  xb[0] -= sb * d0;
  xb[1] -= sb * d1;
  xb[2] -= sb * d2;
  return ok ? 0 : 1;
}

#ifdef DEFORM_PBD_HAVE_AVX2_PATH
// Four constraints of one colour: loads and arithmetic (compute), then the stores (commit). The
// caller computes two groups before committing either, so that the two sqrt/div latency chains
// overlap.
struct Group4 {
  Real* pa[4];
  Real* pb[4];
  __m256d xa[4], xb[4], d[4];
  alignas(32) Real sa[4];
  alignas(32) Real sb[4];
  int ok = 0;
};

__attribute__((target("avx2"), always_inline)) inline void computeGroup4(Real* x4,
                                                                         const DistanceBatch& batch,
                                                                         size_t i, Group4& g) {
  const __m256d tiny = _mm256_set1_pd(tol::kDegenerateLength * tol::kDegenerateLength);
  for (int k = 0; k < 4; ++k) {
    g.pa[k] = x4 + 4 * static_cast<size_t>(batch.a[i + k]);
    g.pb[k] = x4 + 4 * static_cast<size_t>(batch.b[i + k]);
    g.xa[k] = _mm256_loadu_pd(g.pa[k]);
    g.xb[k] = _mm256_loadu_pd(g.pb[k]);
    g.d[k] = _mm256_sub_pd(g.xa[k], g.xb[k]);  // lane 3: 0 - 0
  }
  // Transpose the four (dx, dy, dz, 0) rows into dx, dy, dz columns.
  const __m256d t0 = _mm256_unpacklo_pd(g.d[0], g.d[1]);  // d0x d1x d0z d1z
  const __m256d t1 = _mm256_unpackhi_pd(g.d[0], g.d[1]);  // d0y d1y d0w d1w
  const __m256d t2 = _mm256_unpacklo_pd(g.d[2], g.d[3]);
  const __m256d t3 = _mm256_unpackhi_pd(g.d[2], g.d[3]);
  const __m256d dx = _mm256_permute2f128_pd(t0, t2, 0x20);
  const __m256d dy = _mm256_permute2f128_pd(t1, t3, 0x20);
  const __m256d dz = _mm256_permute2f128_pd(t0, t2, 0x31);
  const __m256d len2 = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
                                     _mm256_mul_pd(dz, dz));
  const __m256d ok = _mm256_cmp_pd(len2, tiny, _CMP_GT_OQ);
  const __m256d len = _mm256_sqrt_pd(_mm256_max_pd(len2, tiny));
  __m256d lambda = _mm256_loadu_pd(batch.lambda + i);
  const __m256d inner = _mm256_sub_pd(_mm256_sub_pd(_mm256_loadu_pd(batch.rest + i), len),
                                      _mm256_mul_pd(_mm256_loadu_pd(batch.alphaTilde + i), lambda));
  const __m256d dl = _mm256_and_pd(ok, _mm256_mul_pd(_mm256_loadu_pd(batch.scale + i), inner));
  lambda = _mm256_add_pd(lambda, dl);
  _mm256_storeu_pd(batch.lambda + i, lambda);
  const __m256d s = _mm256_div_pd(dl, len);
  _mm256_store_pd(g.sa, _mm256_mul_pd(_mm256_loadu_pd(batch.wa + i), s));
  _mm256_store_pd(g.sb, _mm256_mul_pd(_mm256_loadu_pd(batch.wb + i), s));
  g.ok = __builtin_popcount(_mm256_movemask_pd(ok));
}

__attribute__((target("avx2"), always_inline)) inline void commitGroup4(const Group4& g) {
  for (int k = 0; k < 4; ++k) {
    _mm256_storeu_pd(g.pa[k],
                     _mm256_add_pd(g.xa[k], _mm256_mul_pd(_mm256_set1_pd(g.sa[k]), g.d[k])));
    _mm256_storeu_pd(g.pb[k],
                     _mm256_sub_pd(g.xb[k], _mm256_mul_pd(_mm256_set1_pd(g.sb[k]), g.d[k])));
  }
}

__attribute__((target("avx2"))) long long projectPaddedAvx2(Real* x4, const DistanceBatch& batch,
                                                            size_t begin, size_t end) {
  long long degenerate = 0;
  size_t i = begin;
  Group4 g0, g1;
  for (; i + 8 <= end; i += 8) {
    computeGroup4(x4, batch, i, g0);
    computeGroup4(x4, batch, i + 4, g1);
    commitGroup4(g0);
    commitGroup4(g1);
    degenerate += 8 - g0.ok - g1.ok;
  }
  for (; i + 4 <= end; i += 4) {
    computeGroup4(x4, batch, i, g0);
    commitGroup4(g0);
    degenerate += 4 - g0.ok;
  }
  for (; i < end; ++i) degenerate += projectPaddedOne(x4, batch, i);
  return degenerate;
}

// Eight constraints of one colour per step with AVX-512 (zmm arithmetic on columns, ymm rows).
// 1/len comes from the 14-bit estimate rsqrt14 refined by two Newton steps,
// y <- y (3/2 - x y^2 / 2), which gives a relative error below 2^-52 (14 -> 28 -> 56 bits), so
// len = len^2 y and dl / len = dl y differ from the sqrt/div path by rounding only; this removes
// the sqrt and the division, the two slowest instructions of the kernel.
__attribute__((target("avx512f,avx512vl,avx512dq"))) long long projectPaddedAvx512(
    Real* x4, const DistanceBatch& batch, size_t begin, size_t end) {
  const __m512d tiny = _mm512_set1_pd(tol::kDegenerateLength * tol::kDegenerateLength);
  const __m512d half = _mm512_set1_pd(0.5), threeHalf = _mm512_set1_pd(1.5);
  long long degenerate = 0;
  size_t i = begin;
  for (; i + 8 <= end; i += 8) {
    Real* pa[8];
    Real* pb[8];
    __m256d xa[8], xb[8], d[8];
    for (int k = 0; k < 8; ++k) {
      pa[k] = x4 + 4 * static_cast<size_t>(batch.a[i + k]);
      pb[k] = x4 + 4 * static_cast<size_t>(batch.b[i + k]);
      xa[k] = _mm256_loadu_pd(pa[k]);
      xb[k] = _mm256_loadu_pd(pb[k]);
      d[k] = _mm256_sub_pd(xa[k], xb[k]);  // lane 3: 0 - 0
    }
    // Rows (dx, dy, dz, 0) of constraints 0..7 -> columns dx, dy, dz in constraint order.
    const __m512d z0 = _mm512_insertf64x4(_mm512_castpd256_pd512(d[0]), d[2], 1);
    const __m512d z1 = _mm512_insertf64x4(_mm512_castpd256_pd512(d[1]), d[3], 1);
    const __m512d z2 = _mm512_insertf64x4(_mm512_castpd256_pd512(d[4]), d[6], 1);
    const __m512d z3 = _mm512_insertf64x4(_mm512_castpd256_pd512(d[5]), d[7], 1);
    const __m512d t0 = _mm512_unpacklo_pd(z0, z1);  // (0x 1x)(0z 1z)(2x 3x)(2z 3z)
    const __m512d t1 = _mm512_unpackhi_pd(z0, z1);  // (0y 1y)(0w 1w)(2y 3y)(2w 3w)
    const __m512d t2 = _mm512_unpacklo_pd(z2, z3);
    const __m512d t3 = _mm512_unpackhi_pd(z2, z3);
    const __m512d dx = _mm512_shuffle_f64x2(t0, t2, 0x88);
    const __m512d dy = _mm512_shuffle_f64x2(t1, t3, 0x88);
    const __m512d dz = _mm512_shuffle_f64x2(t0, t2, 0xDD);
    const __m512d len2 = _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(dx, dx), _mm512_mul_pd(dy, dy)),
                                       _mm512_mul_pd(dz, dz));
    const __mmask8 ok = _mm512_cmp_pd_mask(len2, tiny, _CMP_GT_OQ);
    const __m512d l2 = _mm512_max_pd(len2, tiny);
    const __m512d hx = _mm512_mul_pd(half, l2);
    __m512d y = _mm512_rsqrt14_pd(l2);
    y = _mm512_mul_pd(y, _mm512_sub_pd(threeHalf, _mm512_mul_pd(hx, _mm512_mul_pd(y, y))));
    y = _mm512_mul_pd(y, _mm512_sub_pd(threeHalf, _mm512_mul_pd(hx, _mm512_mul_pd(y, y))));
    const __m512d len = _mm512_mul_pd(l2, y);
    __m512d lambda = _mm512_loadu_pd(batch.lambda + i);
    const __m512d inner =
        _mm512_sub_pd(_mm512_sub_pd(_mm512_loadu_pd(batch.rest + i), len),
                      _mm512_mul_pd(_mm512_loadu_pd(batch.alphaTilde + i), lambda));
    const __m512d dl = _mm512_maskz_mul_pd(ok, _mm512_loadu_pd(batch.scale + i), inner);
    lambda = _mm512_add_pd(lambda, dl);
    _mm512_storeu_pd(batch.lambda + i, lambda);
    const __m512d s = _mm512_mul_pd(dl, y);
    const __m512d sa = _mm512_mul_pd(_mm512_loadu_pd(batch.wa + i), s);
    const __m512d sb = _mm512_mul_pd(_mm512_loadu_pd(batch.wb + i), s);
    // Corrections as columns, back to rows (cx, cy, cz, 0): p holds (x, y) pairs of rows
    // (0, 2, 4, 6) or (1, 3, 5, 7) by chunk, q the (z, 0) pairs; one two-source permute gives
    // rows k (low half) and k + 2 (high half).
    simd::commitRows8(sa, dx, dy, dz, pa, xa, true);
    simd::commitRows8(sb, dx, dy, dz, pb, xb, false);
    degenerate += 8 - __builtin_popcount(ok);
  }
  if (i < end) degenerate += projectPaddedAvx2(x4, batch, i, end);
  return degenerate;
}
#endif

}  // namespace

bool distanceSimdAvailable() {
#ifdef DEFORM_PBD_HAVE_AVX2_PATH
  return __builtin_cpu_supports("avx2");
#else
  return false;
#endif
}

long long projectDistanceColourPadded(Real* x4, const DistanceBatch& batch, size_t begin,
                                      size_t end, bool simd) {
#ifdef DEFORM_PBD_HAVE_AVX2_PATH
  static const bool kAvx2 = distanceSimdAvailable();
  static const bool kAvx512 = kAvx2 && __builtin_cpu_supports("avx512f") &&
                              __builtin_cpu_supports("avx512vl") &&
                              __builtin_cpu_supports("avx512dq");
  if (simd && kAvx512) return projectPaddedAvx512(x4, batch, begin, end);
  if (simd && kAvx2) return projectPaddedAvx2(x4, batch, begin, end);
#endif
  long long degenerate = 0;
  for (size_t i = begin; i < end; ++i) degenerate += projectPaddedOne(x4, batch, i);
  return degenerate;
}

bool projectSurfaceVolume(const MatX3& x, const VecX& w, const MatX3i& F, Real restVolume,
                          Real alphaTilde, Real k, Real& lambda, MatX3& grad, MatX3& dx) {
  Real dl = 0;
  grad.resize(x.rows(), 3);
  if (!volumeMultiplier(x.data(), x.rows(), 3, w.data(), F, restVolume, alphaTilde, k, lambda,
                        grad.data(), dl))
    return false;
  dx.setZero(x.rows(), 3);
  applyVolumeCorrection(dx.data(), x.rows(), 3, w.data(), grad.data(), dl);
  return true;
}

bool projectSurfaceVolumeInPlace(MatX3& x, const VecX& w, const MatX3i& F, Real restVolume,
                                 Real alphaTilde, Real k, Real& lambda, MatX3& grad) {
  Real dl = 0;
  grad.resize(x.rows(), 3);
  if (!volumeMultiplier(x.data(), x.rows(), 3, w.data(), F, restVolume, alphaTilde, k, lambda,
                        grad.data(), dl))
    return false;
  applyVolumeCorrection(x.data(), x.rows(), 3, w.data(), grad.data(), dl);
  return true;
}

bool projectSurfaceVolumePadded(Real* x4, Eigen::Index n, const Real* w, const MatX3i& F,
                                Real restVolume, Real alphaTilde, Real k, Real& lambda,
                                Real* grad4) {
  Real dl = 0;
  if (!volumeMultiplier(x4, n, 4, w, F, restVolume, alphaTilde, k, lambda, grad4, dl)) return false;
  applyVolumeCorrection(x4, n, 4, w, grad4, dl);
  return true;
}

}  // namespace deform::pbd
