#include "batched_projection.h"

#include <deform/kernels/isometric_bending.h>
#include <deform/kernels/pbd_kernels.h>
#include <deform/kernels/simd_lanes.h>

#include <algorithm>
#include <cmath>

#ifdef DEFORM_HYBRID_AVX2
#include "batched_projection_avx2.h"
#endif

namespace deform::hybrid_fem_pbd {

#ifndef DEFORM_HYBRID_AVX2
namespace batched {
// Without the AVX2 unit (not x86-64): the vector ranges take nothing, the scalar lanes do all.
template <class... Args>
std::size_t stretchRangeAvx2(Args&&...) {
  return 0;
}
template <class... Args>
std::size_t bendRangeAvx2(Args&&...) {
  return 0;
}
}  // namespace batched
#endif

namespace {

// One constraint at a time: the reference for the AVX2 lanes and the tail of each colour.
using ScalarLanes = simd::ScalarLanes<double>;
using ScalarLanesF = simd::ScalarLanes<float>;

bool avx2Supported() {
#ifdef DEFORM_HYBRID_AVX2
  return __builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma");
#else
  return false;
#endif
}

/// One sweep over the colours of a constraint list (colourStart: #colours + 1 offsets): each
/// colour by vector groups first, range(begin, end, &degenerate) returning how many constraints
/// it took (only with vec, and not in a last colour whose constraints share particles), the rest
/// one at a time by one(i), which returns its degenerate count. Returns the degenerate count.
template <class Range, class One>
long long colourSweep(const std::vector<int>& colourStart, bool lastColourShared, bool vec,
                      Range&& range, One&& one) {
  const size_t nc = colourStart.size() - 1;
  long long degenerate = 0;
  for (size_t col = 0; col < nc; ++col) {
    size_t i = static_cast<size_t>(colourStart[col]);
    const size_t end = static_cast<size_t>(colourStart[col + 1]);
    if (vec && !(lastColourShared && col + 1 == nc)) i += range(i, end, &degenerate);
    for (; i < end; ++i) degenerate += one(i);
  }
  return degenerate;
}

}  // namespace

batched::StretchView SurfaceBatches::stretchView() const {
  return {sbMovable.data(), sa.data(), sb.data(), sRest.data(), sScaleA.data(), sScaleB.data()};
}

batched::StretchViewF SurfaceBatches::stretchViewF() const {
  return {sbMovable.data(), sa.data(), sb.data(), fRest.data(), fScaleA.data(), fScaleB.data()};
}

batched::BendView SurfaceBatches::bendView() const {
  return {hMovable.data(),
          {hp[0].data(), hp[1].data(), hp[2].data(), hp[3].data()},
          {hw[0].data(), hw[1].data(), hw[2].data(), hw[3].data()},
          {hwd[0].data(), hwd[1].data(), hwd[2].data(), hwd[3].data()},
          hCos0.data(),
          hSin0.data(),
          kBending};
}

SurfaceBatches buildSurfaceBatches(const SurfaceConstraints& c, const ActiveConstraints& a,
                                   const VecX& w, Real kStretch, Real kBending, int iterations) {
  SurfaceBatches b;
  b.kStretch = pbd::classicStiffness(std::clamp<Real>(kStretch, 0, 1), iterations);
  b.kBending = pbd::classicStiffness(std::clamp<Real>(kBending, 0, 1), iterations);
  const size_t ns = a.stretch.size(), nb = a.bending.size();
  // Within a colour the order is free (its constraints share no movable particle), so each colour
  // is sorted by the pattern of movable slots: groups of four then share it and skip the work of
  // their immovable slots. A stretch constraint is oriented so that a is movable.
  // An overflowing last colour is projected in sequence and keeps its order.
  auto sortColours = [](std::vector<int> ids, const std::vector<int>& start, bool overflow,
                        auto pattern) {
    const size_t sorted = start.size() < 2 ? 0 : start.size() - 1 - (overflow ? 1 : 0);
    for (size_t colour = 0; colour < sorted; ++colour)
      std::stable_sort(ids.begin() + start[colour], ids.begin() + start[colour + 1],
                       [&](int x, int y) { return pattern(x) < pattern(y); });
    return ids;
  };
  const std::vector<int> sOrder = sortColours(
      a.stretch, a.stretchColourStart, a.stretchColourOverflow,
      [&](int i) { return (w[c.stretch[i].a] > 0) && (w[c.stretch[i].b] > 0) ? 1 : 0; });
  auto hPattern = [&](int i) {
    unsigned m = 0;
    for (int k = 0; k < 4; ++k)
      if (w[c.bending[i].p[k]] > 0) m |= 1u << k;
    return m;
  };
  const std::vector<int> hOrder =
      sortColours(a.bending, a.bendingColourStart, a.bendingColourOverflow, hPattern);
  b.sa.reserve(ns);
  b.sb.reserve(ns);
  b.sbMovable.reserve(ns);
  b.sRest.reserve(ns);
  b.sScaleA.reserve(ns);
  b.sScaleB.reserve(ns);
  for (int i : sOrder) {
    const pbd::DistanceConstraint& d = c.stretch[i];
    const bool swap = !(w[d.a] > 0);
    const int ia = swap ? d.b : d.a, ib = swap ? d.a : d.b;
    const Real wsum = w[ia] + w[ib];  // > 0: the constraint is active
    b.sa.push_back(ia);
    b.sb.push_back(ib);
    b.sbMovable.push_back(w[ib] > 0 ? 1 : 0);
    b.sRest.push_back(d.rest);
    b.sScaleA.push_back(b.kStretch * w[ia] / wsum);
    b.sScaleB.push_back(b.kStretch * w[ib] / wsum);
  }
  for (int k = 0; k < 4; ++k) {
    b.hp[k].reserve(nb);
    b.hw[k].reserve(nb);
    b.hwd[k].reserve(nb);
  }
  b.hMovable.reserve(nb);
  b.hCos0.reserve(nb);
  b.hSin0.reserve(nb);
  for (int i : hOrder) {
    const pbd::DihedralConstraint& h = c.bending[i];
    Real wi[4], wd[4];
    for (int k = 0; k < 4; ++k) wi[k] = w[h.p[k]];
    hingeDenominatorWeights(wi, wd);
    for (int k = 0; k < 4; ++k) {
      b.hp[k].push_back(h.p[k]);
      b.hw[k].push_back(wi[k]);
      b.hwd[k].push_back(wd[k]);
    }
    b.hMovable.push_back(static_cast<unsigned char>(hPattern(i)));
    b.hCos0.push_back(std::cos(h.restAngle));
    b.hSin0.push_back(std::sin(h.restAngle));
  }
  b.sColourStart = a.stretchColourStart;
  b.hColourStart = a.bendingColourStart;
  if (b.sColourStart.empty()) b.sColourStart = {0, static_cast<int>(ns)};
  if (b.hColourStart.empty()) b.hColourStart = {0, static_cast<int>(nb)};
  b.sLastColourShared = a.stretchColourOverflow;
  b.hLastColourShared = a.bendingColourOverflow;
  return b;
}

void addIsometricBending(SurfaceBatches& b, const MatX3& restV) {
  const size_t n = b.hCos0.size();
  b.isometric = true;
  for (int k = 0; k < 4; ++k) {
    b.isoP[k].resize(n);
    b.isoK[k].assign(n, 0.0);
    b.isoWK[k].assign(n, 0.0);
  }
  b.isoRest.assign(n, 0.0);
  b.isoAlphaTilde.assign(n, 0.0);
  b.isoScale.assign(n, 0.0);
  b.isoLambda.assign(n, 0.0);
  for (size_t i = 0; i < n; ++i) {
    pbd::IsometricHinge h;
    Vec3 x[4];
    for (int k = 0; k < 4; ++k) {
      b.isoP[k][i] = 4 * b.hp[k][i];
      x[k] = restV.row(b.hp[k][i]).transpose();
    }
    if (!pbd::isometricHinge(x, h)) continue;
    Real denom = 0;
    for (int k = 0; k < 4; ++k) {
      b.isoK[k][i] = h.K[k];
      b.isoWK[k][i] = b.hw[k][i] * h.K[k];
      denom += b.hwd[k][i] * h.K[k] * h.K[k];
    }
    b.isoRest[i] = h.rest;
    b.isoScale[i] = denom > 0 ? b.kBending / denom : 0.0;
  }
}

namespace {

long long projectIsometricPass(Real* x4, const SurfaceBatches& b, bool simd) {
  pbd::IsometricBatch<Real> v = pbd::isometricBatch(b.isoP, b.isoK, b.isoWK, b.isoRest,
                                                    b.isoAlphaTilde, b.isoScale, b.isoLambda);
  v.movable = b.hMovable.data();
  const size_t nhc = b.hColourStart.size() - 1;
  long long degenerate = 0;
  for (size_t col = 0; col < nhc; ++col) {
    const size_t begin = static_cast<size_t>(b.hColourStart[col]);
    const size_t end = static_cast<size_t>(b.hColourStart[col + 1]);
    if (b.hLastColourShared && col + 1 == nhc) {
      for (size_t i = begin; i < end; ++i)
        degenerate += pbd::projectIsometricColour(x4, v, i, i + 1, simd);
    } else {
      degenerate += pbd::projectIsometricColour(x4, v, begin, end, simd);
    }
  }
  return degenerate;
}

// One single-precision stretch sweep over every colour; measure != nullptr: the constraints'
// lengths (stretchGroup) instead, through the same lanes for the same simd flag.
long long stretchPassF(float* x4, const SurfaceBatches& b, bool simd, float* measure) {
  static const bool kAvx2 = avx2Supported();
  const bool vec = simd && kAvx2;
  const batched::StretchViewF sv = b.stretchViewF();
  return colourSweep(
      b.sColourStart, b.sLastColourShared, vec,
      [&](size_t i, size_t end, long long* degenerate) {
        return batched::stretchRangeAvx2(x4, sv, i, end, measure, degenerate);
      },
      [&](size_t i) { return batched::stretchGroup<ScalarLanesF>(x4, sv, i, measure); });
}

// One single-precision isometric bending sweep (the shared float kernel); measure != nullptr:
// the stencil lengths |v| instead.
long long isometricPassF(float* x4, const SurfaceBatches& b, bool simd, float* measure) {
  pbd::IsometricBatch<float> v = pbd::isometricBatch(b.isoP, b.fIsoK, b.fIsoWK, b.fIsoRest,
                                                     b.fIsoAlphaTilde, b.fIsoScale, b.fIsoLambda);
  v.movable = b.hMovable.data();
  const size_t nhc = b.hColourStart.size() - 1;
  long long degenerate = 0;
  auto range = [&](size_t begin, size_t end) {
    if (measure != nullptr) {
      pbd::isometricLengthsColour(x4, v, begin, end, measure, simd);
    } else {
      degenerate += pbd::projectIsometricColour(x4, v, begin, end, simd);
    }
  };
  for (size_t col = 0; col < nhc; ++col) {
    const size_t begin = static_cast<size_t>(b.hColourStart[col]);
    const size_t end = static_cast<size_t>(b.hColourStart[col + 1]);
    if (b.hLastColourShared && col + 1 == nhc) {
      for (size_t i = begin; i < end; ++i) range(i, i + 1);
    } else {
      range(begin, end);
    }
  }
  return degenerate;
}

}  // namespace

void addSinglePrecision(SurfaceBatches& b, const MatX3& restV, const Vec3& origin, bool simd) {
  b.singlePrecision = b.isometric;
  if (!b.isometric || b.sColourStart.empty() || b.hColourStart.empty()) return;
  b.origin = origin;
  const size_t ns = b.sa.size(), nh = b.hCos0.size();
  auto toFloat = [](const std::vector<Real>& d) { return std::vector<float>(d.begin(), d.end()); };
  b.fScaleA = toFloat(b.sScaleA);
  b.fScaleB = toFloat(b.sScaleB);
  for (int k = 0; k < 4; ++k) {
    b.fIsoK[k] = toFloat(b.isoK[k]);
    b.fIsoWK[k] = toFloat(b.isoWK[k]);
  }
  b.fIsoScale = toFloat(b.isoScale);
  b.fIsoAlphaTilde.assign(nh, 0.0f);
  b.fIsoLambda.assign(nh, 0.0f);
  std::vector<float> x4(4 * static_cast<size_t>(restV.rows()), 0.0f);
  for (Eigen::Index i = 0; i < restV.rows(); ++i)
    for (int a = 0; a < 3; ++a)
      x4[4 * static_cast<size_t>(i) + a] = static_cast<float>(restV(i, a) - origin[a]);
  // Rest lengths: measured on the rounded rest positions where they are the rest positions'
  // distances (always, up to the rounding of the positions; the law-of-cosines lengths after a
  // cut included), else the double value rounded.
  std::vector<float> len(ns, 0.0f);
  stretchPassF(x4.data(), b, simd, len.data());
  b.fRest.resize(ns);
  for (size_t i = 0; i < ns; ++i)
    b.fRest[i] = std::abs(double(len[i]) - b.sRest[i]) <= 1e-4 * b.sRest[i]
                     ? len[i]
                     : static_cast<float>(b.sRest[i]);
  b.fIsoRest.assign(nh, 0.0f);
  isometricPassF(x4.data(), b, simd, b.fIsoRest.data());
}

long long projectSurfaceBatchesF(float* x4, const SurfaceBatches& b, int iterations, bool simd) {
  if (!b.singlePrecision) return 0;
  long long degenerate = 0;
  for (int it = 0; it < iterations; ++it) {
    degenerate += stretchPassF(x4, b, simd, nullptr);
    if (b.kBending > 0) degenerate += isometricPassF(x4, b, simd, nullptr);
  }
  return degenerate;
}

long long projectSurfaceBatches(Real* x4, const SurfaceBatches& b, int iterations, bool simd) {
  if (b.sColourStart.empty() || b.hColourStart.empty()) return 0;  // never built: nothing active
  static const bool kAvx2 = avx2Supported();
  const bool vec = simd && kAvx2;
  const batched::StretchView sv = b.stretchView();
  const batched::BendView hv = b.bendView();
  long long degenerate = 0;
  for (int it = 0; it < iterations; ++it) {
    degenerate += colourSweep(
        b.sColourStart, b.sLastColourShared, vec,
        [&](size_t i, size_t end, long long* d) {
          return batched::stretchRangeAvx2(x4, sv, i, end, d);
        },
        [&](size_t i) { return batched::stretchGroup<ScalarLanes>(x4, sv, i); });
    if (b.kBending <= 0) continue;
    if (b.isometric) {
      degenerate += projectIsometricPass(x4, b, simd);
      continue;
    }
    degenerate += colourSweep(
        b.hColourStart, b.hLastColourShared, vec,
        [&](size_t i, size_t end, long long* d) {
          return batched::bendRangeAvx2(x4, hv, i, end, d);
        },
        [&](size_t i) { return batched::bendGroup<ScalarLanes>(x4, hv, i); });
  }
  return degenerate;
}

bool surfaceSimdAvailable() {
  return avx2Supported();
}

Real atan2Polynomial(Real y, Real x) {
  return batched::atan2Poly<ScalarLanes>(y, x);
}

}  // namespace deform::hybrid_fem_pbd
