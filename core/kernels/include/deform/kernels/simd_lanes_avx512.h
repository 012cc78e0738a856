// deformbench kernels: eight doubles per __m512d, the AVX-512F lanes of the interface of
// deform/kernels/simd_lanes.h, its arithmetic part only (no row or point access); masks are
// __mmask8. Include it only from a translation unit compiled with -mavx512f and entered after a
// run-time CPU check.
#pragma once

#include <immintrin.h>

namespace deform::simd {

struct Avx512Double8 {
  using T = double;
  using V = __m512d;
  using M = __mmask8;
  static constexpr int kWidth = 8;
  static V set1(double v) { return _mm512_set1_pd(v); }
  static V load(const double* p) { return _mm512_loadu_pd(p); }
  static void store(double* p, V v) { _mm512_storeu_pd(p, v); }
  static V sqrt(V a) { return _mm512_sqrt_pd(a); }
  static V abs(V a) { return _mm512_abs_pd(a); }
  static M gt(V a, V b) { return _mm512_cmp_pd_mask(a, b, _CMP_GT_OQ); }
  static M lt(V a, V b) { return _mm512_cmp_pd_mask(a, b, _CMP_LT_OQ); }
  static M le(V a, V b) { return _mm512_cmp_pd_mask(a, b, _CMP_LE_OQ); }
  static M ne(V a, V b) { return _mm512_cmp_pd_mask(a, b, _CMP_NEQ_OQ); }
  static M band(M a, M b) { return static_cast<M>(a & b); }
  static M notMask(M a) { return static_cast<M>(~a); }
  static V select(M m, V a, V b) { return _mm512_mask_blend_pd(m, b, a); }
  static int count(M m) { return __builtin_popcount(m); }
};

}  // namespace deform::simd
