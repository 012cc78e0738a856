// AVX2 lanes for isometric_bending_math.h: eight hinges per __m256 (float) or four per __m256d
// (double). Compiled with -mavx2 -ffp-contract=off (core/CMakeLists.txt) and called only after a
// run-time CPU check (isometric_bending.cpp); includes nothing but the intrinsics and the
// internal-linkage math header.
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>

#include "isometric_bending_avx2.h"
#include "isometric_bending_math.h"

namespace deform::pbd::isobatch {

namespace {

struct Float8 {
  using T = float;
  using V = __m256;
  using M = __m256;
  static constexpr int kWidth = 8;
  static V set1(float v) { return _mm256_set1_ps(v); }
  static V load(const float* p) { return _mm256_loadu_ps(p); }
  static void store(float* p, V v) { _mm256_storeu_ps(p, v); }
  static V sqrt(V a) { return _mm256_sqrt_ps(a); }
  static V max(V a, V b) { return _mm256_max_ps(a, b); }
  static M gt(V a, V b) { return _mm256_cmp_ps(a, b, _CMP_GT_OQ); }
  static M lt(V a, V b) { return _mm256_cmp_ps(a, b, _CMP_LT_OQ); }
  static M ne(V a, V b) { return _mm256_cmp_ps(a, b, _CMP_NEQ_OQ); }
  static M band(M a, M b) { return _mm256_and_ps(a, b); }
  static M notMask(M a) { return _mm256_xor_ps(a, _mm256_castsi256_ps(_mm256_set1_epi32(-1))); }
  static V select(M m, V a, V b) { return _mm256_blendv_ps(b, a, m); }
  static int count(M m) { return __builtin_popcount(_mm256_movemask_ps(m)); }
  // Rows (x, y, z, 0) at x4 + off[0..7] -> columns x, y, z: rows k and k + 4 share a 256-bit
  // register, then a 4 x 4 transpose inside each 128-bit half.
  static void loadRows(const float* x4, const int* off, V& x, V& y, V& z) {
    const V r04 = _mm256_loadu2_m128(x4 + off[4], x4 + off[0]);
    const V r15 = _mm256_loadu2_m128(x4 + off[5], x4 + off[1]);
    const V r26 = _mm256_loadu2_m128(x4 + off[6], x4 + off[2]);
    const V r37 = _mm256_loadu2_m128(x4 + off[7], x4 + off[3]);
    const V t0 = _mm256_unpacklo_ps(r04, r15);  // x0 x1 y0 y1 | x4 x5 y4 y5
    const V t1 = _mm256_unpackhi_ps(r04, r15);  // z0 z1 w0 w1 | z4 z5 w4 w5
    const V t2 = _mm256_unpacklo_ps(r26, r37);
    const V t3 = _mm256_unpackhi_ps(r26, r37);
    x = _mm256_shuffle_ps(t0, t2, 0x44);
    y = _mm256_shuffle_ps(t0, t2, 0xEE);
    z = _mm256_shuffle_ps(t1, t3, 0x44);
  }
  // Adds lane k of (dx, dy, dz) to the row at x4 + off[k], one row after the other (an
  // immovable particle shared by two lanes gets + 0 twice).
  static void addRows(float* x4, const int* off, V dx, V dy, V dz) {
    const V zero = _mm256_setzero_ps();
    const V a = _mm256_unpacklo_ps(dx, dy);  // dx0 dy0 dx1 dy1 | dx4 dy4 dx5 dy5
    const V b = _mm256_unpackhi_ps(dx, dy);  // dx2 dy2 dx3 dy3 | dx6 dy6 dx7 dy7
    const V c = _mm256_unpacklo_ps(dz, zero);
    const V d = _mm256_unpackhi_ps(dz, zero);
    const V r04 = _mm256_shuffle_ps(a, c, 0x44), r15 = _mm256_shuffle_ps(a, c, 0xEE);
    const V r26 = _mm256_shuffle_ps(b, d, 0x44), r37 = _mm256_shuffle_ps(b, d, 0xEE);
    const __m128 rows[8] = {_mm256_castps256_ps128(r04),   _mm256_castps256_ps128(r15),
                            _mm256_castps256_ps128(r26),   _mm256_castps256_ps128(r37),
                            _mm256_extractf128_ps(r04, 1), _mm256_extractf128_ps(r15, 1),
                            _mm256_extractf128_ps(r26, 1), _mm256_extractf128_ps(r37, 1)};
    for (int k = 0; k < 8; ++k) {
      float* p = x4 + off[k];
      _mm_storeu_ps(p, _mm_add_ps(_mm_loadu_ps(p), rows[k]));
    }
  }
};

struct Double4 {
  using T = double;
  using V = __m256d;
  using M = __m256d;
  static constexpr int kWidth = 4;
  static V set1(double v) { return _mm256_set1_pd(v); }
  static V load(const double* p) { return _mm256_loadu_pd(p); }
  static void store(double* p, V v) { _mm256_storeu_pd(p, v); }
  static V sqrt(V a) { return _mm256_sqrt_pd(a); }
  static V max(V a, V b) { return _mm256_max_pd(a, b); }
  static M gt(V a, V b) { return _mm256_cmp_pd(a, b, _CMP_GT_OQ); }
  static M lt(V a, V b) { return _mm256_cmp_pd(a, b, _CMP_LT_OQ); }
  static M ne(V a, V b) { return _mm256_cmp_pd(a, b, _CMP_NEQ_OQ); }
  static M band(M a, M b) { return _mm256_and_pd(a, b); }
  static M notMask(M a) { return _mm256_xor_pd(a, _mm256_castsi256_pd(_mm256_set1_epi64x(-1))); }
  static V select(M m, V a, V b) { return _mm256_blendv_pd(b, a, m); }
  static int count(M m) { return __builtin_popcount(_mm256_movemask_pd(m)); }
  static void loadRows(const double* x4, const int* off, V& x, V& y, V& z) {
    const V r0 = _mm256_loadu_pd(x4 + off[0]), r1 = _mm256_loadu_pd(x4 + off[1]);
    const V r2 = _mm256_loadu_pd(x4 + off[2]), r3 = _mm256_loadu_pd(x4 + off[3]);
    const V t0 = _mm256_unpacklo_pd(r0, r1);  // x0 x1 z0 z1
    const V t1 = _mm256_unpackhi_pd(r0, r1);  // y0 y1 w0 w1
    const V t2 = _mm256_unpacklo_pd(r2, r3);
    const V t3 = _mm256_unpackhi_pd(r2, r3);
    x = _mm256_permute2f128_pd(t0, t2, 0x20);
    y = _mm256_permute2f128_pd(t1, t3, 0x20);
    z = _mm256_permute2f128_pd(t0, t2, 0x31);
  }
  static void addRows(double* x4, const int* off, V dx, V dy, V dz) {
    const V zero = _mm256_setzero_pd();
    const V t0 = _mm256_unpacklo_pd(dx, dy);  // dx0 dy0 dx2 dy2
    const V t1 = _mm256_unpackhi_pd(dx, dy);  // dx1 dy1 dx3 dy3
    const V t2 = _mm256_unpacklo_pd(dz, zero);
    const V t3 = _mm256_unpackhi_pd(dz, zero);
    const V rows[4] = {_mm256_permute2f128_pd(t0, t2, 0x20), _mm256_permute2f128_pd(t1, t3, 0x20),
                       _mm256_permute2f128_pd(t0, t2, 0x31), _mm256_permute2f128_pd(t1, t3, 0x31)};
    for (int k = 0; k < 4; ++k) {
      double* p = x4 + off[k];
      _mm256_storeu_pd(p, _mm256_add_pd(_mm256_loadu_pd(p), rows[k]));
    }
  }
};

template <class L>
std::size_t range(typename L::T* x4, const View<typename L::T>& b, std::size_t begin,
                  std::size_t end, typename L::T* measure, long long* degenerate) {
  std::size_t i = begin;
  for (; i + L::kWidth <= end; i += L::kWidth) *degenerate += hingeGroup<L>(x4, b, i, measure);
  return i - begin;
}

}  // namespace

std::size_t rangeAvx2(float* x4, const View<float>& b, std::size_t begin, std::size_t end,
                      float* measure, long long* degenerate) {
  return range<Float8>(x4, b, begin, end, measure, degenerate);
}

std::size_t rangeAvx2(double* x4, const View<double>& b, std::size_t begin, std::size_t end,
                      double* measure, long long* degenerate) {
  return range<Double4>(x4, b, begin, end, measure, degenerate);
}

}  // namespace deform::pbd::isobatch

#endif
