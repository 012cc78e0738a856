// AVX2 lanes for isometric_bending_math.h: eight hinges per __m256 (float) or four per __m256d
// (double). Compiled with -mavx2 -ffp-contract=off (core/CMakeLists.txt) and called only after a
// run-time CPU check (isometric_bending.cpp); includes nothing but the intrinsics, the row
// gathers of deform/kernels/simd_rows_avx2.h and the internal-linkage math header.
#if defined(__x86_64__) && defined(__GNUC__)
#include <deform/kernels/simd_rows_avx2.h>
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
  // Rows (x, y, z, 0) at x4 + off[0..7] <-> columns x, y, z (deform/kernels/simd_rows_avx2.h).
  static void loadRows(const float* x4, const int* off, V& x, V& y, V& z) {
    simd::gatherRows8([&](int k) { return x4 + off[k]; }, x, y, z);
  }
  static void addRows(float* x4, const int* off, V dx, V dy, V dz) {
    simd::addToRows8([&](int k) { return x4 + off[k]; }, dx, dy, dz);
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
    simd::gatherRows4([&](int k) { return x4 + off[k]; }, x, y, z);
  }
  static void addRows(double* x4, const int* off, V dx, V dy, V dz) {
    simd::addToRows4([&](int k) { return x4 + off[k]; }, dx, dy, dz);
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
