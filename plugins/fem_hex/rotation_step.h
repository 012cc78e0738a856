// The arithmetic of one step of extractRotationInfo (hex_element.h), written once for a lane type
// T: double on the scalar path, a vector of doubles on the batch paths (rotation_batch.h). Every
// sum runs in the order written here with separate multiplies and adds (the units that include
// this header are compiled with -ffp-contract=off), so a lane of a batch gives the scalar
// path's bits. The lane operations lanesSqrt, lanesAbs and lanesSelect come by overload: the
// scalar ones below, the vector ones in each batch unit.
#pragma once

#include <cmath>

namespace deform::fem_hex::rotation {

inline double lanesSqrt(double x) {
  return std::sqrt(x);
}
inline double lanesAbs(double x) {
  return std::fabs(x);
}
inline double lanesSelect(bool m, double a, double b) {
  return m ? a : b;
}

/// Rotation matrix of the unit quaternion (w, x, y, z), column-major: r[row + 3 col].
template <class T>
inline void rotationMatrix(T w, T x, T y, T z, T* r) {
  const T tx = 2.0 * x, ty = 2.0 * y, tz = 2.0 * z;
  const T twx = tx * w, twy = ty * w, twz = tz * w;
  const T txx = tx * x, txy = ty * x, txz = tz * x;
  const T tyy = ty * y, tyz = tz * y, tzz = tz * z;
  r[0] = 1.0 - (tyy + tzz);
  r[1] = txy + twz;
  r[2] = txz - twy;
  r[3] = txy - twz;
  r[4] = 1.0 - (txx + tzz);
  r[5] = tyz + twx;
  r[6] = txz + twy;
  r[7] = tyz - twx;
  r[8] = 1.0 - (txx + tyy);
}

/// One step's outcome: the update omega (rad, about the world axes), its length w, whether it is
/// a Newton step, and (for a Newton step) tr(A) and det(H) for the stopping bound.
template <class T, class M>
struct RotationStep {
  T omega[3];
  T w;
  T trA;
  T det;
  M newton;
};

/// The step from q = (w, x, y, z) on tr(R^T F), F column-major (f[row + 3 col]): the Newton step
/// H^-1 g with g = sum_i r_i x f_i, H = tr(A) I - sym(A), A = F R^T where H is positive
/// definite, else Müller et al.'s g / |tr(A)|.
template <class T, class M>
inline RotationStep<T, M> rotationStep(const T* f, T qw, T qx, T qy, T qz) {
  T r[9];
  rotationMatrix(qw, qx, qy, qz, r);
  RotationStep<T, M> s;
  // g: the three cross products r_c x f_c, summed over the columns c.
  const T g0 =
      ((r[1] * f[2] - r[2] * f[1]) + (r[4] * f[5] - r[5] * f[4])) + (r[7] * f[8] - r[8] * f[7]);
  const T g1 =
      ((r[2] * f[0] - r[0] * f[2]) + (r[5] * f[3] - r[3] * f[5])) + (r[8] * f[6] - r[6] * f[8]);
  const T g2 =
      ((r[0] * f[1] - r[1] * f[0]) + (r[3] * f[4] - r[4] * f[3])) + (r[6] * f[7] - r[7] * f[6]);
  // A(i, j) = sum_k F(i, k) R(j, k).
  const auto a = [&](int i, int j) {
    return (f[i] * r[j] + f[i + 3] * r[j + 3]) + f[i + 6] * r[j + 6];
  };
  const T a00 = a(0, 0), a11 = a(1, 1), a22 = a(2, 2);
  const T trA = (a00 + a11) + a22;
  const T h00 = trA - a00, h11 = trA - a11, h22 = trA - a22;
  const T h01 = -0.5 * (a(0, 1) + a(1, 0));
  const T h02 = -0.5 * (a(0, 2) + a(2, 0));
  const T h12 = -0.5 * (a(1, 2) + a(2, 1));
  // The adjugate of the symmetric H: its columns are cross products of H's columns.
  const T c0x = h11 * h22 - h12 * h12, c0y = h12 * h02 - h01 * h22, c0z = h01 * h12 - h11 * h02;
  const T c1x = h12 * h02 - h22 * h01, c1y = h22 * h00 - h02 * h02, c1z = h02 * h01 - h12 * h00;
  const T c2x = h01 * h12 - h02 * h11, c2y = h02 * h01 - h00 * h12, c2z = h00 * h11 - h01 * h01;
  const T det = (h00 * c0x + h01 * c0y) + h02 * c0z;
  // Positive definite by Sylvester's criterion (leading minors).
  s.newton = (trA > 0.0) & (h00 > 0.0) & (h00 * h11 - h01 * h01 > 0.0) & (det > 0.0);
  const T scale = 1.0 / (lanesAbs(trA) + 1e-300);
  s.omega[0] = lanesSelect(s.newton, ((c0x * g0 + c1x * g1) + c2x * g2) / det, g0 * scale);
  s.omega[1] = lanesSelect(s.newton, ((c0y * g0 + c1y * g1) + c2y * g2) / det, g1 * scale);
  s.omega[2] = lanesSelect(s.newton, ((c0z * g0 + c1z * g1) + c2z * g2) / det, g2 * scale);
  s.w = lanesSqrt((s.omega[0] * s.omega[0] + s.omega[1] * s.omega[1]) + s.omega[2] * s.omega[2]);
  s.trA = trA;
  s.det = det;
  return s;
}

/// Whether the angle a Newton step of length w leaves, at most 4 tr(A)^3 / det(H) w^2, is within
/// the tolerance (then the step is the last).
template <class T>
inline auto isLastStep(T w, T trA, T det, double tolerance) {
  return ((((w * w) * 4.0) * trA) * trA) * trA <= tolerance * det;
}

/// q <- d q (Hamilton product), then q normalised; d = (dw, dx, dy, dz).
template <class T>
inline void rotateAndNormalise(T dw, T dx, T dy, T dz, T& qw, T& qx, T& qy, T& qz) {
  const T w = ((dw * qw - dx * qx) - dy * qy) - dz * qz;
  const T x = ((dw * qx + dx * qw) + dy * qz) - dz * qy;
  const T y = ((dw * qy + dy * qw) + dz * qx) - dx * qz;
  const T z = ((dw * qz + dz * qw) + dx * qy) - dy * qx;
  const T n2 = ((w * w + x * x) + y * y) + z * z;
  const auto positive = n2 > 0.0;
  const T n = lanesSqrt(n2);
  qw = lanesSelect(positive, w / n, w);
  qx = lanesSelect(positive, x / n, x);
  qy = lanesSelect(positive, y / n, y);
  qz = lanesSelect(positive, z / n, z);
}

}  // namespace deform::fem_hex::rotation
