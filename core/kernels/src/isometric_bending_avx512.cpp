// AVX-512 projection of sixteen float hinges per step (isometric_bending_math.h gives the
// arithmetic, written here again in the same order: no fused multiply-add, so that the results
// equal the scalar and AVX2 paths' bit for bit). Compiled with -mavx512f -mavx512vl -mavx512dq
// -ffp-contract=off and called only after a run-time CPU check (isometric_bending.cpp); includes
// nothing but the intrinsics and the internal headers.
//
// Layout: the four rows (x, y, z, pad) of slot k of hinges e, e + 4, e + 8, e + 12 share one
// 512-bit register Z[k][e] (hinge 4c + e in 128-bit chunk c). The stencil vector v of those four
// hinges is then four multiplies and three adds on whole registers, with each hinge's weight
// broadcast inside its chunk by one in-lane shuffle of the weights as loaded; the lengths need one
// 4 x 4 transpose inside the chunks, which leaves them in hinge order for the per-hinge
// arithmetic; and the corrections are added to the rows still in the registers and stored back
// (a colour's hinges share no moving particle, so no row of a group is stored twice with
// different values). Where the AVX2 path gathers and scatters every row through transposes, this
// one transposes only the squared lengths.
#if defined(__x86_64__) && defined(__GNUC__)
// GCC 12 reports -W(maybe-)uninitialized inside its own AVX-512 intrinsics (their
// _mm512_undefined_* pass-through operands, GCC bug 105593, fixed in GCC 13); nothing in this file
// is uninitialised.
#if !defined(__clang__) && __GNUC__ < 13
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#endif
#include <immintrin.h>

#include "isometric_bending_avx2.h"
#include "isometric_bending_math.h"

namespace deform::pbd::isobatch {

namespace {

__attribute__((always_inline)) inline __m512 loadRows(const float* x4, const int* off, int e) {
  __m512 z = _mm512_castps128_ps512(_mm_loadu_ps(x4 + off[e]));
  z = _mm512_insertf32x4(z, _mm_loadu_ps(x4 + off[4 + e]), 1);
  z = _mm512_insertf32x4(z, _mm_loadu_ps(x4 + off[8 + e]), 2);
  return _mm512_insertf32x4(z, _mm_loadu_ps(x4 + off[12 + e]), 3);
}

__attribute__((always_inline)) inline void storeRows(float* x4, const int* off, int e, __m512 z) {
  _mm_storeu_ps(x4 + off[e], _mm512_castps512_ps128(z));
  _mm_storeu_ps(x4 + off[4 + e], _mm512_extractf32x4_ps(z, 1));
  _mm_storeu_ps(x4 + off[8 + e], _mm512_extractf32x4_ps(z, 2));
  _mm_storeu_ps(x4 + off[12 + e], _mm512_extractf32x4_ps(z, 3));
}

// Broadcasts lane 4c + e of a to the four lanes of chunk c.
template <int e>
__attribute__((always_inline)) inline __m512 spread(__m512 a) {
  return _mm512_shuffle_ps(a, a, e * 0x55);
}

template <int e>
__attribute__((always_inline)) inline __m512 stencil(const __m512 (&Z)[4][4], const __m512 K[4]) {
  const __m512 v =
      _mm512_add_ps(_mm512_add_ps(_mm512_add_ps(_mm512_mul_ps(spread<e>(K[0]), Z[0][e]),
                                                _mm512_mul_ps(spread<e>(K[1]), Z[1][e])),
                                  _mm512_mul_ps(spread<e>(K[2]), Z[2][e])),
                    _mm512_mul_ps(spread<e>(K[3]), Z[3][e]));
  return _mm512_maskz_mov_ps(0x7777, v);  // the padding lane adds nothing to the rows
}

template <int e>
__attribute__((always_inline)) inline void commit(float* x4, const int* off, __m512 Z, __m512 c,
                                                  __m512 v) {
  storeRows(x4, off, e, _mm512_add_ps(Z, _mm512_mul_ps(spread<e>(c), v)));
}

// The first half of a group: the rows, the stencil vectors, the multipliers' update (stored) and
// the per-hinge factor s = dlambda / |v|; the second half (commitGroup) moves the rows.
struct Group {
  const int* off[4];
  __m512 Z[4][4];
  __m512 v[4];
  __m512 s;
  int degenerate;
};

__attribute__((always_inline)) inline void projectGroup(const float* x4, const View<float>& b,
                                                        std::size_t i, Group& g) {
  for (int k = 0; k < 4; ++k) g.off[k] = b.p[k] + i;
#pragma GCC unroll 4
  for (int k = 0; k < 4; ++k) {
#pragma GCC unroll 4
    for (int e = 0; e < 4; ++e) g.Z[k][e] = loadRows(x4, g.off[k], e);
  }
  const __m512 K[4] = {_mm512_loadu_ps(b.K[0] + i), _mm512_loadu_ps(b.K[1] + i),
                       _mm512_loadu_ps(b.K[2] + i), _mm512_loadu_ps(b.K[3] + i)};
  g.v[0] = stencil<0>(g.Z, K);
  g.v[1] = stencil<1>(g.Z, K);
  g.v[2] = stencil<2>(g.Z, K);
  g.v[3] = stencil<3>(g.Z, K);
  // |v|^2 of hinge 4c + e in lane 4c + e: squares, then a 4 x 4 transpose inside the chunks.
  const __m512 q0 = _mm512_mul_ps(g.v[0], g.v[0]), q1 = _mm512_mul_ps(g.v[1], g.v[1]);
  const __m512 q2 = _mm512_mul_ps(g.v[2], g.v[2]), q3 = _mm512_mul_ps(g.v[3], g.v[3]);
  const __m512 t0 = _mm512_unpacklo_ps(q0, q1), t1 = _mm512_unpackhi_ps(q0, q1);
  const __m512 t2 = _mm512_unpacklo_ps(q2, q3), t3 = _mm512_unpackhi_ps(q2, q3);
  const __m512 l2 =
      _mm512_add_ps(_mm512_add_ps(_mm512_shuffle_ps(t0, t2, 0x44), _mm512_shuffle_ps(t0, t2, 0xEE)),
                    _mm512_shuffle_ps(t1, t3, 0x44));
  const __m512 tiny = _mm512_set1_ps(static_cast<float>(kTinyLength2));
  const __mmask16 ok = _mm512_cmp_ps_mask(l2, tiny, _CMP_GT_OQ);
  const __m512 len = _mm512_sqrt_ps(_mm512_max_ps(l2, tiny));
  const __m512 rest = _mm512_loadu_ps(b.rest + i);
  __m512 lambda = _mm512_loadu_ps(b.lambda + i);
  const __m512 minusC = _mm512_xor_ps(_mm512_sub_ps(len, rest), _mm512_set1_ps(-0.0f));
  const __m512 dl = _mm512_maskz_mul_ps(
      ok, _mm512_loadu_ps(b.scale + i),
      _mm512_sub_ps(minusC, _mm512_mul_ps(_mm512_loadu_ps(b.alphaTilde + i), lambda)));
  lambda = _mm512_add_ps(lambda, dl);
  _mm512_storeu_ps(b.lambda + i, lambda);
  g.s = _mm512_div_ps(dl, len);
  // Degenerate: |v| = 0 where the rest value asks for a bend (a flat hinge at rest is fine).
  const __mmask16 bent = _mm512_cmp_ps_mask(rest, _mm512_setzero_ps(), _CMP_NEQ_OQ);
  g.degenerate = __builtin_popcount(static_cast<unsigned>(static_cast<__mmask16>(~ok) & bent));
}

__attribute__((always_inline)) inline int commitGroup(float* x4, const View<float>& b,
                                                      std::size_t i, const Group& g) {
  // dx_k = w_k dlambda g_k, g_k = K_k v / |v|; a slot immovable in every hinge adds exactly 0.
  unsigned slots = 0xFu;
  if (b.movable != nullptr) {
    slots = 0;
    for (int l = 0; l < 16; ++l) slots |= b.movable[i + l];
  }
#pragma GCC unroll 4
  for (int k = 0; k < 4; ++k) {
    if (!(slots & (1u << k))) continue;
    const __m512 c = _mm512_mul_ps(_mm512_loadu_ps(b.wK[k] + i), g.s);
    commit<0>(x4, g.off[k], g.Z[k][0], c, g.v[0]);
    commit<1>(x4, g.off[k], g.Z[k][1], c, g.v[1]);
    commit<2>(x4, g.off[k], g.Z[k][2], c, g.v[2]);
    commit<3>(x4, g.off[k], g.Z[k][3], c, g.v[3]);
  }
  return g.degenerate;
}

}  // namespace

std::size_t rangeAvx512(float* x4, const View<float>& b, std::size_t begin, std::size_t end,
                        long long* degenerate) {
  // Two groups at a time, both first halves before both second halves: the second group's loads
  // and its square root and division overlap the first's (one group alone is latency-bound).
  std::size_t i = begin;
  for (; i + 32 <= end; i += 32) {
    Group g0, g1;
    projectGroup(x4, b, i, g0);
    projectGroup(x4, b, i + 16, g1);
    *degenerate += commitGroup(x4, b, i, g0);
    *degenerate += commitGroup(x4, b, i + 16, g1);
  }
  for (; i + 16 <= end; i += 16) {
    Group g;
    projectGroup(x4, b, i, g);
    *degenerate += commitGroup(x4, b, i, g);
  }
  return i - begin;
}

}  // namespace deform::pbd::isobatch

#endif
