#include "solver_kernels.h"

#include <algorithm>
#include <cmath>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#define DEFORM_METABALLS_HAVE_AVX512 1
// GCC 12's masked AVX-512 intrinsics start from _mm512_undefined_pd(), which -Wmaybe-uninitialized
// flags inside the system header.
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#endif

namespace deform::metaballs {

namespace {
constexpr Real kTiny2 = 1e-24;  // (1e-12 m)^2: a zero-length link
}

StretchBatches buildStretchBatches(const MatX2i& links, const std::vector<Real>& rest,
                                   const std::vector<Real>& compliance, int dummy) {
  const int nl = int(links.rows());
  // Greedy colouring: each link takes the lowest colour used by neither end yet. Colour sets are
  // kept as per-sphere bit lists grown on demand.
  std::vector<std::vector<uint8_t>> used{size_t(dummy)};
  std::vector<int> colour(size_t(nl), 0);
  int numColours = 0;
  for (int l = 0; l < nl; ++l) {
    auto& ua = used[size_t(links(l, 0))];
    auto& ub = used[size_t(links(l, 1))];
    int c = 0;
    while ((c < int(ua.size()) && ua[size_t(c)]) || (c < int(ub.size()) && ub[size_t(c)])) ++c;
    if (int(ua.size()) <= c) ua.resize(size_t(c) + 1, 0);
    if (int(ub.size()) <= c) ub.resize(size_t(c) + 1, 0);
    ua[size_t(c)] = ub[size_t(c)] = 1;
    colour[size_t(l)] = c;
    numColours = std::max(numColours, c + 1);
  }
  std::vector<std::vector<int>> members{size_t(numColours)};
  for (int l = 0; l < nl; ++l) members[size_t(colour[size_t(l)])].push_back(l);
  StretchBatches b;
  b.colourStart.push_back(0);
  for (const auto& m : members) {
    const size_t padded = (m.size() + 7) / 8 * 8;
    for (size_t k = 0; k < padded; ++k) {
      const int l = k < m.size() ? m[k] : -1;
      b.a.push_back(l >= 0 ? links(l, 0) : dummy);
      b.b.push_back(l >= 0 ? links(l, 1) : dummy);
      b.link.push_back(l);
      b.rest.push_back(l >= 0 ? rest[size_t(l)] : 0);
      b.compliance.push_back(l >= 0 ? compliance[size_t(l)] : 0);
    }
    b.colourStart.push_back(int(b.a.size()));
  }
  return b;
}

namespace {

// One link, scalar; the reference for the AVX-512 lanes (same operations, same order).
inline long long projectOne(const StretchBatches& bt, StretchStepData& d, Real* p4, Real k,
                            size_t i) {
  const Real wa = d.wa[i], wb = d.wb[i], at = d.alphaTilde[i];
  Real* pa = p4 + 4 * size_t(bt.a[i]);
  Real* pb = p4 + 4 * size_t(bt.b[i]);
  const Real dx = pa[0] - pb[0], dy = pa[1] - pb[1], dz = pa[2] - pb[2];
  const Real len2 = (dx * dx + dy * dy) + dz * dz;
  const Real wsum = wa + wb;
  if (!(wsum > 0)) return 0;
  if (!(len2 > kTiny2)) return 1;
  const Real len = std::sqrt(len2);
  const Real dl = (k * (bt.rest[i] - len) - at * d.lambda[i]) / (wsum + at);
  d.lambda[i] = d.lambda[i] + dl;
  const Real s = dl / len;
  const Real sa = wa * s, sb = wb * s;
  pa[0] = pa[0] + sa * dx;
  pa[1] = pa[1] + sa * dy;
  pa[2] = pa[2] + sa * dz;
  pb[0] = pb[0] - sb * dx;
  pb[1] = pb[1] - sb * dy;
  pb[2] = pb[2] - sb * dz;
  return 0;
}

#ifdef DEFORM_METABALLS_HAVE_AVX512
#define DEFORM_AVX512 __attribute__((target("avx512f,avx512vl,avx512dq")))

// Corrections s * (dx, dy, dz) of eight links (columns) back to rows (x, y, z, 0), added to (add)
// or subtracted from the rows x0 and stored at ptr.
DEFORM_AVX512 inline void commitRows8(__m512d s, __m512d dx, __m512d dy, __m512d dz,
                                      Real* const* ptr, const __m256d* x0, bool add) {
  const __m512i lowRows = _mm512_set_epi64(11, 10, 3, 2, 9, 8, 1, 0);
  const __m512i highRows = _mm512_set_epi64(15, 14, 7, 6, 13, 12, 5, 4);
  const __m512d zero = _mm512_setzero_pd();
  const __m512d cx = _mm512_mul_pd(s, dx), cy = _mm512_mul_pd(s, dy), cz = _mm512_mul_pd(s, dz);
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

DEFORM_AVX512 long long sweepAvx512(const StretchBatches& bt, StretchStepData& d, Real* p4,
                                    Real k) {
  const __m512d tiny2 = _mm512_set1_pd(kTiny2), zero = _mm512_setzero_pd(), kk = _mm512_set1_pd(k);
  long long degenerate = 0;
  const size_t n = size_t(bt.size());
  for (size_t i = 0; i < n; i += 8) {
    Real* pa[8];
    Real* pb[8];
    __m256d xa[8], xb[8], dr[8];
    for (int q = 0; q < 8; ++q) {
      pa[q] = p4 + 4 * size_t(bt.a[i + size_t(q)]);
      pb[q] = p4 + 4 * size_t(bt.b[i + size_t(q)]);
      xa[q] = _mm256_loadu_pd(pa[q]);
      xb[q] = _mm256_loadu_pd(pb[q]);
      dr[q] = _mm256_sub_pd(xa[q], xb[q]);
    }
    // Rows (dx, dy, dz, 0) of links 0..7 -> columns dx, dy, dz in link order.
    const __m512d z0 = _mm512_insertf64x4(_mm512_castpd256_pd512(dr[0]), dr[2], 1);
    const __m512d z1 = _mm512_insertf64x4(_mm512_castpd256_pd512(dr[1]), dr[3], 1);
    const __m512d z2 = _mm512_insertf64x4(_mm512_castpd256_pd512(dr[4]), dr[6], 1);
    const __m512d z3 = _mm512_insertf64x4(_mm512_castpd256_pd512(dr[5]), dr[7], 1);
    const __m512d t0 = _mm512_unpacklo_pd(z0, z1), t1 = _mm512_unpackhi_pd(z0, z1);
    const __m512d t2 = _mm512_unpacklo_pd(z2, z3), t3 = _mm512_unpackhi_pd(z2, z3);
    const __m512d dx = _mm512_shuffle_f64x2(t0, t2, 0x88);
    const __m512d dy = _mm512_shuffle_f64x2(t1, t3, 0x88);
    const __m512d dz = _mm512_shuffle_f64x2(t0, t2, 0xDD);
    const __m512d len2 = _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(dx, dx), _mm512_mul_pd(dy, dy)),
                                       _mm512_mul_pd(dz, dz));
    const __m512d wa = _mm512_loadu_pd(d.wa.data() + i), wb = _mm512_loadu_pd(d.wb.data() + i);
    const __m512d at = _mm512_loadu_pd(d.alphaTilde.data() + i);
    const __m512d wsum = _mm512_add_pd(wa, wb);
    const __mmask8 movable = _mm512_cmp_pd_mask(wsum, zero, _CMP_GT_OQ);
    const __mmask8 ok = movable & _mm512_cmp_pd_mask(len2, tiny2, _CMP_GT_OQ);
    degenerate += __builtin_popcount(unsigned(movable & ~ok) & 0xffu);
    if (!ok) continue;
    const __m512d len = _mm512_maskz_sqrt_pd(ok, len2);
    __m512d lambda = _mm512_loadu_pd(d.lambda.data() + i);
    const __m512d num =
        _mm512_sub_pd(_mm512_mul_pd(kk, _mm512_sub_pd(_mm512_loadu_pd(bt.rest.data() + i), len)),
                      _mm512_mul_pd(at, lambda));
    const __m512d dl = _mm512_maskz_div_pd(ok, num, _mm512_add_pd(wsum, at));
    lambda = _mm512_mask_add_pd(lambda, ok, lambda, dl);
    _mm512_storeu_pd(d.lambda.data() + i, lambda);
    const __m512d s = _mm512_maskz_div_pd(ok, dl, len);
    commitRows8(_mm512_mul_pd(wa, s), dx, dy, dz, pa, xa, true);
    commitRows8(_mm512_mul_pd(wb, s), dx, dy, dz, pb, xb, false);
  }
  return degenerate;
}

bool cpuHasAvx512() {
  static const bool ok = __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") &&
                         __builtin_cpu_supports("avx512dq");
  return ok;
}
#endif

}  // namespace

bool simdAvailable() {
#ifdef DEFORM_METABALLS_HAVE_AVX512
  return cpuHasAvx512();
#else
  return false;
#endif
}

long long projectStretchSweep(const StretchBatches& batches, StretchStepData& data, Real* p4,
                              Real k, bool simd) {
#ifdef DEFORM_METABALLS_HAVE_AVX512
  if (simd && cpuHasAvx512()) return sweepAvx512(batches, data, p4, k);
#endif
  long long degenerate = 0;
  for (size_t i = 0; i < size_t(batches.size()); ++i)
    degenerate += projectOne(batches, data, p4, k, i);
  return degenerate;
}

void projectLaplacianSweep(const std::vector<int>& adjStart, const std::vector<int>& adj,
                           const Real* w, LaplacianStepData& d, Real* p4, Real k) {
  const int n = int(adjStart.size()) - 1;
  for (int m = 0; m < n; ++m) {
    const Real W = d.W[size_t(m)];
    if (!(W > 0)) continue;
    const int b = adjStart[size_t(m)], e = adjStart[size_t(m) + 1];
    Real cx = 0, cy = 0, cz = 0;
    for (int q = b; q < e; ++q) {
      const Real* pi = p4 + 4 * size_t(adj[size_t(q)]);
      cx += pi[0];
      cy += pi[1];
      cz += pi[2];
    }
    const Real cnt = Real(e - b);
    Real* pm = p4 + 4 * size_t(m);
    const Real* t = d.target.data() + 4 * size_t(m);
    Real* lam = d.lambda.data() + 4 * size_t(m);
    const Real at = d.alphaTilde[size_t(m)];
    const Real denom = W + at;
    const Real dlx = (-k * (pm[0] - cx / cnt - t[0]) - at * lam[0]) / denom;
    const Real dly = (-k * (pm[1] - cy / cnt - t[1]) - at * lam[1]) / denom;
    const Real dlz = (-k * (pm[2] - cz / cnt - t[2]) - at * lam[2]) / denom;
    lam[0] += dlx;
    lam[1] += dly;
    lam[2] += dlz;
    const Real wm = w[m];
    pm[0] += wm * dlx;
    pm[1] += wm * dly;
    pm[2] += wm * dlz;
    for (int q = b; q < e; ++q) {
      Real* pi = p4 + 4 * size_t(adj[size_t(q)]);
      const Real c = d.coef[size_t(q)];
      pi[0] -= c * dlx;
      pi[1] -= c * dly;
      pi[2] -= c * dlz;
    }
  }
}

}  // namespace deform::metaballs
