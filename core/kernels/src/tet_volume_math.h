// Internal: the arithmetic of the batched tet volume projection (deform/kernels/
// tet_volume_batch.h), written once over a "lanes" policy L so that the same operations, in the
// same order, run one tet at a time (tet_volume.cpp) and eight floats / four doubles at a time
// (tet_volume_avx2.cpp, compiled with -mavx2). Both files are compiled with -ffp-contract=off, so
// that no multiply-add is fused on one path and not on the other. Plain pointers and builtin
// types only, and internal linkage throughout (the rules of isometric_bending_math.h).
#pragma once

#include <deform/kernels/tet_volume_batch.h>

#include <cstddef>

namespace deform::pbd::tetbatch {

template <class T>
using View = TetVolumeBatch<T>;

namespace {  // internal linkage on purpose (see the header comment)

/// What the projection of tets i .. i + L::kWidth - 1 adds to their rows: dx_k = (w_k dl) g_k.
template <class L>
struct TetUpdate {
  typename L::V gx[4], gy[4], gz[4], dl;
  int degenerate;
};

/// The loads and arithmetic of tets i .. i + L::kWidth - 1: measure == nullptr: the multiplier
/// update (stored) and u, true; otherwise store V(x) to measure[i..], false.
template <class L>
inline bool tetCompute(const typename L::T* x4, const View<typename L::T>& b, std::size_t i,
                       typename L::T* measure, TetUpdate<L>& u) {
  using V = typename L::V;
  using T = typename L::T;
  V x[4], y[4], z[4];
  for (int k = 0; k < 4; ++k) L::loadRows(x4, b.p[k] + i, x[k], y[k], z[k]);
  const V e1x = x[1] - x[0], e1y = y[1] - y[0], e1z = z[1] - z[0];
  const V e2x = x[2] - x[0], e2y = y[2] - y[0], e2z = z[2] - z[0];
  const V e3x = x[3] - x[0], e3y = y[3] - y[0], e3z = z[3] - z[0];
  const V six = L::set1(T(6));
  // g1 = e2 x e3 / 6, g2 = e3 x e1 / 6, g3 = e1 x e2 / 6 (Eigen's cross product, then / 6).
  u.gx[1] = (e2y * e3z - e2z * e3y) / six;
  u.gy[1] = (e2z * e3x - e2x * e3z) / six;
  u.gz[1] = (e2x * e3y - e2y * e3x) / six;
  u.gx[2] = (e3y * e1z - e3z * e1y) / six;
  u.gy[2] = (e3z * e1x - e3x * e1z) / six;
  u.gz[2] = (e3x * e1y - e3y * e1x) / six;
  u.gx[3] = (e1y * e2z - e1z * e2y) / six;
  u.gy[3] = (e1z * e2x - e1x * e2z) / six;
  u.gz[3] = (e1x * e2y - e1y * e2x) / six;
  u.gx[0] = -((u.gx[1] + u.gx[2]) + u.gx[3]);
  u.gy[0] = -((u.gy[1] + u.gy[2]) + u.gy[3]);
  u.gz[0] = -((u.gz[1] + u.gz[2]) + u.gz[3]);
  const V vol = (e1x * u.gx[1] + e1y * u.gy[1]) + e1z * u.gz[1];
  if (measure != nullptr) {
    L::store(measure + i, vol);
    return false;
  }
  const V zero = L::set1(T(0));
  V gsum = zero, denom = zero;
  for (int k = 0; k < 4; ++k) {
    const V g2 = (u.gx[k] * u.gx[k] + u.gy[k] * u.gy[k]) + u.gz[k] * u.gz[k];
    gsum = gsum + g2;
    denom = denom + L::load(b.w[k] + i) * g2;
  }
  const V at = L::load(b.alphaTilde + i);
  const V den = denom + at;
  const typename L::M ok = L::band(L::gt(den, zero), L::gt(gsum, L::load(b.floor + i)));
  V lambda = L::load(b.lambda + i);
  const V C = vol - L::load(b.rest + i);
  u.dl = L::select(ok, (L::set1(b.k) * ((-C) - at * lambda)) / den, zero);
  lambda = L::select(ok, lambda + u.dl, lambda);
  L::store(b.lambda + i, lambda);
  u.degenerate = L::count(L::notMask(ok));
  return true;
}

/// The stores of tets i .. i + L::kWidth - 1.
template <class L>
inline void tetCommit(typename L::T* x4, const View<typename L::T>& b, std::size_t i,
                      const TetUpdate<L>& u) {
  for (int k = 0; k < 4; ++k) {
    const typename L::V c = L::load(b.w[k] + i) * u.dl;
    L::addRows(x4, b.p[k] + i, c * u.gx[k], c * u.gy[k], c * u.gz[k]);
  }
}

/// Tets i .. i + L::kWidth - 1. measure == nullptr: project them, return the number of
/// degenerate ones; otherwise store V(x) to measure[i..] and change nothing.
template <class L>
inline int tetGroup(typename L::T* x4, const View<typename L::T>& b, std::size_t i,
                    typename L::T* measure) {
  TetUpdate<L> u;
  if (!tetCompute<L>(x4, b, i, measure, u)) return 0;
  tetCommit<L>(x4, b, i, u);
  return u.degenerate;
}

}  // namespace

}  // namespace deform::pbd::tetbatch
