// deformbench SDK: AVX-512 helpers for kernels that keep particle positions as padded rows
// (x, y, z, 0) and project eight constraints per vector step with their data as columns (the PBD
// plugin's distance kernel, the metaballs plugin's link kernel). x86-64 with GCC or Clang only;
// callers check the CPU at run time (__builtin_cpu_supports) and must themselves carry the same
// target attribute, so that these always_inline helpers inline into them.
#pragma once

#if defined(__x86_64__) && defined(__GNUC__)
#include <deform/sdk/types.h>
#include <immintrin.h>

#define DEFORM_HAVE_SIMD_ROWS 1

namespace deform::simd {

/// Adds (add) or subtracts the corrections w * (dx, dy, dz) of eight constraints (one per lane)
/// to their rows x0 and stores the results at ptr[0..7]. The columns go back to rows (cx, cy, cz,
/// 0): pe / po hold the (x, y) pairs of rows (0, 2, 4, 6) / (1, 3, 5, 7) by 128-bit chunk, qe / qo
/// the (z, 0) pairs; one two-source permute gives rows k (low half) and k + 2 (high half).
__attribute__((target("avx512f,avx512vl,avx512dq"), always_inline)) inline void commitRows8(
    __m512d w, __m512d dx, __m512d dy, __m512d dz, Real* const* ptr, const __m256d* x0, bool add) {
  const __m512i lowRows = _mm512_set_epi64(11, 10, 3, 2, 9, 8, 1, 0);
  const __m512i highRows = _mm512_set_epi64(15, 14, 7, 6, 13, 12, 5, 4);
  const __m512d zero = _mm512_setzero_pd();
  const __m512d cx = _mm512_mul_pd(w, dx), cy = _mm512_mul_pd(w, dy), cz = _mm512_mul_pd(w, dz);
  const __m512d pe = _mm512_unpacklo_pd(cx, cy), po = _mm512_unpackhi_pd(cx, cy);
  const __m512d qe = _mm512_unpacklo_pd(cz, zero), qo = _mm512_unpackhi_pd(cz, zero);
  const __m512d r02 = _mm512_permutex2var_pd(pe, lowRows, qe);
  const __m512d r46 = _mm512_permutex2var_pd(pe, highRows, qe);
  const __m512d r13 = _mm512_permutex2var_pd(po, lowRows, qo);
  const __m512d r57 = _mm512_permutex2var_pd(po, highRows, qo);
  const __m256d rows[8] = {_mm512_castpd512_pd256(r02),    _mm512_castpd512_pd256(r13),
                           _mm512_extractf64x4_pd(r02, 1), _mm512_extractf64x4_pd(r13, 1),
                           _mm512_castpd512_pd256(r46),    _mm512_castpd512_pd256(r57),
                           _mm512_extractf64x4_pd(r46, 1), _mm512_extractf64x4_pd(r57, 1)};
  for (int k = 0; k < 8; ++k)
    _mm256_storeu_pd(ptr[k], add ? _mm256_add_pd(x0[k], rows[k]) : _mm256_sub_pd(x0[k], rows[k]));
}

}  // namespace deform::simd

#endif
