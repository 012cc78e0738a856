// The AVX-512 spring pass of explicit_rows.h (the node update is the AVX2 unit's on both). Compiled
// with -mavx512f -mavx512vl -mavx512dq -ffp-contract=off and entered only after the run-time CPU
// check in explicit_rows.cpp; includes nothing but the intrinsics and the plain header.
#if defined(__x86_64__) && defined(__GNUC__)
// GCC 12 reports -Wmaybe-uninitialized inside its own AVX-512 intrinsics (their _mm512_undefined_*
// pass-through operands, GCC bug 105593, fixed in GCC 13); nothing in this file is uninitialised.
#if !defined(__clang__) && __GNUC__ < 13
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif
#include <immintrin.h>

#include "explicit_rows.h"

namespace deform::massspring::rows::detail {

namespace {
constexpr double kTiny2 = 1e-12 * 1e-12;  // tol::kDegenerateLength^2, as the scalar path
}  // namespace

// Eight springs per step. Each spring's row difference D = (x_b - x_a, 0, v_b - v_a, 0) is one
// 512-bit subtraction of the nodes' rows (a cache line each); an 8 x 8 transpose (without the
// padding columns) gives dx, dy, dz, dvx, dvy, dvz with one spring per lane for the arithmetic;
// the forces go back as rows m_k (dx, dy, dz, 0)_k, added to f_a and subtracted from f_b one
// spring after the other (the order of the scalar loop, so a node's sum is rounded alike).
std::size_t addSpringForcesAvx512(const double* xv, const SpringArrays& s, double* f4,
                                  long long* degenerate) {
  const __m512d tiny = _mm512_set1_pd(kTiny2);
  const __m512d one = _mm512_set1_pd(1.0);
  alignas(64) double mm[8];
  std::size_t i = 0;
  for (; i + 8 <= s.n; i += 8) {
    const int* A = s.a + i;
    const int* B = s.b + i;
    __m512d D[8];
#pragma GCC unroll 8
    for (int k = 0; k < 8; ++k)
      D[k] = _mm512_sub_pd(_mm512_loadu_pd(xv + B[k]), _mm512_loadu_pd(xv + A[k]));
    // Per 128-bit chunk: t0 = (x0 x1 | z0 z1 | vx0 vx1 | vz0 vz1), t1 = (y0 y1 | . | vy0 vy1 | .).
    const __m512d t0 = _mm512_unpacklo_pd(D[0], D[1]), t1 = _mm512_unpackhi_pd(D[0], D[1]);
    const __m512d t2 = _mm512_unpacklo_pd(D[2], D[3]), t3 = _mm512_unpackhi_pd(D[2], D[3]);
    const __m512d t4 = _mm512_unpacklo_pd(D[4], D[5]), t5 = _mm512_unpackhi_pd(D[4], D[5]);
    const __m512d t6 = _mm512_unpacklo_pd(D[6], D[7]), t7 = _mm512_unpackhi_pd(D[6], D[7]);
    const __m512d u0 = _mm512_shuffle_f64x2(t0, t2, 0x88);  // x01 vx01 x23 vx23
    const __m512d u1 = _mm512_shuffle_f64x2(t4, t6, 0x88);  // x45 vx45 x67 vx67
    const __m512d u2 = _mm512_shuffle_f64x2(t0, t2, 0xDD);  // z01 vz01 z23 vz23
    const __m512d u3 = _mm512_shuffle_f64x2(t4, t6, 0xDD);
    const __m512d u4 = _mm512_shuffle_f64x2(t1, t3, 0x88);  // y01 vy01 y23 vy23
    const __m512d u5 = _mm512_shuffle_f64x2(t5, t7, 0x88);
    const __m512d dx = _mm512_shuffle_f64x2(u0, u1, 0x88);
    const __m512d dvx = _mm512_shuffle_f64x2(u0, u1, 0xDD);
    const __m512d dz = _mm512_shuffle_f64x2(u2, u3, 0x88);
    const __m512d dvz = _mm512_shuffle_f64x2(u2, u3, 0xDD);
    const __m512d dy = _mm512_shuffle_f64x2(u4, u5, 0x88);
    const __m512d dvy = _mm512_shuffle_f64x2(u4, u5, 0xDD);
    const __m512d l2 = _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(dx, dx), _mm512_mul_pd(dy, dy)),
                                     _mm512_mul_pd(dz, dz));
    // Not (l2 <= tiny): a NaN length goes on, as in the scalar loop.
    const __mmask8 ok = _mm512_cmp_pd_mask(l2, tiny, _CMP_NLE_UQ);
    const __m512d l = _mm512_sqrt_pd(l2);
    const __m512d il = _mm512_div_pd(one, l);
    const __m512d vn =
        _mm512_mul_pd(_mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(dvx, dx), _mm512_mul_pd(dvy, dy)),
                                    _mm512_mul_pd(dvz, dz)),
                      il);
    const __m512d inner = _mm512_add_pd(
        _mm512_mul_pd(_mm512_loadu_pd(s.k + i), _mm512_sub_pd(l, _mm512_loadu_pd(s.rest + i))),
        _mm512_mul_pd(_mm512_loadu_pd(s.c + i), vn));
    _mm512_store_pd(mm, _mm512_maskz_mul_pd(ok, inner, il));
#pragma GCC unroll 8
    for (int k = 0; k < 8; ++k) {
      const __m256d F = _mm256_mul_pd(_mm256_broadcast_sd(mm + k), _mm512_castpd512_pd256(D[k]));
      double* fa = f4 + A[k] / 2;
      double* fb = f4 + B[k] / 2;
      _mm256_storeu_pd(fa, _mm256_add_pd(_mm256_loadu_pd(fa), F));
      _mm256_storeu_pd(fb, _mm256_sub_pd(_mm256_loadu_pd(fb), F));
    }
    *degenerate += 8 - __builtin_popcount(ok);
  }
  return i;
}

}  // namespace deform::massspring::rows::detail

#endif
