// AVX2 lanes for batched_projection_math.h: four constraints per __m256d. Compiled with
// -mavx2 -mfma; includes nothing but the intrinsics and the internal-linkage math header.
#include <immintrin.h>

#include "batched_projection_avx2.h"

namespace deform::hybrid::batched {

namespace {

struct Avx2Lanes {
  using V = __m256d;
  using M = __m256d;
  static constexpr int kWidth = 4;
  static V set1(double v) { return _mm256_set1_pd(v); }
  static V load(const double* p) { return _mm256_loadu_pd(p); }
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

}  // namespace

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
