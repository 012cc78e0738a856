// The AVX2 path of multiplyElements (element_product.h). Compiled with -mavx2 -ffp-contract=off
// (CMakeLists.txt) and entered only after a run-time CPU check (element_product.cpp).
#include <immintrin.h>

#include "element_product.h"

namespace deform::fem_hex::detail {

namespace {

/// acc[r] += K0 column rows 4r..4r+3 times x, for the six row blocks of one column.
inline void accumulate(const double* k, __m256d x, __m256d* acc) {
  for (int r = 0; r < 6; ++r)
    acc[r] = _mm256_add_pd(acc[r], _mm256_mul_pd(_mm256_loadu_pd(k + 4 * r), x));
}

}  // namespace

void multiplyElementsAvx2(const double* K0, const double* U, double* KU, int E) {
  int e = 0;
  // Two elements per pass: 12 accumulators, each K0 column block loaded once for both.
  for (; e + 2 <= E; e += 2) {
    const double* u0 = U + 24 * e;
    const double* u1 = u0 + 24;
    __m256d a[6], b[6];
    for (int r = 0; r < 6; ++r) a[r] = b[r] = _mm256_setzero_pd();
    for (int j = 0; j < 24; ++j) {
      const double* k = K0 + 24 * j;
      const __m256d x0 = _mm256_broadcast_sd(u0 + j), x1 = _mm256_broadcast_sd(u1 + j);
      for (int r = 0; r < 6; ++r) {
        const __m256d c = _mm256_loadu_pd(k + 4 * r);
        a[r] = _mm256_add_pd(a[r], _mm256_mul_pd(c, x0));
        b[r] = _mm256_add_pd(b[r], _mm256_mul_pd(c, x1));
      }
    }
    for (int r = 0; r < 6; ++r) {
      _mm256_storeu_pd(KU + 24 * e + 4 * r, a[r]);
      _mm256_storeu_pd(KU + 24 * (e + 1) + 4 * r, b[r]);
    }
  }
  for (; e < E; ++e) {
    __m256d a[6];
    for (int r = 0; r < 6; ++r) a[r] = _mm256_setzero_pd();
    for (int j = 0; j < 24; ++j) accumulate(K0 + 24 * j, _mm256_broadcast_sd(U + 24 * e + j), a);
    for (int r = 0; r < 6; ++r) _mm256_storeu_pd(KU + 24 * e + 4 * r, a[r]);
  }
}

}  // namespace deform::fem_hex::detail
