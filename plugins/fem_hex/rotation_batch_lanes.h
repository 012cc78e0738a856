// The body of the batch paths of rotation_batch.h for one GCC vector type V of L doubles.
// Included by the vector units after they declare lanesSqrt for V: rotation_step.h names the
// lane operations unqualified, so every overload must be declared before it.
#pragma once

#include <cstring>

namespace deform::fem_hex::rotation {

/// |x| on vector lanes (the sign bit cleared).
template <class V>
inline V lanesAbs(V x) {
  using Mask = decltype(x > 0.0);
  return (V)((Mask)x & (Mask{} + 0x7fffffffffffffffLL));
}

/// Lane by lane m ? a : b, m the result of a comparison (all bits set or none).
template <class Mask, class V>
inline V lanesSelect(Mask m, V a, V b) {
  return (V)(((Mask)a & m) | ((Mask)b & ~m));
}

}  // namespace deform::fem_hex::rotation

#include "rotation_step.h"

namespace deform::fem_hex::rotation {

template <class V, int L>
inline void stepsOnLanes(const double* F, double* q, double* R, signed char* outcome,
                         double tolerance, int maxSteps) {
  static_assert(sizeof(V) == L * sizeof(double));
  using Mask = decltype(V{} > 0.0);
  const auto load = [](const double* p) {
    V v;
    std::memcpy(&v, p, sizeof v);
    return v;
  };
  const auto store = [](double* p, V v) { std::memcpy(p, &v, sizeof v); };
  V f[9];
  for (int k = 0; k < 9; ++k) f[k] = load(F + k * L);
  const V qw0 = load(q), qx0 = load(q + L), qy0 = load(q + 2 * L), qz0 = load(q + 3 * L);
  V qw = qw0, qx = qx0, qy = qy0, qz = qz0;
  // The lanes still iterating, and each lane's outcome so far (0: not finished).
  Mask active = qw == qw;  // every lane
  V steps = V{};
  V done = V{};  // 1 + the steps taken, where finished
  for (int it = 0; it < maxSteps; ++it) {
    const RotationStep<V, Mask> s = rotationStep<V, Mask>(f, qw, qx, qy, qz);
    // As extractRotationInfo: finished where |omega| <= tolerance (NaN compares false: left to
    // the scalar path), or after a Newton step that is the last by its bound. A step of 1e-3 rad
    // or more (the axis-angle update) is left to the scalar path.
    const Mask none = active & (s.w <= tolerance);
    const Mask small = active & (s.w > tolerance) & (s.w < 1e-3);
    const Mask last = small & s.newton & isLastStep(s.w, s.trA, s.det, tolerance);
    done = lanesSelect(none, steps + 1.0, done);
    V nw = qw, nx = qx, ny = qy, nz = qz;
    rotateAndNormalise(V{} + 1.0, 0.5 * s.omega[0], 0.5 * s.omega[1], 0.5 * s.omega[2], nw, nx, ny,
                       nz);
    qw = lanesSelect(small, nw, qw);
    qx = lanesSelect(small, nx, qx);
    qy = lanesSelect(small, ny, qy);
    qz = lanesSelect(small, nz, qz);
    steps = lanesSelect(small, steps + 1.0, steps);
    done = lanesSelect(last, steps + 1.0, done);
    active = small & ~last;
    bool any = false;
    for (int l = 0; l < L; ++l) any = any || active[l] != 0;
    if (!any) break;
  }
  // Unfinished lanes keep their start.
  const Mask finished = done > 0.0;
  qw = lanesSelect(finished, qw, qw0);
  qx = lanesSelect(finished, qx, qx0);
  qy = lanesSelect(finished, qy, qy0);
  qz = lanesSelect(finished, qz, qz0);
  store(q, qw);
  store(q + L, qx);
  store(q + 2 * L, qy);
  store(q + 3 * L, qz);
  V r[9];
  rotationMatrix(qw, qx, qy, qz, r);
  for (int k = 0; k < 9; ++k) store(R + k * L, r[k]);
  for (int l = 0; l < L; ++l) outcome[l] = static_cast<signed char>(done[l]);
}

}  // namespace deform::fem_hex::rotation
