// AVX2 lanes for batched_projection_math.h: four constraints per __m256d, eight per __m256
// (single-precision stretch), and the blocked float x double product of response_product.h.
// Compiled with -mavx2 -mfma; includes nothing but the intrinsics, the lanes of
// deform/kernels/simd_lanes_avx2.h and the internal-linkage math header.
#include <deform/kernels/simd_lanes_avx2.h>
#include <immintrin.h>

#include "batched_projection_avx2.h"

namespace deform::hybrid_fem_pbd::batched {

std::size_t stretchRangeAvx2(float* x4, const StretchViewF& s, std::size_t begin, std::size_t end,
                             float* measure, long long* degenerate) {
  std::size_t i = begin;
  for (; i + 8 <= end; i += 8) *degenerate += stretchGroup<simd::Avx2Float8>(x4, s, i, measure);
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
  for (; i + 4 <= end; i += 4) *degenerate += stretchGroup<simd::Avx2Double4>(x4, s, i);
  return i - begin;
}

std::size_t bendRangeAvx2(double* x4, const BendView& h, std::size_t begin, std::size_t end,
                          long long* degenerate) {
  std::size_t i = begin;
  for (; i + 4 <= end; i += 4) *degenerate += bendGroup<simd::Avx2Double4>(x4, h, i);
  return i - begin;
}

}  // namespace deform::hybrid_fem_pbd::batched
