// AVX2 lanes for batched_projection_math.h: four constraints per __m256d, eight per __m256
// (single-precision stretch), and the blocked float x double product of response_product.h.
// Compiled with -mavx2 -mfma; includes nothing but the intrinsics, the row gathers of
// deform/kernels/simd_rows_avx2.h and the internal-linkage math header.
#include <deform/kernels/simd_rows_avx2.h>
#include <immintrin.h>

#include "batched_projection_avx2.h"

namespace deform::hybrid::batched {

namespace {

struct Avx2Lanes {
  using T = double;
  using V = __m256d;
  using M = __m256d;
  static constexpr int kWidth = 4;
  static V set1(double v) { return _mm256_set1_pd(v); }
  static V load(const double* p) { return _mm256_loadu_pd(p); }
  static void store(double* p, V v) { _mm256_storeu_pd(p, v); }
  static V sqrt(V a) { return _mm256_sqrt_pd(a); }
  static V min(V a, V b) { return _mm256_min_pd(a, b); }
  static V max(V a, V b) { return _mm256_max_pd(a, b); }
  static V abs(V a) { return _mm256_andnot_pd(_mm256_set1_pd(-0.0), a); }
  static M gt(V a, V b) { return _mm256_cmp_pd(a, b, _CMP_GT_OQ); }
  static M lt(V a, V b) { return _mm256_cmp_pd(a, b, _CMP_LT_OQ); }
  static M band(M a, M b) { return _mm256_and_pd(a, b); }
  static V select(M m, V a, V b) { return _mm256_blendv_pd(b, a, m); }
  static int count(M m) { return __builtin_popcount(_mm256_movemask_pd(m)); }
  static unsigned orBytes(const unsigned char* m) { return m[0] | m[1] | m[2] | m[3]; }
  static bool anyByte(const unsigned char* m) { return (m[0] | m[1] | m[2] | m[3]) != 0; }
  // The points idx[0..3] of the padded array <-> x, y, z lanes (deform/kernels/simd_rows_avx2.h);
  // the four points of an add are distinct or immovable (their lanes are then exactly zero).
  static void loadPoints(const double* x4, const int* idx, V& x, V& y, V& z) {
    simd::gatherRows4([&](int k) { return x4 + 4 * static_cast<long>(idx[k]); }, x, y, z);
  }
  static void addPoints(double* x4, const int* idx, V dx, V dy, V dz) {
    simd::addToRows4([&](int k) { return x4 + 4 * static_cast<long>(idx[k]); }, dx, dy, dz);
  }
};

// Eight constraints per __m256 on a padded float array (x, y, z, 0 per particle).
struct Float8Lanes {
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
  static V select(M m, V a, V b) { return _mm256_blendv_ps(b, a, m); }
  static int count(M m) { return __builtin_popcount(_mm256_movemask_ps(m)); }
  static bool anyByte(const unsigned char* m) {
    unsigned char any = 0;
    for (int k = 0; k < 8; ++k) any |= m[k];
    return any != 0;
  }
  // The points idx[0..7] <-> lanes, as above.
  static void loadPoints(const float* x4, const int* idx, V& x, V& y, V& z) {
    simd::gatherRows8([&](int k) { return x4 + 4 * static_cast<long>(idx[k]); }, x, y, z);
  }
  static void addPoints(float* x4, const int* idx, V dx, V dy, V dz) {
    simd::addToRows8([&](int k) { return x4 + 4 * static_cast<long>(idx[k]); }, dx, dy, dz);
  }
};

}  // namespace

std::size_t stretchRangeAvx2(float* x4, const StretchViewF& s, std::size_t begin, std::size_t end,
                             float* measure, long long* degenerate) {
  std::size_t i = begin;
  for (; i + 8 <= end; i += 8) *degenerate += stretchGroup<Float8Lanes>(x4, s, i, measure);
  return i - begin;
}

void blockedResponseAvx2(const float* data, int blocks, int cols, const double* lambda, double* y) {
  constexpr int kRows = 16;
  for (int b = 0; b < blocks; ++b) {
    const float* d = data + static_cast<long>(b) * cols * kRows;
    // Two columns per iteration into separate accumulators (eight chains of fused
    // multiply-adds), summed at the end.
    __m256d acc[8];
    for (__m256d& a : acc) a = _mm256_setzero_pd();
    int j = 0;
    for (; j + 2 <= cols; j += 2, d += 2 * kRows) {
      const __m256d l0 = _mm256_broadcast_sd(lambda + j), l1 = _mm256_broadcast_sd(lambda + j + 1);
      for (int q = 0; q < 4; ++q) {
        acc[q] = _mm256_fmadd_pd(_mm256_cvtps_pd(_mm_loadu_ps(d + 4 * q)), l0, acc[q]);
        acc[4 + q] =
            _mm256_fmadd_pd(_mm256_cvtps_pd(_mm_loadu_ps(d + kRows + 4 * q)), l1, acc[4 + q]);
      }
    }
    if (j < cols) {
      const __m256d l0 = _mm256_broadcast_sd(lambda + j);
      for (int q = 0; q < 4; ++q)
        acc[q] = _mm256_fmadd_pd(_mm256_cvtps_pd(_mm_loadu_ps(d + 4 * q)), l0, acc[q]);
    }
    double* out = y + static_cast<long>(b) * kRows;
    for (int q = 0; q < 4; ++q) _mm256_storeu_pd(out + 4 * q, _mm256_add_pd(acc[q], acc[4 + q]));
  }
}

std::size_t stretchRangeAvx2(double* x4, const StretchView& s, std::size_t begin, std::size_t end,
                             long long* degenerate) {
  std::size_t i = begin;
  for (; i + 4 <= end; i += 4) *degenerate += stretchGroup<Avx2Lanes>(x4, s, i);
  return i - begin;
}

std::size_t bendRangeAvx2(double* x4, const BendView& h, std::size_t begin, std::size_t end,
                          long long* degenerate) {
  std::size_t i = begin;
  for (; i + 4 <= end; i += 4) *degenerate += bendGroup<Avx2Lanes>(x4, h, i);
  return i - begin;
}

}  // namespace deform::hybrid::batched
