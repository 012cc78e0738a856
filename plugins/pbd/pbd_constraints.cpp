#include "pbd_constraints.h"

// GCC 12 reports -Wmaybe-uninitialized inside its own AVX-512 intrinsics (their _mm512_undefined_*
// pass-through operands, GCC bug 105593, fixed in GCC 13); nothing in this file is uninitialised.
#if defined(__GNUC__) && !defined(__clang__) && __GNUC__ < 13
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif

#include <deform/kernels/simd_rows.h>

#include <algorithm>
#include <type_traits>
#include <vector>

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
// V = (1/6) sum_T x_a . N_T. stride: values per particle in x and grad (3 or 4). T: double, or
// float for the single-precision solver (the volume is still summed in double).
template <class T>
Real volumeAndGradient(const T* x, Eigen::Index n, int stride, const MatX3i& F, T* grad) {
  if (grad != nullptr) std::fill(grad, grad + n * stride, T(0));
  Real six = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const T* xa = x + stride * F(f, 0);
    const T* xb = x + stride * F(f, 1);
    const T* xc = x + stride * F(f, 2);
    const T u0 = xb[0] - xa[0], u1 = xb[1] - xa[1], u2 = xb[2] - xa[2];
    const T v0 = xc[0] - xa[0], v1 = xc[1] - xa[1], v2 = xc[2] - xa[2];
    const T N0 = u1 * v2 - u2 * v1, N1 = u2 * v0 - u0 * v2, N2 = u0 * v1 - u1 * v0;
    six += xa[0] * N0 + xa[1] * N1 + xa[2] * N2;
    if (grad == nullptr) continue;
    for (int k = 0; k < 3; ++k) {
      T* g = grad + stride * F(f, k);
      g[0] += N0;
      g[1] += N1;
      g[2] += N2;
    }
  }
  if (grad != nullptr)
    for (Eigen::Index i = 0; i < n * stride; ++i) grad[i] /= T(6);
  return six / 6.0;
}

#ifdef DEFORM_PBD_HAVE_AVX2_PATH
// volumeAndGradient<float> on padded rows with SSE: the same operations in the same order as the
// scalar template (N_k = u_{k+1} v_{k+2} - u_{k+2} v_{k+1}, the dot summed x + y then + z), so
// the results are identical; a row costs one load and one store instead of three of each.
Real volumeAndGradientRowsF(const float* x, Eigen::Index n, const MatX3i& F, float* grad) {
  std::fill(grad, grad + 4 * n, 0.0f);
  Real six = 0;
  const int* f = F.data();  // row-major #F by 3
  for (Eigen::Index t = 0; t < F.rows(); ++t, f += 3) {
    const __m128 xa = _mm_load_ps(x + 4 * static_cast<size_t>(f[0]));
    const __m128 u = _mm_sub_ps(_mm_load_ps(x + 4 * static_cast<size_t>(f[1])), xa);
    const __m128 v = _mm_sub_ps(_mm_load_ps(x + 4 * static_cast<size_t>(f[2])), xa);
    // yzx and zxy lane rotations of (x, y, z, 0).
    const __m128 u1 = _mm_shuffle_ps(u, u, _MM_SHUFFLE(3, 0, 2, 1));
    const __m128 u2 = _mm_shuffle_ps(u, u, _MM_SHUFFLE(3, 1, 0, 2));
    const __m128 v1 = _mm_shuffle_ps(v, v, _MM_SHUFFLE(3, 0, 2, 1));
    const __m128 v2 = _mm_shuffle_ps(v, v, _MM_SHUFFLE(3, 1, 0, 2));
    const __m128 N = _mm_sub_ps(_mm_mul_ps(u1, v2), _mm_mul_ps(u2, v1));
    alignas(16) float p[4];
    _mm_store_ps(p, _mm_mul_ps(xa, N));
    six += p[0] + p[1] + p[2];
    for (int k = 0; k < 3; ++k) {
      float* g = grad + 4 * static_cast<size_t>(f[k]);
      _mm_store_ps(g, _mm_add_ps(_mm_load_ps(g), N));
    }
  }
  const __m128 sixth = _mm_set1_ps(6.0f);
  for (Eigen::Index i = 0; i < n; ++i)
    _mm_store_ps(grad + 4 * i, _mm_div_ps(_mm_load_ps(grad + 4 * i), sixth));
  return six / 6.0;
}
#endif

template <class T>
bool volumeMultiplier(const T* x, Eigen::Index n, int stride, const Real* w, const MatX3i& F,
                      Real restVolume, Real alphaTilde, Real k, Real& lambda, T* grad, Real& dl,
                      bool rowsSimd = false) {
  Real vol;
#ifdef DEFORM_PBD_HAVE_AVX2_PATH
  if constexpr (std::is_same_v<T, float>)
    vol =
        rowsSimd ? volumeAndGradientRowsF(x, n, F, grad) : volumeAndGradient(x, n, stride, F, grad);
  else
#endif
    vol = volumeAndGradient(x, n, stride, F, grad);
  Real denom = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const T* g = grad + stride * i;
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
template <class T>
void applyVolumeCorrection(T* x, Eigen::Index n, int stride, const Real* w, const T* grad,
                           Real dl) {
  for (Eigen::Index i = 0; i < n; ++i) {
    const T s = static_cast<T>(w[i] * dl);
    for (int k = 0; k < 3; ++k) x[stride * i + k] += s * grad[stride * i + k];
  }
}

}  // namespace

namespace {

// One distance constraint on padded rows, in double or float: d = x_a - x_b and |d| (clamped
// below by the degenerate length; ok says it was not clamped), then the XPBD update
// dl = scale (rest - |d| - alphaTilde lambda) moving a and b along d. The scalar reference of the
// SIMD paths below; lengthOne is also the rest length of the single-precision batches, so that a
// constraint at rest sees C = 0 exactly.
template <class T>
inline T lengthOne(const T* xa, const T* xb, T d[3], bool& ok) {
  constexpr T kTiny = static_cast<T>(tol::kDegenerateLength * tol::kDegenerateLength);
  d[0] = xa[0] - xb[0];
  d[1] = xa[1] - xb[1];
  d[2] = xa[2] - xb[2];
  const T len2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
  ok = len2 > kTiny;
  return std::sqrt(std::max(len2, kTiny));
}

template <class T, class Batch>
inline long long projectPairOne(T* xa, T* xb, const Batch& batch, size_t i) {
  T d[3];
  bool ok;
  const T len = lengthOne(xa, xb, d, ok);
  const T dl =
      ok ? batch.scale[i] * (batch.rest[i] - len - batch.alphaTilde[i] * batch.lambda[i]) : T(0);
  batch.lambda[i] += dl;
  const T s = dl / len;
  const T sa = batch.wa[i] * s, sb = batch.wb[i] * s;
  for (int k = 0; k < 3; ++k) {
    xa[k] += sa * d[k];
    xb[k] -= sb * d[k];
  }
  return ok ? 0 : 1;
}

// |x_a - x_b| as the projection measures it (the rest lengths of the float batches).
inline float lengthOf(const float* xa, const float* xb) {
  float d[3];
  bool ok;
  return lengthOne(xa, xb, d, ok);
}

// Double rows: the batch holds particle indices.
inline long long projectPaddedOne(Real* x4, const DistanceBatch& batch, size_t i) {
  return projectPairOne(x4 + 4 * static_cast<size_t>(batch.a[i]),
                        x4 + 4 * static_cast<size_t>(batch.b[i]), batch, i);
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

// Single precision: the batch holds row offsets (4 * particle index).
inline long long projectPaddedOneF(float* x4, const DistanceBatchF& batch, size_t i) {
  return projectPairOne(x4 + batch.a[i], x4 + batch.b[i], batch, i);
}

#ifdef DEFORM_PBD_HAVE_AVX2_PATH
#define DEFORM_PBD_AVX512 __attribute__((target("avx512f,avx512vl,avx512dq"), always_inline)) inline

// Sixteen constraints of one colour per step. The step is bound by instruction throughput (the
// row loads and stores, not the arithmetic: dropping the stores halves its time), so it is
// written for few instructions per constraint: particle offsets are pre-scaled (one load, then
// base + index * 4 addressing), the row differences d_k stay in registers, and the corrections
// go back as x += (w dl / |d|)_k d_k with the factor broadcast inside its 128-bit chunk.
struct LengthsF16 {
  __m512 y;    // 1 / |d|
  __m512 len;  // |d|
  __mmask16 ok;
};

// Loads the rows of constraints i .. i + 15 and returns d_k = x_a - x_b (lane 3: 0 - 0) and the
// lengths. The rows of constraints 4j + k go to 128-bit chunk j of Z_k; a 4 x 4 transpose inside
// each chunk then gives columns dx, dy, dz in constraint order. 1/|d| comes from rsqrt14 refined
// by one Newton step, y <- y (3/2 - x y^2 / 2) (relative error ~2^-27, below float rounding).
DEFORM_PBD_AVX512 LengthsF16 lengthsF16(const float* x4, const int* A, const int* B, __m128* d) {
  const __m512 tiny =
      _mm512_set1_ps(static_cast<float>(tol::kDegenerateLength * tol::kDegenerateLength));
  const __m512 half = _mm512_set1_ps(0.5f), threeHalf = _mm512_set1_ps(1.5f);
#pragma GCC unroll 16
  for (int k = 0; k < 16; ++k) d[k] = _mm_sub_ps(_mm_load_ps(x4 + A[k]), _mm_load_ps(x4 + B[k]));
  __m512 z[4];
  for (int k = 0; k < 4; ++k)
    z[k] = _mm512_insertf32x4(
        _mm512_insertf32x4(_mm512_insertf32x4(_mm512_zextps128_ps512(d[k]), d[k + 4], 1), d[k + 8],
                           2),
        d[k + 12], 3);
  const __m512 t0 = _mm512_unpacklo_ps(z[0], z[1]);  // per chunk j: a.x b.x a.y b.y
  const __m512 t1 = _mm512_unpackhi_ps(z[0], z[1]);  // a.z b.z a.w b.w (a = 4j, b = 4j + 1)
  const __m512 t2 = _mm512_unpacklo_ps(z[2], z[3]);
  const __m512 t3 = _mm512_unpackhi_ps(z[2], z[3]);
  const __m512 dx = _mm512_shuffle_ps(t0, t2, 0x44);
  const __m512 dy = _mm512_shuffle_ps(t0, t2, 0xEE);
  const __m512 dz = _mm512_shuffle_ps(t1, t3, 0x44);
  const __m512 len2 = _mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(dx, dx), _mm512_mul_ps(dy, dy)),
                                    _mm512_mul_ps(dz, dz));
  LengthsF16 r;
  r.ok = _mm512_cmp_ps_mask(len2, tiny, _CMP_GT_OQ);
  const __m512 l2 = _mm512_max_ps(len2, tiny);
  const __m512 y0 = _mm512_rsqrt14_ps(l2);
  r.y = _mm512_mul_ps(
      y0, _mm512_sub_ps(threeHalf, _mm512_mul_ps(_mm512_mul_ps(half, l2), _mm512_mul_ps(y0, y0))));
  r.len = _mm512_mul_ps(l2, r.y);
  // |d| is rounded here, as distanceLengthsColourF stores it: without this barrier the compiler
  // fuses rest - l2 y into one multiply-add, and a constraint at rest would see C != 0.
  asm("" : "+v"(r.len));
  return r;
}

// Rows 4j .. 4j + 3 of a group: x_a += sa_k d_k, x_b -= sb_k d_k with the factors broadcast
// from 128-bit chunk j of sa / sb.
template <int j>
DEFORM_PBD_AVX512 void commitChunkF4(float* x4, const int* A, const int* B, __m512 sa, __m512 sb,
                                     const __m128* d) {
  const __m128 ca = _mm512_extractf32x4_ps(sa, j), cb = _mm512_extractf32x4_ps(sb, j);
  const auto row = [&]<int m>() {
    float* pa = x4 + A[4 * j + m];
    float* pb = x4 + B[4 * j + m];
    const __m128 fa = _mm_shuffle_ps(ca, ca, m * 0x55), fb = _mm_shuffle_ps(cb, cb, m * 0x55);
    _mm_store_ps(pa, _mm_add_ps(_mm_load_ps(pa), _mm_mul_ps(fa, d[4 * j + m])));
    _mm_store_ps(pb, _mm_sub_ps(_mm_load_ps(pb), _mm_mul_ps(fb, d[4 * j + m])));
  };
  row.template operator()<0>();
  row.template operator()<1>();
  row.template operator()<2>();
  row.template operator()<3>();
}

__attribute__((target("avx512f,avx512vl,avx512dq"))) long long projectPaddedF512(
    float* x4, const DistanceBatchF& batch, size_t begin, size_t end) {
  long long degenerate = 0;
  size_t i = begin;
  for (; i + 16 <= end; i += 16) {
    const int* A = batch.a + i;
    const int* B = batch.b + i;
    __m128 d[16];
    const LengthsF16 l = lengthsF16(x4, A, B, d);
    const __m512 lambda = _mm512_loadu_ps(batch.lambda + i);
    const __m512 inner =
        _mm512_sub_ps(_mm512_sub_ps(_mm512_loadu_ps(batch.rest + i), l.len),
                      _mm512_mul_ps(_mm512_loadu_ps(batch.alphaTilde + i), lambda));
    const __m512 dl = _mm512_maskz_mul_ps(l.ok, _mm512_loadu_ps(batch.scale + i), inner);
    _mm512_storeu_ps(batch.lambda + i, _mm512_add_ps(lambda, dl));
    const __m512 s = _mm512_mul_ps(dl, l.y);
    const __m512 sa = _mm512_mul_ps(_mm512_loadu_ps(batch.wa + i), s);
    const __m512 sb = _mm512_mul_ps(_mm512_loadu_ps(batch.wb + i), s);
    // Reload the particle offsets below instead of keeping 32 addresses alive across the
    // arithmetic (the compiler would park them in vector registers: more instructions).
    asm volatile("" ::: "memory");
    commitChunkF4<0>(x4, A, B, sa, sb, d);
    commitChunkF4<1>(x4, A, B, sa, sb, d);
    commitChunkF4<2>(x4, A, B, sa, sb, d);
    commitChunkF4<3>(x4, A, B, sa, sb, d);
    degenerate += 16 - __builtin_popcount(l.ok);
  }
  for (; i < end; ++i) degenerate += projectPaddedOneF(x4, batch, i);
  return degenerate;
}

// Eight constraints of one colour per step with AVX2 (CPUs without AVX-512). Unlike the AVX-512
// step, |d| and the division are the scalar reference's own (sqrt and divide, each exactly
// rounded, and no multiply-add: AVX2 does not imply FMA), so this path and the scalar one agree
// bit for bit, and rest lengths measured by the scalar lengthOf are at rest here too. A group is
// computed (loads and arithmetic), then committed (the stores); the loop computes two groups
// before committing either, so that their sqrt / divide latency chains overlap.
struct GroupF8 {
  const int* A;
  const int* B;
  __m128 d[8];  // the rows' differences x_a - x_b (lane 3: 0 - 0)
  __m256 sa, sb;
  int ok;
};

__attribute__((target("avx2"), always_inline)) inline void computeGroupF8(
    const float* x4, const DistanceBatchF& batch, size_t i, GroupF8& g) {
  const __m256 tiny =
      _mm256_set1_ps(static_cast<float>(tol::kDegenerateLength * tol::kDegenerateLength));
  g.A = batch.a + i;
  g.B = batch.b + i;
#pragma GCC unroll 8
  for (int k = 0; k < 8; ++k)
    g.d[k] = _mm_sub_ps(_mm_load_ps(x4 + g.A[k]), _mm_load_ps(x4 + g.B[k]));
  // Rows of constraints 4j + m go to 128-bit lane j of z_m; a 4 x 4 transpose inside each lane
  // gives columns dx, dy, dz in constraint order.
  __m256 z[4];
  for (int k = 0; k < 4; ++k)
    z[k] = _mm256_insertf128_ps(_mm256_castps128_ps256(g.d[k]), g.d[k + 4], 1);
  const __m256 t0 = _mm256_unpacklo_ps(z[0], z[1]);  // per lane: a.x b.x a.y b.y
  const __m256 t1 = _mm256_unpackhi_ps(z[0], z[1]);  // a.z b.z a.w b.w
  const __m256 t2 = _mm256_unpacklo_ps(z[2], z[3]);
  const __m256 t3 = _mm256_unpackhi_ps(z[2], z[3]);
  const __m256 dx = _mm256_shuffle_ps(t0, t2, 0x44);
  const __m256 dy = _mm256_shuffle_ps(t0, t2, 0xEE);
  const __m256 dz = _mm256_shuffle_ps(t1, t3, 0x44);
  const __m256 len2 = _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(dx, dx), _mm256_mul_ps(dy, dy)),
                                    _mm256_mul_ps(dz, dz));
  const __m256 ok = _mm256_cmp_ps(len2, tiny, _CMP_GT_OQ);
  // max(tiny, len2) keeps a NaN len2, as std::max(len2, tiny) does.
  const __m256 len = _mm256_sqrt_ps(_mm256_max_ps(tiny, len2));
  const __m256 lambda = _mm256_loadu_ps(batch.lambda + i);
  const __m256 inner = _mm256_sub_ps(_mm256_sub_ps(_mm256_loadu_ps(batch.rest + i), len),
                                     _mm256_mul_ps(_mm256_loadu_ps(batch.alphaTilde + i), lambda));
  const __m256 dl = _mm256_and_ps(ok, _mm256_mul_ps(_mm256_loadu_ps(batch.scale + i), inner));
  _mm256_storeu_ps(batch.lambda + i, _mm256_add_ps(lambda, dl));
  const __m256 s = _mm256_div_ps(dl, len);
  g.sa = _mm256_mul_ps(_mm256_loadu_ps(batch.wa + i), s);
  g.sb = _mm256_mul_ps(_mm256_loadu_ps(batch.wb + i), s);
  g.ok = __builtin_popcount(_mm256_movemask_ps(ok));
}

// x_a += sa_k d_k and x_b -= sb_k d_k for the rows of lane j, the factors broadcast in the lane.
template <int j>
__attribute__((target("avx2"), always_inline)) inline void commitLaneF4(float* x4,
                                                                        const GroupF8& g) {
  const __m128 ca = j == 0 ? _mm256_castps256_ps128(g.sa) : _mm256_extractf128_ps(g.sa, 1);
  const __m128 cb = j == 0 ? _mm256_castps256_ps128(g.sb) : _mm256_extractf128_ps(g.sb, 1);
  const auto row = [&]<int m>() {
    float* pa = x4 + g.A[4 * j + m];
    float* pb = x4 + g.B[4 * j + m];
    const __m128 fa = _mm_shuffle_ps(ca, ca, m * 0x55), fb = _mm_shuffle_ps(cb, cb, m * 0x55);
    _mm_store_ps(pa, _mm_add_ps(_mm_load_ps(pa), _mm_mul_ps(fa, g.d[4 * j + m])));
    _mm_store_ps(pb, _mm_sub_ps(_mm_load_ps(pb), _mm_mul_ps(fb, g.d[4 * j + m])));
  };
  row.template operator()<0>();
  row.template operator()<1>();
  row.template operator()<2>();
  row.template operator()<3>();
}

__attribute__((target("avx2"))) long long projectPaddedF256(float* x4, const DistanceBatchF& batch,
                                                            size_t begin, size_t end) {
  long long degenerate = 0;
  size_t i = begin;
  GroupF8 g0, g1;
  for (; i + 16 <= end; i += 16) {
    computeGroupF8(x4, batch, i, g0);
    computeGroupF8(x4, batch, i + 8, g1);
    commitLaneF4<0>(x4, g0);
    commitLaneF4<1>(x4, g0);
    commitLaneF4<0>(x4, g1);
    commitLaneF4<1>(x4, g1);
    degenerate += 16 - g0.ok - g1.ok;
  }
  for (; i + 8 <= end; i += 8) {
    computeGroupF8(x4, batch, i, g0);
    commitLaneF4<0>(x4, g0);
    commitLaneF4<1>(x4, g0);
    degenerate += 8 - g0.ok;
  }
  for (; i < end; ++i) degenerate += projectPaddedOneF(x4, batch, i);
  return degenerate;
}

__attribute__((target("avx512f,avx512vl,avx512dq"))) void lengthsF512(const float* x4, const int* a,
                                                                      const int* b, size_t begin,
                                                                      size_t end, float* len) {
  size_t i = begin;
  for (; i + 16 <= end; i += 16) {
    __m128 d[16];
    _mm512_storeu_ps(len + i, lengthsF16(x4, a + i, b + i, d).len);
  }
  for (; i < end; ++i) len[i] = lengthOf(x4 + a[i], x4 + b[i]);
}
#undef DEFORM_PBD_AVX512
#endif

}  // namespace

// The CPU's vector units, checked once per process by the callers (static locals).
bool distanceSimdAvailable() {
#ifdef DEFORM_PBD_HAVE_AVX2_PATH
  return __builtin_cpu_supports("avx2");
#else
  return false;
#endif
}

bool distanceSimdFloatAvailable() {
#ifdef DEFORM_PBD_HAVE_AVX2_PATH
  return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
         __builtin_cpu_supports("avx512dq");
#else
  return false;
#endif
}

long long projectDistanceColourPadded(Real* x4, const DistanceBatch& batch, size_t begin,
                                      size_t end, bool simd) {
#ifdef DEFORM_PBD_HAVE_AVX2_PATH
  static const bool kAvx2 = distanceSimdAvailable();
  static const bool kAvx512 = kAvx2 && distanceSimdFloatAvailable();  // AVX-512 F, VL, DQ
  if (simd && kAvx512) return projectPaddedAvx512(x4, batch, begin, end);
  if (simd && kAvx2) return projectPaddedAvx2(x4, batch, begin, end);
#endif
  long long degenerate = 0;
  for (size_t i = begin; i < end; ++i) degenerate += projectPaddedOne(x4, batch, i);
  return degenerate;
}

FloatPath fastestFloatPath() {
  static const FloatPath kPath = !distanceSimdAvailable()       ? FloatPath::Scalar
                                 : distanceSimdFloatAvailable() ? FloatPath::Avx512
                                                                : FloatPath::Avx2;
  return kPath;
}

long long projectDistanceColourPaddedF(float* x4, const DistanceBatchF& batch, size_t begin,
                                       size_t end, FloatPath path) {
#ifdef DEFORM_PBD_HAVE_AVX2_PATH
  if (path == FloatPath::Avx512) return projectPaddedF512(x4, batch, begin, end);
  if (path == FloatPath::Avx2) return projectPaddedF256(x4, batch, begin, end);
#endif
  long long degenerate = 0;
  for (size_t i = begin; i < end; ++i) degenerate += projectPaddedOneF(x4, batch, i);
  return degenerate;
}

long long projectDistanceColourPaddedF(float* x4, const DistanceBatchF& batch, size_t begin,
                                       size_t end, bool simd) {
  return projectDistanceColourPaddedF(x4, batch, begin, end,
                                      simd ? fastestFloatPath() : FloatPath::Scalar);
}

void distanceLengthsColourF(const float* x4, const int* a, const int* b, size_t begin, size_t end,
                            float* len, bool simd) {
#ifdef DEFORM_PBD_HAVE_AVX2_PATH
  static const bool kAvx512 = distanceSimdFloatAvailable();
  if (simd && kAvx512) return lengthsF512(x4, a, b, begin, end, len);
#endif
  for (size_t i = begin; i < end; ++i) len[i] = lengthOf(x4 + a[i], x4 + b[i]);
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

bool projectSurfaceVolumePaddedF(float* x4, Eigen::Index n, const Real* w, const MatX3i& F,
                                 Real restVolume, Real alphaTilde, Real k, Real& lambda,
                                 float* grad4, bool simd) {
  Real dl = 0;
  if (!volumeMultiplier(x4, n, 4, w, F, restVolume, alphaTilde, k, lambda, grad4, dl, simd))
    return false;
  applyVolumeCorrection(x4, n, 4, w, grad4, dl);
  return true;
}

Real surfaceVolumePaddedF(const float* x4, Eigen::Index n, const MatX3i& F, bool simd) {
#ifdef DEFORM_PBD_HAVE_AVX2_PATH
  if (simd) {
    std::vector<float> grad(4 * static_cast<size_t>(n));
    return volumeAndGradientRowsF(x4, n, F, grad.data());
  }
#endif
  return volumeAndGradient<float>(x4, n, 4, F, nullptr);
}

}  // namespace deform::pbd
