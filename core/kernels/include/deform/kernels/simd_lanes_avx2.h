// deformbench kernels: the AVX2 lanes of the batched constraint kernels (deform/kernels/
// simd_lanes.h describes the interface): four doubles per __m256d, eight floats per __m256.
// Include it only from a translation unit compiled for AVX2, under the rules of
// deform/kernels/simd_rows_avx2.h (whose row gathers these lanes use).
#pragma once

#include <deform/kernels/simd_rows_avx2.h>
#include <immintrin.h>

namespace deform::simd {

/// The 256-bit vector of T (a trait: a vector type passed as a template argument would lose its
/// attributes).
template <class T>
struct Avx2Vector;
template <>
struct Avx2Vector<double> {
  using type = __m256d;
};
template <>
struct Avx2Vector<float> {
  using type = __m256;
};

/// Row and point access of the AVX2 lanes (simd_lanes.h): rows (x, y, z, 0) at x4 + off[k], or
/// the points idx[k] (rows at x4 + 4 idx[k]), <-> columns x, y, z of kWidth lanes. The points of
/// an add are distinct or immovable (their lanes are then exactly zero).
template <class T>
struct Avx2Rows {
  using V = typename Avx2Vector<T>::type;
  static void loadRows(const T* x4, const int* off, V& x, V& y, V& z) {
    gatherRows([&](int k) { return x4 + off[k]; }, x, y, z);
  }
  static void addRows(T* x4, const int* off, V dx, V dy, V dz) {
    addToRows([&](int k) { return x4 + off[k]; }, dx, dy, dz);
  }
  static void loadPoints(const T* x4, const int* idx, V& x, V& y, V& z) {
    gatherRows([&](int k) { return x4 + 4 * static_cast<long>(idx[k]); }, x, y, z);
  }
  static void addPoints(T* x4, const int* idx, V dx, V dy, V dz) {
    addToRows([&](int k) { return x4 + 4 * static_cast<long>(idx[k]); }, dx, dy, dz);
  }
};

/// Four double lanes per __m256d.
struct Avx2Double4 : Avx2Rows<double> {
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
  static M le(V a, V b) { return _mm256_cmp_pd(a, b, _CMP_LE_OQ); }
  static M ne(V a, V b) { return _mm256_cmp_pd(a, b, _CMP_NEQ_OQ); }
  static M band(M a, M b) { return _mm256_and_pd(a, b); }
  static M notMask(M a) { return _mm256_xor_pd(a, _mm256_castsi256_pd(_mm256_set1_epi64x(-1))); }
  static V select(M m, V a, V b) { return _mm256_blendv_pd(b, a, m); }
  static int count(M m) { return __builtin_popcount(_mm256_movemask_pd(m)); }
  static unsigned orBytes(const unsigned char* m) { return m[0] | m[1] | m[2] | m[3]; }
  static bool anyByte(const unsigned char* m) { return (m[0] | m[1] | m[2] | m[3]) != 0; }
};

/// Eight float lanes per __m256.
struct Avx2Float8 : Avx2Rows<float> {
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
  static M le(V a, V b) { return _mm256_cmp_ps(a, b, _CMP_LE_OQ); }
  static M ne(V a, V b) { return _mm256_cmp_ps(a, b, _CMP_NEQ_OQ); }
  static M band(M a, M b) { return _mm256_and_ps(a, b); }
  static M notMask(M a) { return _mm256_xor_ps(a, _mm256_castsi256_ps(_mm256_set1_epi32(-1))); }
  static V select(M m, V a, V b) { return _mm256_blendv_ps(b, a, m); }
  static int count(M m) { return __builtin_popcount(_mm256_movemask_ps(m)); }
  static bool anyByte(const unsigned char* m) {
    unsigned char any = 0;
    for (int k = 0; k < 8; ++k) any |= m[k];
    return any != 0;
  }
};

}  // namespace deform::simd
