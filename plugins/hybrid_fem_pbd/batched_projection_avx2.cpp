// AVX2 lanes for batched_projection_math.h: four constraints per __m256d, eight per __m256
// (single-precision stretch), and the blocked float x double product of response_product.h.
// Compiled with -mavx2 -mfma; includes nothing but the intrinsics and the internal-linkage math
// header.
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
  // Gathers the points idx[0..3] of the padded array into x, y, z lanes.
  static void loadPoints(const double* x4, const int* idx, V& x, V& y, V& z) {
    const V r0 = _mm256_loadu_pd(x4 + 4 * static_cast<long>(idx[0]));
    const V r1 = _mm256_loadu_pd(x4 + 4 * static_cast<long>(idx[1]));
    const V r2 = _mm256_loadu_pd(x4 + 4 * static_cast<long>(idx[2]));
    const V r3 = _mm256_loadu_pd(x4 + 4 * static_cast<long>(idx[3]));
    const V t0 = _mm256_unpacklo_pd(r0, r1);  // x0 x1 z0 z1
    const V t1 = _mm256_unpackhi_pd(r0, r1);  // y0 y1 w0 w1
    const V t2 = _mm256_unpacklo_pd(r2, r3);
    const V t3 = _mm256_unpackhi_pd(r2, r3);
    x = _mm256_permute2f128_pd(t0, t2, 0x20);
    y = _mm256_permute2f128_pd(t1, t3, 0x20);
    z = _mm256_permute2f128_pd(t0, t2, 0x31);
  }
  // Adds (dx, dy, dz) lane k to point idx[k]; the four points are distinct or immovable (their
  // lanes are then exactly zero), so the read-modify-writes do not interfere.
  static void addPoints(double* x4, const int* idx, V dx, V dy, V dz) {
    const V zero = _mm256_setzero_pd();
    const V t0 = _mm256_unpacklo_pd(dx, dy);  // dx0 dy0 dx2 dy2
    const V t1 = _mm256_unpackhi_pd(dx, dy);  // dx1 dy1 dx3 dy3
    const V t2 = _mm256_unpacklo_pd(dz, zero);
    const V t3 = _mm256_unpackhi_pd(dz, zero);
    const V row[4] = {_mm256_permute2f128_pd(t0, t2, 0x20), _mm256_permute2f128_pd(t1, t3, 0x20),
                      _mm256_permute2f128_pd(t0, t2, 0x31), _mm256_permute2f128_pd(t1, t3, 0x31)};
    for (int k = 0; k < 4; ++k) {
      double* p = x4 + 4 * static_cast<long>(idx[k]);
      _mm256_storeu_pd(p, _mm256_add_pd(_mm256_loadu_pd(p), row[k]));
    }
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
  // Rows idx[k] and idx[k + 4] share a 256-bit register, then a 4 x 4 transpose per 128-bit half.
  static void loadPoints(const float* x4, const int* idx, V& x, V& y, V& z) {
    auto row = [&](int k) { return x4 + 4 * static_cast<long>(idx[k]); };
    const V r04 = _mm256_loadu2_m128(row(4), row(0));
    const V r15 = _mm256_loadu2_m128(row(5), row(1));
    const V r26 = _mm256_loadu2_m128(row(6), row(2));
    const V r37 = _mm256_loadu2_m128(row(7), row(3));
    const V t0 = _mm256_unpacklo_ps(r04, r15);  // x0 x1 y0 y1 | x4 x5 y4 y5
    const V t1 = _mm256_unpackhi_ps(r04, r15);  // z0 z1 w0 w1 | z4 z5 w4 w5
    const V t2 = _mm256_unpacklo_ps(r26, r37);
    const V t3 = _mm256_unpackhi_ps(r26, r37);
    x = _mm256_shuffle_ps(t0, t2, 0x44);
    y = _mm256_shuffle_ps(t0, t2, 0xEE);
    z = _mm256_shuffle_ps(t1, t3, 0x44);
  }
  // Adds lane k to point idx[k]: distinct or immovable points (exactly zero lanes), as above.
  static void addPoints(float* x4, const int* idx, V dx, V dy, V dz) {
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
      float* p = x4 + 4 * static_cast<long>(idx[k]);
      _mm_storeu_ps(p, _mm_add_ps(_mm_loadu_ps(p), rows[k]));
    }
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
