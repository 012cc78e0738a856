// deformbench SDK: AVX2 gathers and scatters between particle positions kept as padded rows
// (x, y, z, 0) and columns of one coordinate per lane, for kernels that project eight (float) or
// four (double) constraints per vector step (the core's isometric bending, the hybrid FEM+PBD
// model's batched projections). x86-64 with GCC or Clang only.
//
// Include it only from a translation unit compiled for AVX2 (-mavx2) that includes nothing else
// with inline functions (no Eigen, no deform/sdk/types.h): an inline function compiled there would
// carry AVX2 instructions, and the linker may keep that copy for callers on any CPU. The callers
// check the CPU at run time (__builtin_cpu_supports) before they enter such a unit.
#pragma once

#if !defined(__x86_64__) || !defined(__GNUC__) || !defined(__AVX2__)
#error "deform/kernels/simd_rows_avx2.h needs x86-64, GCC or Clang, and -mavx2"
#endif

#include <immintrin.h>

namespace deform::simd {

// `row(k)` gives the address of lane k's row: the callers index their rows by offsets or by
// particle indices, and a callable lets each keep its own address arithmetic in the inlined code.
// The vector type picks the width: eight float rows per __m256, four double rows per __m256d.

/// The rows row(0..7) (float x, y, z, 0 each) as columns x, y, z: rows k and k + 4 share a
/// 256-bit register, then a 4 x 4 transpose inside each 128-bit half.
template <class Row>
__attribute__((always_inline)) inline void gatherRows(Row row, __m256& x, __m256& y, __m256& z) {
  const __m256 r04 = _mm256_loadu2_m128(row(4), row(0));
  const __m256 r15 = _mm256_loadu2_m128(row(5), row(1));
  const __m256 r26 = _mm256_loadu2_m128(row(6), row(2));
  const __m256 r37 = _mm256_loadu2_m128(row(7), row(3));
  const __m256 t0 = _mm256_unpacklo_ps(r04, r15);  // x0 x1 y0 y1 | x4 x5 y4 y5
  const __m256 t1 = _mm256_unpackhi_ps(r04, r15);  // z0 z1 w0 w1 | z4 z5 w4 w5
  const __m256 t2 = _mm256_unpacklo_ps(r26, r37);
  const __m256 t3 = _mm256_unpackhi_ps(r26, r37);
  x = _mm256_shuffle_ps(t0, t2, 0x44);
  y = _mm256_shuffle_ps(t0, t2, 0xEE);
  z = _mm256_shuffle_ps(t1, t3, 0x44);
}

/// Adds lane k of (dx, dy, dz) to the row at row(k), one row after the other: two lanes may name
/// the same row only when one of them adds exactly zero (an immovable particle).
template <class Row>
__attribute__((always_inline)) inline void addToRows(Row row, __m256 dx, __m256 dy, __m256 dz) {
  const __m256 zero = _mm256_setzero_ps();
  const __m256 a = _mm256_unpacklo_ps(dx, dy);  // dx0 dy0 dx1 dy1 | dx4 dy4 dx5 dy5
  const __m256 b = _mm256_unpackhi_ps(dx, dy);  // dx2 dy2 dx3 dy3 | dx6 dy6 dx7 dy7
  const __m256 c = _mm256_unpacklo_ps(dz, zero);
  const __m256 d = _mm256_unpackhi_ps(dz, zero);
  const __m256 r04 = _mm256_shuffle_ps(a, c, 0x44), r15 = _mm256_shuffle_ps(a, c, 0xEE);
  const __m256 r26 = _mm256_shuffle_ps(b, d, 0x44), r37 = _mm256_shuffle_ps(b, d, 0xEE);
  const __m128 rows[8] = {_mm256_castps256_ps128(r04),   _mm256_castps256_ps128(r15),
                          _mm256_castps256_ps128(r26),   _mm256_castps256_ps128(r37),
                          _mm256_extractf128_ps(r04, 1), _mm256_extractf128_ps(r15, 1),
                          _mm256_extractf128_ps(r26, 1), _mm256_extractf128_ps(r37, 1)};
  for (int k = 0; k < 8; ++k) {
    float* p = row(k);
    _mm_storeu_ps(p, _mm_add_ps(_mm_loadu_ps(p), rows[k]));
  };
}

/// The rows row(0..3) (double x, y, z, 0 each) as columns x, y, z.
template <class Row>
__attribute__((always_inline)) inline void gatherRows(Row row, __m256d& x, __m256d& y, __m256d& z) {
  const __m256d r0 = _mm256_loadu_pd(row(0)), r1 = _mm256_loadu_pd(row(1));
  const __m256d r2 = _mm256_loadu_pd(row(2)), r3 = _mm256_loadu_pd(row(3));
  const __m256d t0 = _mm256_unpacklo_pd(r0, r1);  // x0 x1 z0 z1
  const __m256d t1 = _mm256_unpackhi_pd(r0, r1);  // y0 y1 w0 w1
  const __m256d t2 = _mm256_unpacklo_pd(r2, r3);
  const __m256d t3 = _mm256_unpackhi_pd(r2, r3);
  x = _mm256_permute2f128_pd(t0, t2, 0x20);
  y = _mm256_permute2f128_pd(t1, t3, 0x20);
  z = _mm256_permute2f128_pd(t0, t2, 0x31);
}

/// Adds lane k of (dx, dy, dz) to the row at row(k), as the float addToRows().
template <class Row>
__attribute__((always_inline)) inline void addToRows(Row row, __m256d dx, __m256d dy, __m256d dz) {
  const __m256d zero = _mm256_setzero_pd();
  const __m256d t0 = _mm256_unpacklo_pd(dx, dy);  // dx0 dy0 dx2 dy2
  const __m256d t1 = _mm256_unpackhi_pd(dx, dy);  // dx1 dy1 dx3 dy3
  const __m256d t2 = _mm256_unpacklo_pd(dz, zero);
  const __m256d t3 = _mm256_unpackhi_pd(dz, zero);
  const __m256d rows[4] = {
      _mm256_permute2f128_pd(t0, t2, 0x20), _mm256_permute2f128_pd(t1, t3, 0x20),
      _mm256_permute2f128_pd(t0, t2, 0x31), _mm256_permute2f128_pd(t1, t3, 0x31)};
  for (int k = 0; k < 4; ++k) {
    double* p = row(k);
    _mm256_storeu_pd(p, _mm256_add_pd(_mm256_loadu_pd(p), rows[k]));
  };
}

}  // namespace deform::simd
