// Internal: the arithmetic of the batched isometric bending projection
// (deform/kernels/isometric_bending.h), written once over a "lanes" policy L so that the same
// operations, in the same order, run one hinge at a time (isometric_bending.cpp) and eight floats /
// four doubles at a time (isometric_bending_avx2.cpp, compiled with -mavx2). Both files are
// compiled with -ffp-contract=off, so that no multiply-add is fused on one path and not on the
// other: the two give identical results. Plain pointers and builtin types only (this header is
// compiled with and without -mavx2, so it includes no library header with inline functions) and
// internal linkage throughout.
#pragma once

#include <deform/kernels/isometric_batch.h>
#include <deform/kernels/lane_length.h>

#include <cstddef>

namespace deform::pbd::isobatch {

/// The batch the kernels read (deform/kernels/isometric_batch.h, which includes nothing).
template <class T>
using View = IsometricBatch<T>;

namespace {  // internal linkage on purpose (see the header comment)

using simd::kTinyLength2;

/// What the projection of hinges i .. i + L::kWidth - 1 adds to their rows: dx_k = w_k s K_k v
/// for the slots k that move in some lane.
template <class L>
struct HingeUpdate {
  typename L::V vx, vy, vz, s;
  unsigned slots;
  int degenerate;
};

/// The loads and arithmetic of hinges i .. i + L::kWidth - 1: measure == nullptr: the multiplier
/// update (stored) and u, true; otherwise store |v| (0 where degenerate) to measure[i..], false.
template <class L>
inline bool hingeCompute(const typename L::T* x4, const View<typename L::T>& b, std::size_t i,
                         typename L::T* measure, HingeUpdate<L>& u) {
  using V = typename L::V;
  using T = typename L::T;
  V x[4], y[4], z[4];
  for (int k = 0; k < 4; ++k) L::loadRows(x4, b.p[k] + i, x[k], y[k], z[k]);
  const V K0 = L::load(b.K[0] + i), K1 = L::load(b.K[1] + i), K2 = L::load(b.K[2] + i),
          K3 = L::load(b.K[3] + i);
  u.vx = K0 * x[0] + K1 * x[1] + K2 * x[2] + K3 * x[3];
  u.vy = K0 * y[0] + K1 * y[1] + K2 * y[2] + K3 * y[3];
  u.vz = K0 * z[0] + K1 * z[1] + K2 * z[2] + K3 * z[3];
  const V l2 = u.vx * u.vx + u.vy * u.vy + u.vz * u.vz;
  typename L::M ok;
  const V len = simd::clampedLength<L>(l2, ok);
  if (simd::measureLength<L>(measure, i, ok, len)) return false;
  const V rest = L::load(b.rest + i);
  V lambda = L::load(b.lambda + i);
  const V C = len - rest;
  const V dl = L::select(ok, L::load(b.scale + i) * ((-C) - L::load(b.alphaTilde + i) * lambda),
                         L::set1(T(0)));
  lambda = lambda + dl;
  L::store(b.lambda + i, lambda);
  // A slot immovable in every lane adds exactly 0 and is skipped.
  u.slots = 0xFu;
  if (b.movable != nullptr) {
    u.slots = 0;
    for (int l = 0; l < L::kWidth; ++l) u.slots |= b.movable[i + l];
  }
  u.s = dl / len;
  // Degenerate: |v| = 0 where the rest value asks for a bend (a flat hinge at rest is fine).
  u.degenerate = L::count(L::band(L::notMask(ok), L::ne(rest, L::set1(T(0)))));
  return true;
}

/// The stores of hinges i .. i + L::kWidth - 1: dx_k = w_k dl g_k, g_k = K_k v / |v|.
template <class L>
inline void hingeCommit(typename L::T* x4, const View<typename L::T>& b, std::size_t i,
                        const HingeUpdate<L>& u) {
  for (int k = 0; k < 4; ++k) {
    if (!(u.slots & (1u << k))) continue;
    const typename L::V c = L::load(b.wK[k] + i) * u.s;
    L::addRows(x4, b.p[k] + i, c * u.vx, c * u.vy, c * u.vz);
  }
}

/// Hinges i .. i + L::kWidth - 1. measure == nullptr: project them, return the number of
/// degenerate ones; otherwise store |v| (0 where degenerate) to measure[i..] and change nothing.
template <class L>
inline int hingeGroup(typename L::T* x4, const View<typename L::T>& b, std::size_t i,
                      typename L::T* measure) {
  HingeUpdate<L> u;
  if (!hingeCompute<L>(x4, b, i, measure, u)) return 0;
  hingeCommit<L>(x4, b, i, u);
  return u.degenerate;
}

}  // namespace

}  // namespace deform::pbd::isobatch
