// Hybrid FEM+PBD: the arithmetic of the colour-batched surface projection, written once over a
// "lanes" policy L so that the same code runs one constraint at a time (L::V = double or float)
// and four doubles or eight floats at a time (L::V = __m256d or __m256, AVX2,
// batched_projection_avx2.cpp; the single-precision form is the stretch pass of the default
// `precision = float32`). Plain pointers and builtin
// types only: this header is compiled both with and without -mavx2, so it includes no library
// header whose inline functions could be merged across the two instruction sets, and everything
// here has internal linkage.
//
// Stretch (paper Eqs. (8)-(9), Mueller et al. 2007 Sec. 4.2), classic PBD with per-iteration
// stiffness k:  d = x_a - x_b,  s = (l - |d|) / |d|,  x_a += k w_a/(w_a+w_b) s d,
//               x_b -= k w_b/(w_a+w_b) s d   (the two scales precomputed per constraint).
// Bending (paper Eqs. (10)-(11)), C = theta - theta0 wrapped to (-pi, pi] with the gradients of
// Bridson et al. 2003 (see deform/kernels/pbd_kernels.h, DihedralConstraint): dx_i = -k C w_i g_i /
// sum_j w_j |g_j|^2. The wrapped difference is evaluated directly as
//   C = atan2(s cos theta0 - c sin theta0, c cos theta0 + s sin theta0),
//   s = ((nB x nA) . e),  c = |e| (nA . nB)      (atan2 is scale invariant, so the common factor
// 1 / (|nA| |nB| |e|) of sin theta and cos theta is never formed), with cos theta0, sin theta0
// stored per hinge and atan2 evaluated by atan2Poly() below (|error| < 1e-15 rad, tested against
// std::atan2).
#pragma once

#include <deform/kernels/lane_length.h>

#include <cstddef>

namespace deform::hybrid_fem_pbd::batched {

/// Structure-of-arrays views of one constraint list (built by SurfaceBatches). Positions are a
/// padded #V by 4 array (x, y, z, 0) so that a point is one aligned-size load.
/// T = double, or float for the single-precision projection (positions then relative to the
/// organ's centre, see SurfaceBatches).
template <class T>
struct StretchViewT {
  const unsigned char* bMovable;  ///< 1 when w_b > 0 (a is always movable: SurfaceBatches orients)
  const int* a;
  const int* b;
  const T* rest;  ///< l, m
  const T* sa;    ///< k w_a / (w_a + w_b)
  const T* sb;    ///< k w_b / (w_a + w_b)
};
using StretchView = StretchViewT<double>;
using StretchViewF = StretchViewT<float>;
struct BendView {
  const unsigned char* movable;  ///< bit k set when w[k] > 0
  const int* p[4];      ///< x0, x1 wings; x2, x3 the shared edge (DihedralConstraint order)
  const double* w[4];   ///< inverse masses, 1/kg
  const double* wd[4];  ///< the inverse masses the update divides by (hingeDenominatorWeights)
  const double* cos0;   ///< cos theta0
  const double* sin0;   ///< sin theta0
  double k;             ///< per-iteration bending stiffness
};

namespace {  // internal linkage on purpose (see the header comment)

using simd::kTinyLength2;
constexpr double kTinyArea2 = 1e-48;  // (tol::kDegenerateLength^2)^2, m^4
constexpr double kPi = 3.141592653589793238462643383279502884;

// atan on [0, 1] by reduction to four intervals of width pi/16 around c_j = tan((2j+1) pi/32):
// atan(t) = atan(c_j) + atan(z), z = (t - c_j) / (1 + t c_j), |z| <= tan(pi/32) < 0.0985, and an
// odd Taylor polynomial of degree 15 (truncation < 0.0985^17 / 17 < 1e-18). t = a / b is never
// formed: z = (a - c_j b) / (b + c_j a), one division.
template <class L>
inline typename L::V atanRatio(typename L::V a, typename L::V b) {
  using V = typename L::V;
  // c_j = tan((2j+1) pi / 32), atan(c_j) = (2j+1) pi / 32; thresholds tan(j pi / 16).
  const V c0 = L::set1(0.098491403357164253), c1 = L::set1(0.30334668360734239),
          c2 = L::set1(0.53451113595079153), c3 = L::set1(0.82067879082866024);
  const V t1 = L::set1(0.19891236737965800), t2 = L::set1(0.41421356237309505),
          t3 = L::set1(0.66817863791929892);
  const auto m1 = L::gt(a, t1 * b), m2 = L::gt(a, t2 * b), m3 = L::gt(a, t3 * b);
  V c = L::select(m1, c1, c0);
  c = L::select(m2, c2, c);
  c = L::select(m3, c3, c);
  V base = L::select(m1, L::set1(3 * kPi / 32), L::set1(kPi / 32));
  base = L::select(m2, L::set1(5 * kPi / 32), base);
  base = L::select(m3, L::set1(7 * kPi / 32), base);
  const V z = (a - c * b) / (b + c * a);
  const V u = z * z;
  V p = L::set1(-1.0 / 15);
  p = p * u + L::set1(1.0 / 13);
  p = p * u + L::set1(-1.0 / 11);
  p = p * u + L::set1(1.0 / 9);
  p = p * u + L::set1(-1.0 / 7);
  p = p * u + L::set1(1.0 / 5);
  p = p * u + L::set1(-1.0 / 3);
  return base + (z + z * u * p);
}

/// atan2(y, x) in [-pi, pi]; exact (0, +-pi/2, +-pi) on the axes, 0 when x = y = 0.
template <class L>
inline typename L::V atan2Poly(typename L::V y, typename L::V x) {
  using V = typename L::V;
  const V ax = L::abs(x), ay = L::abs(y);
  const V a = L::min(ax, ay), b = L::max(L::max(ax, ay), L::set1(1e-300));
  V r = L::select(L::gt(a, L::set1(0.0)), atanRatio<L>(a, b), L::set1(0.0));  // exact on axes
  r = L::select(L::gt(ay, ax), L::set1(kPi / 2) - r, r);
  r = L::select(L::lt(x, L::set1(0.0)), L::set1(kPi) - r, r);
  return L::select(L::lt(y, L::set1(0.0)), -r, r);
}

/// Projects L::kWidth stretch constraints starting at i (independent in their movable
/// particles), in L::T (double or float) arithmetic. Returns the number of degenerate
/// (zero-length) ones, which are left unchanged. measure != nullptr: store |x_a - x_b| (0 where
/// degenerate) to measure[i..] instead and change nothing (rest lengths measured with the
/// projection's own arithmetic give C = 0 bit for bit at rest).
template <class L>
inline int stretchGroup(typename L::T* x4, const StretchViewT<typename L::T>& s, std::size_t i,
                        typename L::T* measure = nullptr) {
  using V = typename L::V;
  using T = typename L::T;
  V ax, ay, az, bx, by, bz;
  L::loadPoints(x4, s.a + i, ax, ay, az);
  L::loadPoints(x4, s.b + i, bx, by, bz);
  const V dx = ax - bx, dy = ay - by, dz = az - bz;
  const V len2 = dx * dx + dy * dy + dz * dz;
  typename L::M ok;
  const V len = simd::clampedLength<L>(len2, ok);
  if (simd::measureLength<L>(measure, i, ok, len)) return 0;
  const V f = L::select(ok, (L::load(s.rest + i) - len) / len, L::set1(T(0)));
  const V fa = L::load(s.sa + i) * f, fb = L::load(s.sb + i) * f;
  L::addPoints(x4, s.a + i, fa * dx, fa * dy, fa * dz);
  if (L::anyByte(s.bMovable + i)) L::addPoints(x4, s.b + i, -(fb * dx), -(fb * dy), -(fb * dz));
  return L::kWidth - L::count(ok);
}

/// Projects L::kWidth dihedral constraints starting at i. Returns the number of degenerate ones.
/// Every slot's gradient enters the denominator (with the weights wd); the update of a particle
/// slot is skipped when the slot is immovable in every lane (w = 0 there, so it would add
/// nothing): SurfaceBatches sorts each colour by its movable-slot pattern so that the groups of
/// four share it.
template <class L>
inline int bendGroup(double* x4, const BendView& h, std::size_t i) {
  using V = typename L::V;
  const unsigned mask = L::orBytes(h.movable + i);
  V x[4], y[4], z[4], w[4], wd[4];
  for (int k = 0; k < 4; ++k) {
    L::loadPoints(x4, h.p[k] + i, x[k], y[k], z[k]);
    w[k] = L::load(h.w[k] + i);
    wd[k] = L::load(h.wd[k] + i);
  }
  const V ex = x[3] - x[2], ey = y[3] - y[2], ez = z[3] - z[2];
  const V elen2 = ex * ex + ey * ey + ez * ez;
  // nA = (x2 - x0) x (x3 - x0), nB = (x3 - x1) x (x2 - x1)
  const V p20x = x[2] - x[0], p20y = y[2] - y[0], p20z = z[2] - z[0];
  const V p30x = x[3] - x[0], p30y = y[3] - y[0], p30z = z[3] - z[0];
  const V p31x = x[3] - x[1], p31y = y[3] - y[1], p31z = z[3] - z[1];
  const V p21x = x[2] - x[1], p21y = y[2] - y[1], p21z = z[2] - z[1];
  const V nAx = p20y * p30z - p20z * p30y, nAy = p20z * p30x - p20x * p30z,
          nAz = p20x * p30y - p20y * p30x;
  const V nBx = p31y * p21z - p31z * p21y, nBy = p31z * p21x - p31x * p21z,
          nBz = p31x * p21y - p31y * p21x;
  const V a2 = nAx * nAx + nAy * nAy + nAz * nAz, b2 = nBx * nBx + nBy * nBy + nBz * nBz;
  auto ok = L::band(L::gt(elen2, L::set1(kTinyLength2)),
                    L::band(L::gt(a2, L::set1(kTinyArea2)), L::gt(b2, L::set1(kTinyArea2))));
  const V elen2s = L::max(elen2, L::set1(kTinyLength2));
  const V a2s = L::max(a2, L::set1(kTinyArea2)), b2s = L::max(b2, L::set1(kTinyArea2));
  const V elen = L::sqrt(elen2s);
  // One division for 1/|nA|^2, 1/|nB|^2 and 1/|e|.
  const V r = L::set1(1.0) / (a2s * b2s * elen);
  const V invA = b2s * elen * r, invB = a2s * elen * r, invE = a2s * b2s * r;
  const V uAx = nAx * invA, uAy = nAy * invA, uAz = nAz * invA;
  const V uBx = nBx * invB, uBy = nBy * invB, uBz = nBz * invB;
  V gx[4], gy[4], gz[4];
  gx[0] = elen * uAx, gy[0] = elen * uAy, gz[0] = elen * uAz;
  gx[1] = elen * uBx, gy[1] = elen * uBy, gz[1] = elen * uBz;
  {
    const V d03 = ((x[0] - x[3]) * ex + (y[0] - y[3]) * ey + (z[0] - z[3]) * ez) * invE;
    const V d13 = ((x[1] - x[3]) * ex + (y[1] - y[3]) * ey + (z[1] - z[3]) * ez) * invE;
    gx[2] = d03 * uAx + d13 * uBx, gy[2] = d03 * uAy + d13 * uBy, gz[2] = d03 * uAz + d13 * uBz;
    const V d02 = -(p20x * ex + p20y * ey + p20z * ez) * invE;  // (x0 - x2).e / |e|
    const V d12 = -(p21x * ex + p21y * ey + p21z * ez) * invE;  // (x1 - x2).e / |e|
    gx[3] = -(d02 * uAx + d12 * uBx), gy[3] = -(d02 * uAy + d12 * uBy),
    gz[3] = -(d02 * uAz + d12 * uBz);
  }
  V denom = L::set1(0.0);
  for (int k = 0; k < 4; ++k)
    denom = denom + wd[k] * (gx[k] * gx[k] + gy[k] * gy[k] + gz[k] * gz[k]);
  ok = L::band(ok, L::gt(denom, L::set1(0.0)));
  // s = (nB x nA) . e, c = |e| nA . nB
  const V s =
      (nBy * nAz - nBz * nAy) * ex + (nBz * nAx - nBx * nAz) * ey + (nBx * nAy - nBy * nAx) * ez;
  const V c = elen * (nAx * nBx + nAy * nBy + nAz * nBz);
  const V cos0 = L::load(h.cos0 + i), sin0 = L::load(h.sin0 + i);
  const V C = atan2Poly<L>(s * cos0 - c * sin0, c * cos0 + s * sin0);
  const V dl = L::select(ok, (L::set1(-h.k) * C) / L::max(denom, L::set1(1e-300)), L::set1(0.0));
  for (int k = 0; k < 4; ++k) {
    if (!(mask & (1u << k))) continue;
    const V f = w[k] * dl;  // exactly 0 for immovable particles: adding it changes nothing
    L::addPoints(x4, h.p[k] + i, f * gx[k], f * gy[k], f * gz[k]);
  }
  return L::kWidth - L::count(ok);
}

}  // namespace

}  // namespace deform::hybrid_fem_pbd::batched
