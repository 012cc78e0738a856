// The body of the batch paths of rotation_batch.h for lanes L of deform/kernels/simd_lanes.h
// (four or eight doubles). Included by the vector units, each with its own lanes.
#pragma once

#include "rotation_step.h"

namespace deform::fem_hex::rotation {

template <class L>
inline void stepsOnLanes(const double* F, double* q, double* R, signed char* outcome,
                         double tolerance, int maxSteps) {
  using V = typename L::V;
  using M = typename L::M;
  constexpr int kL = L::kWidth;
  V f[9];
  for (int k = 0; k < 9; ++k) f[k] = L::load(F + k * kL);
  const V qw0 = L::load(q), qx0 = L::load(q + kL), qy0 = L::load(q + 2 * kL),
          qz0 = L::load(q + 3 * kL);
  V qw = qw0, qx = qx0, qy = qy0, qz = qz0;
  const V zero = L::set1(0.0), one = L::set1(1.0), half = L::set1(0.5), tol = L::set1(tolerance);
  // The lanes still iterating, the steps taken, and each lane's outcome (0: not finished).
  M active = L::le(zero, one);  // every lane
  V steps = zero, done = zero;
  for (int it = 0; it < maxSteps; ++it) {
    const RotationStep<L> s = rotationStep<L>(f, qw, qx, qy, qz);
    // As extractRotationInfo: finished where |omega| <= tolerance (NaN compares false: left to
    // the scalar path), or after a Newton step that is the last by its bound. A step of 1e-3 rad
    // or more (the axis-angle update) is left to the scalar path.
    const M none = L::band(active, L::le(s.w, tol));
    const M small = L::band(active, L::band(L::gt(s.w, tol), L::lt(s.w, L::set1(1e-3))));
    const M last = L::band(small, L::band(s.newton, isLastStep<L>(s.w, s.trA, s.det, tolerance)));
    done = L::select(none, steps + one, done);
    V nw = qw, nx = qx, ny = qy, nz = qz;
    rotateAndNormalise<L>(one, half * s.omega[0], half * s.omega[1], half * s.omega[2], nw, nx, ny,
                          nz);
    qw = L::select(small, nw, qw);
    qx = L::select(small, nx, qx);
    qy = L::select(small, ny, qy);
    qz = L::select(small, nz, qz);
    steps = L::select(small, steps + one, steps);
    done = L::select(last, steps + one, done);
    active = L::band(small, L::notMask(last));
    if (L::count(active) == 0) break;
  }
  // Unfinished lanes keep their start.
  const M finished = L::gt(done, zero);
  qw = L::select(finished, qw, qw0);
  qx = L::select(finished, qx, qx0);
  qy = L::select(finished, qy, qy0);
  qz = L::select(finished, qz, qz0);
  L::store(q, qw);
  L::store(q + kL, qx);
  L::store(q + 2 * kL, qy);
  L::store(q + 3 * kL, qz);
  V r[9];
  rotationMatrix<L>(qw, qx, qy, qz, r);
  for (int k = 0; k < 9; ++k) L::store(R + k * kL, r[k]);
  double d[kL];
  L::store(d, done);
  for (int l = 0; l < kL; ++l) outcome[l] = static_cast<signed char>(d[l]);
}

}  // namespace deform::fem_hex::rotation
