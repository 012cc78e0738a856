// AVX2 bodies of explicit_rows.h, for CPUs without AVX-512. Compiled with -mavx2
// -ffp-contract=off (no fused multiply-add: AVX2 does not imply FMA) and entered only after the
// run-time CPU check in explicit_rows.cpp; includes nothing but the intrinsics and the plain
// header.
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>

#include <cfloat>

#include "explicit_rows.h"

namespace deform::massspring::rows::detail {

namespace {

constexpr double kTiny2 = 1e-12 * 1e-12;  // tol::kDegenerateLength^2, as the scalar path

// The rows r0..r3 (x, y, z, 0 each) as columns x, y, z.
inline void columns(const __m256d r[4], __m256d& x, __m256d& y, __m256d& z) {
  const __m256d t0 = _mm256_unpacklo_pd(r[0], r[1]);  // x0 x1 z0 z1
  const __m256d t1 = _mm256_unpackhi_pd(r[0], r[1]);  // y0 y1 w0 w1
  const __m256d t2 = _mm256_unpacklo_pd(r[2], r[3]);
  const __m256d t3 = _mm256_unpackhi_pd(r[2], r[3]);
  x = _mm256_permute2f128_pd(t0, t2, 0x20);
  y = _mm256_permute2f128_pd(t1, t3, 0x20);
  z = _mm256_permute2f128_pd(t0, t2, 0x31);
}

}  // namespace

// Four springs per step: the position and velocity differences of each spring's rows, transposed
// to one spring per lane for the arithmetic (the scalar loop's operations in its order), then
// the forces m_k (dx, dy, dz, 0)_k added to f_a and subtracted from f_b one spring after the
// other, in spring order, so that a node's sum is rounded as in the scalar loop.
std::size_t addSpringForcesAvx2(const double* xv, const SpringArrays& s, double* f4,
                                long long* degenerate) {
  const __m256d tiny = _mm256_set1_pd(kTiny2);
  const __m256d one = _mm256_set1_pd(1.0);
  alignas(32) double mm[4];
  std::size_t i = 0;
  for (; i + 4 <= s.n; i += 4) {
    const int* A = s.a + i;
    const int* B = s.b + i;
    __m256d D[4], DV[4];
    for (int k = 0; k < 4; ++k) {
      D[k] = _mm256_sub_pd(_mm256_loadu_pd(xv + B[k]), _mm256_loadu_pd(xv + A[k]));
      DV[k] = _mm256_sub_pd(_mm256_loadu_pd(xv + B[k] + 4), _mm256_loadu_pd(xv + A[k] + 4));
    }
    __m256d dx, dy, dz, dvx, dvy, dvz;
    columns(D, dx, dy, dz);
    columns(DV, dvx, dvy, dvz);
    const __m256d l2 = _mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dx, dx), _mm256_mul_pd(dy, dy)),
                                     _mm256_mul_pd(dz, dz));
    // Not (l2 <= tiny): a NaN length goes on, as in the scalar loop.
    const __m256d ok = _mm256_cmp_pd(l2, tiny, _CMP_NLE_UQ);
    const __m256d l = _mm256_sqrt_pd(l2);
    const __m256d il = _mm256_div_pd(one, l);
    const __m256d vn =
        _mm256_mul_pd(_mm256_add_pd(_mm256_add_pd(_mm256_mul_pd(dvx, dx), _mm256_mul_pd(dvy, dy)),
                                    _mm256_mul_pd(dvz, dz)),
                      il);
    const __m256d inner = _mm256_add_pd(
        _mm256_mul_pd(_mm256_loadu_pd(s.k + i), _mm256_sub_pd(l, _mm256_loadu_pd(s.rest + i))),
        _mm256_mul_pd(_mm256_loadu_pd(s.c + i), vn));
    _mm256_store_pd(mm, _mm256_and_pd(ok, _mm256_mul_pd(inner, il)));
    for (int k = 0; k < 4; ++k) {
      const __m256d F = _mm256_mul_pd(_mm256_broadcast_sd(mm + k), D[k]);
      double* fa = f4 + A[k] / 2;
      double* fb = f4 + B[k] / 2;
      _mm256_storeu_pd(fa, _mm256_add_pd(_mm256_loadu_pd(fa), F));
      _mm256_storeu_pd(fb, _mm256_sub_pd(_mm256_loadu_pd(fb), F));
    }
    *degenerate += 4 - __builtin_popcount(_mm256_movemask_pd(ok));
  }
  return i;
}

namespace {

template <bool kSymplectic>
bool integrateRows(double* xv, const double* f4, std::size_t n, const IntegrateArgs& p) {
  const __m256d g = _mm256_set_pd(0.0, p.g[2], p.g[1], p.g[0]);
  const __m256d c = _mm256_set_pd(0.0, p.c[2], p.c[1], p.c[0]);
  const __m256d alpha = _mm256_set1_pd(p.alpha), h = _mm256_set1_pd(p.h);
  const __m256d half = _mm256_set1_pd(p.half), vmax = _mm256_set1_pd(DBL_MAX);
  const __m256d sign = _mm256_set1_pd(-0.0);
  __m256d ok = _mm256_castsi256_pd(_mm256_set1_epi64x(-1));
  for (std::size_t i = 0; i < n; ++i) {
    double* px = xv + 8 * i;
    __m256d X = _mm256_loadu_pd(px), V = _mm256_loadu_pd(px + 4);
    const double w = p.w[i];
    if (w != 0.0) {  // fixed (or massless) nodes stay at rest
      const __m256d a = _mm256_sub_pd(
          _mm256_add_pd(_mm256_mul_pd(_mm256_loadu_pd(f4 + 4 * i), _mm256_set1_pd(w)), g),
          _mm256_mul_pd(alpha, V));
      if constexpr (kSymplectic) {
        V = _mm256_add_pd(V, _mm256_mul_pd(h, a));
        X = _mm256_add_pd(X, _mm256_mul_pd(h, V));
      } else {
        X = _mm256_add_pd(X, _mm256_mul_pd(h, V));
        V = _mm256_add_pd(V, _mm256_mul_pd(h, a));
      }
      _mm256_storeu_pd(px, X);
      _mm256_storeu_pd(px + 4, V);
    }
    ok = _mm256_and_pd(
        ok,
        _mm256_and_pd(_mm256_cmp_pd(_mm256_andnot_pd(sign, _mm256_sub_pd(X, c)), half, _CMP_LE_OQ),
                      _mm256_cmp_pd(_mm256_andnot_pd(sign, V), vmax, _CMP_LE_OQ)));
  }
  return _mm256_movemask_pd(ok) == 0xF;
}

}  // namespace

bool integrateAvx2(double* xv, const double* f4, std::size_t n, const IntegrateArgs& args) {
  return args.symplectic ? integrateRows<true>(xv, f4, n, args)
                         : integrateRows<false>(xv, f4, n, args);
}

}  // namespace deform::massspring::rows::detail

#endif
