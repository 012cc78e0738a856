// deformbench kernels: the clamped length of the batched constraint kernels (the core's isometric
// bending, the hybrid FEM+PBD model's stretch), written once over a "lanes" policy L
// (deform/kernels/simd_lanes.h) so that one hinge or constraint at a time and eight floats /
// four doubles at a time run the same operations. Like the kernels' math headers it is compiled
// with and without -mavx2: it includes nothing and everything here has internal linkage.
#pragma once

namespace deform::simd {

namespace {  // internal linkage on purpose (see the header comment)

constexpr double kTinyLength2 = 1e-24;  // tol::kDegenerateLength^2, m^2

/// |d| from len2 = |d|^2, clamped below at the degenerate length; ok marks the lanes that were
/// not clamped.
template <class L>
inline typename L::V clampedLength(typename L::V len2, typename L::M& ok) {
  const typename L::V tiny = L::set1(static_cast<typename L::T>(kTinyLength2));
  ok = L::gt(len2, tiny);
  return L::sqrt(L::max(len2, tiny));
}

/// The measuring mode of the kernels: with measure given, measure[i ..] = len where ok, else 0
/// (the lengths rest values are measured with), and true; without, false (project instead).
template <class L>
inline bool measureLength(typename L::T* measure, decltype(sizeof 0) i, typename L::M ok,
                          typename L::V len) {
  if (measure == nullptr) return false;
  L::store(measure + i, L::select(ok, len, L::set1(typename L::T(0))));
  return true;
}

}  // namespace

}  // namespace deform::simd
