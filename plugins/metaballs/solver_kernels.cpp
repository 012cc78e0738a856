#include "solver_kernels.h"

#include <deform/kernels/simd_rows.h>

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
    simd::commitRows8(_mm512_mul_pd(wa, s), dx, dy, dz, pa, xa, true);
    simd::commitRows8(_mm512_mul_pd(wb, s), dx, dy, dz, pb, xb, false);
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

void RotationBatch::resize(int count) {
  n = count;
  padded = (count + 7) / 8 * 8;
  A.assign(size_t(9) * size_t(padded), 0);
  q.assign(size_t(4) * size_t(padded), 0);
  setIdentity();
}

void RotationBatch::setIdentity() {
  std::fill(q.begin(), q.end(), 0.0);
  std::fill(q.begin(), q.begin() + padded, 1.0);
}

namespace {

constexpr Real kQuarterPi = 0.78539816339744830962;
// Taylor coefficients of sin and cos up to h^15 / h^16: below 1e-16 relative on |h| <= pi/4.
constexpr Real kSin[8] = {1.0,          -1.0 / 6,        1.0 / 120,        -1.0 / 5040,
                          1.0 / 362880, -1.0 / 39916800, 1.0 / 6227020800, -1.0 / 1307674368000};
constexpr Real kCos[9] = {1.0,
                          -1.0 / 2,
                          1.0 / 24,
                          -1.0 / 720,
                          1.0 / 40320,
                          -1.0 / 3628800,
                          1.0 / 479001600,
                          -1.0 / 87178291200,
                          1.0 / 20922789888000};

inline void sinCosHalf(Real h, Real& s, Real& c) {
  if (!(std::abs(h) <= kQuarterPi)) {
    s = std::sin(h);
    c = std::cos(h);
    return;
  }
  const Real h2 = h * h;
  Real ps = kSin[7], pc = kCos[8];
  for (int k = 6; k >= 0; --k) ps = ps * h2 + kSin[k];
  for (int k = 7; k >= 0; --k) pc = pc * h2 + kCos[k];
  s = h * ps;
  c = pc;
}

// R(q) row-major, Eigen's toRotationMatrix() formula.
inline void rotationOf(Real w, Real x, Real y, Real z, Real* R) {
  const Real tx = 2 * x, ty = 2 * y, tz = 2 * z;
  const Real twx = tx * w, twy = ty * w, twz = tz * w;
  const Real txx = tx * x, txy = ty * x, txz = tz * x;
  const Real tyy = ty * y, tyz = tz * y, tzz = tz * z;
  R[0] = 1 - (tyy + tzz);
  R[1] = txy - twz;
  R[2] = txz + twy;
  R[3] = txy + twz;
  R[4] = 1 - (txx + tzz);
  R[5] = tyz - twx;
  R[6] = txz - twy;
  R[7] = tyz + twx;
  R[8] = 1 - (txx + tyy);
}

void extractOne(RotationBatch& b, int i, int maxIter, Real* out) {
  const size_t P = size_t(b.padded);
  Real a[9];
  for (int k = 0; k < 9; ++k) a[k] = b.A[size_t(k) * P + size_t(i)];
  Real w = b.q[size_t(i)], x = b.q[P + size_t(i)], y = b.q[2 * P + size_t(i)],
       z = b.q[3 * P + size_t(i)];
  Real R[9];
  for (int it = 0; it < maxIter; ++it) {
    rotationOf(w, x, y, z, R);
    // sum over columns c of R_c x A_c and R_c . A_c (column c of a 3x3 row-major M: M[c], M[3+c],
    // M[6+c]).
    Real ox = 0, oy = 0, oz = 0, dot = 0;
    for (int c = 0; c < 3; ++c) {
      const Real r0 = R[c], r1 = R[3 + c], r2 = R[6 + c];
      const Real a0 = a[c], a1 = a[3 + c], a2 = a[6 + c];
      ox = ox + (r1 * a2 - r2 * a1);
      oy = oy + (r2 * a0 - r0 * a2);
      oz = oz + (r0 * a1 - r1 * a0);
      dot = dot + ((r0 * a0 + r1 * a1) + r2 * a2);
    }
    const Real inv = 1 / (std::abs(dot) + 1e-30);
    ox = ox * inv;
    oy = oy * inv;
    oz = oz * inv;
    const Real ang = std::sqrt((ox * ox + oy * oy) + oz * oz);
    if (!(ang >= 1e-9)) break;
    Real sh, ch;
    sinCosHalf(0.5 * ang, sh, ch);
    const Real f = sh / ang;
    const Real dw = ch, dx = f * ox, dy = f * oy, dz = f * oz;
    // q <- dq q (Hamilton product), then normalise.
    const Real nw = ((dw * w - dx * x) - dy * y) - dz * z;
    const Real nx = ((dw * x + dx * w) + dy * z) - dz * y;
    const Real ny = ((dw * y - dx * z) + dy * w) + dz * x;
    const Real nz = ((dw * z + dx * y) - dy * x) + dz * w;
    const Real rn = 1 / std::sqrt(((nw * nw + nx * nx) + ny * ny) + nz * nz);
    w = nw * rn;
    x = nx * rn;
    y = ny * rn;
    z = nz * rn;
  }
  b.q[size_t(i)] = w;
  b.q[P + size_t(i)] = x;
  b.q[2 * P + size_t(i)] = y;
  b.q[3 * P + size_t(i)] = z;
  rotationOf(w, x, y, z, out + 9 * size_t(i));
}

#ifdef DEFORM_METABALLS_HAVE_AVX512
DEFORM_AVX512 inline void rotationOf8(__m512d w, __m512d x, __m512d y, __m512d z, __m512d* R) {
  const __m512d two = _mm512_set1_pd(2), one = _mm512_set1_pd(1);
  const __m512d tx = _mm512_mul_pd(two, x), ty = _mm512_mul_pd(two, y), tz = _mm512_mul_pd(two, z);
  const __m512d twx = _mm512_mul_pd(tx, w), twy = _mm512_mul_pd(ty, w), twz = _mm512_mul_pd(tz, w);
  const __m512d txx = _mm512_mul_pd(tx, x), txy = _mm512_mul_pd(ty, x), txz = _mm512_mul_pd(tz, x);
  const __m512d tyy = _mm512_mul_pd(ty, y), tyz = _mm512_mul_pd(tz, y), tzz = _mm512_mul_pd(tz, z);
  R[0] = _mm512_sub_pd(one, _mm512_add_pd(tyy, tzz));
  R[1] = _mm512_sub_pd(txy, twz);
  R[2] = _mm512_add_pd(txz, twy);
  R[3] = _mm512_add_pd(txy, twz);
  R[4] = _mm512_sub_pd(one, _mm512_add_pd(txx, tzz));
  R[5] = _mm512_sub_pd(tyz, twx);
  R[6] = _mm512_sub_pd(txz, twy);
  R[7] = _mm512_add_pd(tyz, twx);
  R[8] = _mm512_sub_pd(one, _mm512_add_pd(txx, tyy));
}

DEFORM_AVX512 void extract8(RotationBatch& b, int i0, int maxIter, Real* out) {
  const size_t P = size_t(b.padded), i = size_t(i0);
  __m512d a[9];
  for (int k = 0; k < 9; ++k) a[k] = _mm512_loadu_pd(b.A.data() + size_t(k) * P + i);
  __m512d w = _mm512_loadu_pd(b.q.data() + i), x = _mm512_loadu_pd(b.q.data() + P + i),
          y = _mm512_loadu_pd(b.q.data() + 2 * P + i), z = _mm512_loadu_pd(b.q.data() + 3 * P + i);
  const __m512d zero = _mm512_setzero_pd(), one = _mm512_set1_pd(1), half = _mm512_set1_pd(0.5),
                eps = _mm512_set1_pd(1e-30), stop = _mm512_set1_pd(1e-9),
                quarterPi = _mm512_set1_pd(kQuarterPi);
  __mmask8 active = 0xff;
  __m512d R[9];
  for (int it = 0; it < maxIter && active; ++it) {
    rotationOf8(w, x, y, z, R);
    __m512d ox = zero, oy = zero, oz = zero, dot = zero;
    for (int c = 0; c < 3; ++c) {
      const __m512d r0 = R[c], r1 = R[3 + c], r2 = R[6 + c];
      const __m512d a0 = a[c], a1 = a[3 + c], a2 = a[6 + c];
      ox = _mm512_add_pd(ox, _mm512_sub_pd(_mm512_mul_pd(r1, a2), _mm512_mul_pd(r2, a1)));
      oy = _mm512_add_pd(oy, _mm512_sub_pd(_mm512_mul_pd(r2, a0), _mm512_mul_pd(r0, a2)));
      oz = _mm512_add_pd(oz, _mm512_sub_pd(_mm512_mul_pd(r0, a1), _mm512_mul_pd(r1, a0)));
      dot = _mm512_add_pd(dot,
                          _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(r0, a0), _mm512_mul_pd(r1, a1)),
                                        _mm512_mul_pd(r2, a2)));
    }
    const __m512d inv = _mm512_div_pd(one, _mm512_add_pd(_mm512_abs_pd(dot), eps));
    ox = _mm512_mul_pd(ox, inv);
    oy = _mm512_mul_pd(oy, inv);
    oz = _mm512_mul_pd(oz, inv);
    const __m512d ang = _mm512_sqrt_pd(_mm512_add_pd(
        _mm512_add_pd(_mm512_mul_pd(ox, ox), _mm512_mul_pd(oy, oy)), _mm512_mul_pd(oz, oz)));
    active &= _mm512_cmp_pd_mask(ang, stop, _CMP_GE_OQ);
    if (!active) break;
    const __m512d h = _mm512_mul_pd(half, ang);
    const __m512d h2 = _mm512_mul_pd(h, h);
    __m512d ps = _mm512_set1_pd(kSin[7]), pc = _mm512_set1_pd(kCos[8]);
    for (int k = 6; k >= 0; --k) ps = _mm512_add_pd(_mm512_mul_pd(ps, h2), _mm512_set1_pd(kSin[k]));
    for (int k = 7; k >= 0; --k) pc = _mm512_add_pd(_mm512_mul_pd(pc, h2), _mm512_set1_pd(kCos[k]));
    __m512d sh = _mm512_mul_pd(h, ps), ch = pc;
    const __mmask8 far = active & ~_mm512_cmp_pd_mask(_mm512_abs_pd(h), quarterPi, _CMP_LE_OQ);
    if (far) {  // rare: large correction angles take the library sin/cos, as the scalar path
      alignas(64) Real hs[8], ss[8], cs[8];
      _mm512_store_pd(hs, h);
      _mm512_store_pd(ss, sh);
      _mm512_store_pd(cs, ch);
      for (int k = 0; k < 8; ++k)
        if (far & (1u << k)) {
          ss[k] = std::sin(hs[k]);
          cs[k] = std::cos(hs[k]);
        }
      sh = _mm512_load_pd(ss);
      ch = _mm512_load_pd(cs);
    }
    const __m512d f = _mm512_maskz_div_pd(active, sh, ang);
    const __m512d dw = ch, dx = _mm512_mul_pd(f, ox), dy = _mm512_mul_pd(f, oy),
                  dz = _mm512_mul_pd(f, oz);
    const __m512d nw =
        _mm512_sub_pd(_mm512_sub_pd(_mm512_sub_pd(_mm512_mul_pd(dw, w), _mm512_mul_pd(dx, x)),
                                    _mm512_mul_pd(dy, y)),
                      _mm512_mul_pd(dz, z));
    const __m512d nx =
        _mm512_sub_pd(_mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(dw, x), _mm512_mul_pd(dx, w)),
                                    _mm512_mul_pd(dy, z)),
                      _mm512_mul_pd(dz, y));
    const __m512d ny =
        _mm512_add_pd(_mm512_add_pd(_mm512_sub_pd(_mm512_mul_pd(dw, y), _mm512_mul_pd(dx, z)),
                                    _mm512_mul_pd(dy, w)),
                      _mm512_mul_pd(dz, x));
    const __m512d nz =
        _mm512_add_pd(_mm512_sub_pd(_mm512_add_pd(_mm512_mul_pd(dw, z), _mm512_mul_pd(dx, y)),
                                    _mm512_mul_pd(dy, x)),
                      _mm512_mul_pd(dz, w));
    const __m512d rn = _mm512_div_pd(
        one, _mm512_sqrt_pd(_mm512_add_pd(
                 _mm512_add_pd(_mm512_add_pd(_mm512_mul_pd(nw, nw), _mm512_mul_pd(nx, nx)),
                               _mm512_mul_pd(ny, ny)),
                 _mm512_mul_pd(nz, nz))));
    w = _mm512_mask_mul_pd(w, active, nw, rn);
    x = _mm512_mask_mul_pd(x, active, nx, rn);
    y = _mm512_mask_mul_pd(y, active, ny, rn);
    z = _mm512_mask_mul_pd(z, active, nz, rn);
  }
  _mm512_storeu_pd(b.q.data() + i, w);
  _mm512_storeu_pd(b.q.data() + P + i, x);
  _mm512_storeu_pd(b.q.data() + 2 * P + i, y);
  _mm512_storeu_pd(b.q.data() + 3 * P + i, z);
  rotationOf8(w, x, y, z, R);
  alignas(64) Real rr[9][8];
  for (int k = 0; k < 9; ++k) _mm512_store_pd(rr[k], R[k]);
  const int lanes = std::min(8, b.n - i0);
  for (int l = 0; l < lanes; ++l)
    for (int k = 0; k < 9; ++k) out[9 * (i + size_t(l)) + size_t(k)] = rr[k][l];
}
#endif

}  // namespace

void extractRotations(RotationBatch& batch, int maxIter, Real* rotations, bool simd) {
#ifdef DEFORM_METABALLS_HAVE_AVX512
  if (simd && cpuHasAvx512()) {
    for (int i = 0; i < batch.n; i += 8) extract8(batch, i, maxIter, rotations);
    return;
  }
#endif
  for (int i = 0; i < batch.n; ++i) extractOne(batch, i, maxIter, rotations);
}

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

std::vector<int> laplacianOrder(const std::vector<int>& adjStart, const std::vector<int>& adj) {
  const int n = int(adjStart.size()) - 1;
  // A colour is taken by sphere m when some constraint of that colour touches m (as centre or
  // neighbour); constraint m needs a colour free on m and on all its neighbours.
  std::vector<std::vector<uint8_t>> taken{size_t(n)};
  std::vector<int> colour(size_t(n), 0);
  int numColours = 0;
  auto isTaken = [&](int s, int c) {
    return c < int(taken[size_t(s)].size()) && taken[size_t(s)][size_t(c)];
  };
  auto take = [&](int s, int c) {
    if (int(taken[size_t(s)].size()) <= c) taken[size_t(s)].resize(size_t(c) + 1, 0);
    taken[size_t(s)][size_t(c)] = 1;
  };
  for (int m = 0; m < n; ++m) {
    int c = 0;
    for (;; ++c) {
      bool free = !isTaken(m, c);
      for (int k = adjStart[size_t(m)]; free && k < adjStart[size_t(m) + 1]; ++k)
        free = !isTaken(adj[size_t(k)], c);
      if (free) break;
    }
    take(m, c);
    for (int k = adjStart[size_t(m)]; k < adjStart[size_t(m) + 1]; ++k) take(adj[size_t(k)], c);
    colour[size_t(m)] = c;
    numColours = std::max(numColours, c + 1);
  }
  std::vector<int> order;
  order.reserve(size_t(n));
  for (int c = 0; c < numColours; ++c)
    for (int m = 0; m < n; ++m)
      if (colour[size_t(m)] == c) order.push_back(m);
  return order;
}

namespace {

// The neighbour sum uses two accumulators (even and odd neighbours), added at the end.
void laplacianScalar(const std::vector<int>& adjStart, const std::vector<int>& adj, const Real* w,
                     LaplacianStepData& d, Real* p4, Real k) {
  for (int m : d.order) {
    const Real W = d.W[size_t(m)];
    if (!(W > 0)) continue;
    const int b = adjStart[size_t(m)], e = adjStart[size_t(m) + 1];
    Real s0[3] = {0, 0, 0}, s1[3] = {0, 0, 0};
    int q = b;
    for (; q + 1 < e; q += 2) {
      const Real* p0 = p4 + 4 * size_t(adj[size_t(q)]);
      const Real* p1 = p4 + 4 * size_t(adj[size_t(q) + 1]);
      for (int c = 0; c < 3; ++c) {
        s0[c] = s0[c] + p0[c];
        s1[c] = s1[c] + p1[c];
      }
    }
    if (q < e) {
      const Real* p0 = p4 + 4 * size_t(adj[size_t(q)]);
      for (int c = 0; c < 3; ++c) s0[c] = s0[c] + p0[c];
    }
    const Real cnt = Real(e - b);
    Real* pm = p4 + 4 * size_t(m);
    const Real* t = d.target.data() + 4 * size_t(m);
    Real* lam = d.lambda.data() + 4 * size_t(m);
    const Real at = d.alphaTilde[size_t(m)], inv = d.invDenom[size_t(m)], wm = w[m];
    Real dl[3];
    for (int c = 0; c < 3; ++c) {
      const Real C = (pm[c] - (s0[c] + s1[c]) / cnt) - t[c];
      dl[c] = (-k * C - at * lam[c]) * inv;
      lam[c] = lam[c] + dl[c];
      pm[c] = pm[c] + wm * dl[c];
    }
    for (q = b; q < e; ++q) {
      Real* pi = p4 + 4 * size_t(adj[size_t(q)]);
      const Real cf = d.coef[size_t(q)];
      for (int c = 0; c < 3; ++c) pi[c] = pi[c] - cf * dl[c];
    }
  }
}

#ifdef DEFORM_METABALLS_HAVE_AVX512
// The same operations on rows (x, y, z, 0) with AVX2; lane 3 stays 0.
__attribute__((target("avx2"))) void laplacianAvx2(const std::vector<int>& adjStart,
                                                   const std::vector<int>& adj, const Real* w,
                                                   LaplacianStepData& d, Real* p4, Real k) {
  const __m256d mk = _mm256_set1_pd(-k);
  for (int m : d.order) {
    const Real W = d.W[size_t(m)];
    if (!(W > 0)) continue;
    const int b = adjStart[size_t(m)], e = adjStart[size_t(m) + 1];
    __m256d s0 = _mm256_setzero_pd(), s1 = _mm256_setzero_pd();
    int q = b;
    for (; q + 1 < e; q += 2) {
      s0 = _mm256_add_pd(s0, _mm256_loadu_pd(p4 + 4 * size_t(adj[size_t(q)])));
      s1 = _mm256_add_pd(s1, _mm256_loadu_pd(p4 + 4 * size_t(adj[size_t(q) + 1])));
    }
    if (q < e) s0 = _mm256_add_pd(s0, _mm256_loadu_pd(p4 + 4 * size_t(adj[size_t(q)])));
    const __m256d cnt = _mm256_set1_pd(Real(e - b));
    Real* pm = p4 + 4 * size_t(m);
    Real* lam = d.lambda.data() + 4 * size_t(m);
    const __m256d xm = _mm256_loadu_pd(pm), l = _mm256_loadu_pd(lam);
    const __m256d C = _mm256_sub_pd(_mm256_sub_pd(xm, _mm256_div_pd(_mm256_add_pd(s0, s1), cnt)),
                                    _mm256_loadu_pd(d.target.data() + 4 * size_t(m)));
    const __m256d dl =
        _mm256_mul_pd(_mm256_sub_pd(_mm256_mul_pd(mk, C),
                                    _mm256_mul_pd(_mm256_set1_pd(d.alphaTilde[size_t(m)]), l)),
                      _mm256_set1_pd(d.invDenom[size_t(m)]));
    // Lane 3 of dl: (-k * 0 - at * 0) * inv = 0 (keeps the padding lane at 0).
    _mm256_storeu_pd(lam, _mm256_add_pd(l, dl));
    _mm256_storeu_pd(pm, _mm256_add_pd(xm, _mm256_mul_pd(_mm256_set1_pd(w[m]), dl)));
    for (q = b; q < e; ++q) {
      Real* pi = p4 + 4 * size_t(adj[size_t(q)]);
      _mm256_storeu_pd(pi, _mm256_sub_pd(_mm256_loadu_pd(pi),
                                         _mm256_mul_pd(_mm256_set1_pd(d.coef[size_t(q)]), dl)));
    }
  }
}
bool cpuHasAvx2() {
  static const bool ok = __builtin_cpu_supports("avx2");
  return ok;
}
#endif

}  // namespace

void projectLaplacianSweep(const std::vector<int>& adjStart, const std::vector<int>& adj,
                           const Real* w, LaplacianStepData& d, Real* p4, Real k, bool simd) {
#ifdef DEFORM_METABALLS_HAVE_AVX512
  if (simd && cpuHasAvx2()) {
    laplacianAvx2(adjStart, adj, w, d, p4, k);
    return;
  }
#endif
  laplacianScalar(adjStart, adj, w, d, p4, k);
}

}  // namespace deform::metaballs
