// The AVX2 paths of the element pass (element_product.h). Compiled with -mavx2 -ffp-contract=off
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

/// The three values at p in lanes 0-2 (lane 3 zero), reading nothing beyond them.
inline __m256d load3(const double* p) {
  return _mm256_insertf128_pd(_mm256_castpd128_pd256(_mm_loadu_pd(p)), _mm_load_sd(p + 2), 1);
}

/// Lanes 0-2 of v to p, writing nothing beyond them.
inline void store3(double* p, __m256d v) {
  _mm_storeu_pd(p, _mm256_castpd256_pd128(v));
  _mm_store_sd(p + 2, _mm256_extractf128_pd(v, 1));
}

}  // namespace

void gatherRotatedAvx2(const int* hexes, const double* R, const double* in, const double* rest,
                       double a, double b, double* U, int E) {
  const __m256d va = _mm256_set1_pd(a), vb = _mm256_set1_pd(b);
  for (int e = 0; e < E; ++e) {
    const double* r = R + 9 * e;
    // Lane c of row k: R(k, c), so u = row0 v0 + row1 v1 + row2 v2 is R^T v.
    const __m256d row0 = _mm256_setr_pd(r[0], r[3], r[6], 0.0);
    const __m256d row1 = _mm256_setr_pd(r[1], r[4], r[7], 0.0);
    const __m256d row2 = _mm256_setr_pd(r[2], r[5], r[8], 0.0);
    for (int i = 0; i < 8; ++i) {
      const int n = hexes[8 * e + i];
      const double* v = in + 3 * n;
      __m256d u = _mm256_mul_pd(row0, _mm256_mul_pd(va, _mm256_broadcast_sd(v)));
      u = _mm256_add_pd(u, _mm256_mul_pd(row1, _mm256_mul_pd(va, _mm256_broadcast_sd(v + 1))));
      u = _mm256_add_pd(u, _mm256_mul_pd(row2, _mm256_mul_pd(va, _mm256_broadcast_sd(v + 2))));
      if (b != 0) u = _mm256_sub_pd(u, _mm256_mul_pd(vb, load3(rest + 3 * n)));
      store3(U + 24 * e + 3 * i, u);
    }
  }
}

void scatterRotatedAvx2(const int* hexes, const double* R, const double* KU, const double* fill,
                        double scale, double* out, int E) {
  for (int e = 0; e < E; ++e) {
    const __m256d s = _mm256_set1_pd(scale * fill[e]);
    const double* r = R + 9 * e;
    // Column c of s R in lanes 0-2: out += col0 f0 + col1 f1 + col2 f2.
    const __m256d col0 = _mm256_mul_pd(s, load3(r)), col1 = _mm256_mul_pd(s, load3(r + 3));
    const __m256d col2 = _mm256_mul_pd(s, load3(r + 6));
    for (int i = 0; i < 8; ++i) {
      const double* f = KU + 24 * e + 3 * i;
      double* o = out + 3 * hexes[8 * e + i];
      __m256d x = _mm256_mul_pd(col0, _mm256_broadcast_sd(f));
      x = _mm256_add_pd(x, _mm256_mul_pd(col1, _mm256_broadcast_sd(f + 1)));
      x = _mm256_add_pd(x, _mm256_mul_pd(col2, _mm256_broadcast_sd(f + 2)));
      store3(o, _mm256_add_pd(load3(o), x));
    }
  }
}

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
