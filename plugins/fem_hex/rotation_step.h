// The arithmetic of one step of extractRotationInfo (hex_element.h), written once over the lanes
// of deform/kernels/simd_lanes.h: simd::ScalarLanes<double> on the scalar path, four or eight
// doubles on the batch paths (rotation_batch.h). Every sum runs in the order written here with
// separate multiplies and adds (the units that include this header are compiled with
// -ffp-contract=off), so a lane of a batch gives the scalar path's bits.
#pragma once

#include <deform/kernels/simd_lanes.h>

namespace deform::fem_hex::rotation {

/// Rotation matrix of the unit quaternion (w, x, y, z), column-major: r[row + 3 col].
template <class L>
inline void rotationMatrix(typename L::V w, typename L::V x, typename L::V y, typename L::V z,
                           typename L::V* r) {
  using V = typename L::V;
  const V one = L::set1(1.0), two = L::set1(2.0);
  const V tx = two * x, ty = two * y, tz = two * z;
  const V twx = tx * w, twy = ty * w, twz = tz * w;
  const V txx = tx * x, txy = ty * x, txz = tz * x;
  const V tyy = ty * y, tyz = tz * y, tzz = tz * z;
  r[0] = one - (tyy + tzz);
  r[1] = txy + twz;
  r[2] = txz - twy;
  r[3] = txy - twz;
  r[4] = one - (txx + tzz);
  r[5] = tyz + twx;
  r[6] = txz + twy;
  r[7] = tyz - twx;
  r[8] = one - (txx + tyy);
}

/// One step's outcome: the update omega (rad, about the world axes), its length w, whether it is
/// a Newton step, and (for a Newton step) tr(A) and det(H) for the stopping bound.
template <class L>
struct RotationStep {
  typename L::V omega[3];
  typename L::V w;
  typename L::V trA;
  typename L::V det;
  typename L::M newton;
};

/// The step from q = (w, x, y, z) on tr(R^T F), F column-major (f[row + 3 col]): the Newton step
/// H^-1 g with g = sum_i r_i x f_i, H = tr(A) I - sym(A), A = F R^T where H is positive
/// definite, else Müller et al.'s g / |tr(A)|.
template <class L>
inline RotationStep<L> rotationStep(const typename L::V* f, typename L::V qw, typename L::V qx,
                                    typename L::V qy, typename L::V qz) {
  using V = typename L::V;
  V r[9];
  rotationMatrix<L>(qw, qx, qy, qz, r);
  RotationStep<L> s;
  // g: the three cross products r_c x f_c, summed over the columns c.
  const V g0 =
      ((r[1] * f[2] - r[2] * f[1]) + (r[4] * f[5] - r[5] * f[4])) + (r[7] * f[8] - r[8] * f[7]);
  const V g1 =
      ((r[2] * f[0] - r[0] * f[2]) + (r[5] * f[3] - r[3] * f[5])) + (r[8] * f[6] - r[6] * f[8]);
  const V g2 =
      ((r[0] * f[1] - r[1] * f[0]) + (r[3] * f[4] - r[4] * f[3])) + (r[6] * f[7] - r[7] * f[6]);
  // A(i, j) = sum_k F(i, k) R(j, k).
  const auto a = [&](int i, int j) {
    return (f[i] * r[j] + f[i + 3] * r[j + 3]) + f[i + 6] * r[j + 6];
  };
  const V minusHalf = L::set1(-0.5), zero = L::set1(0.0);
  const V a00 = a(0, 0), a11 = a(1, 1), a22 = a(2, 2);
  const V trA = (a00 + a11) + a22;
  const V h00 = trA - a00, h11 = trA - a11, h22 = trA - a22;
  const V h01 = minusHalf * (a(0, 1) + a(1, 0));
  const V h02 = minusHalf * (a(0, 2) + a(2, 0));
  const V h12 = minusHalf * (a(1, 2) + a(2, 1));
  // The adjugate of the symmetric H: its columns are cross products of H's columns.
  const V c0x = h11 * h22 - h12 * h12, c0y = h12 * h02 - h01 * h22, c0z = h01 * h12 - h11 * h02;
  const V c1x = h12 * h02 - h22 * h01, c1y = h22 * h00 - h02 * h02, c1z = h02 * h01 - h12 * h00;
  const V c2x = h01 * h12 - h02 * h11, c2y = h02 * h01 - h00 * h12, c2z = h00 * h11 - h01 * h01;
  const V det = (h00 * c0x + h01 * c0y) + h02 * c0z;
  // Positive definite by Sylvester's criterion (leading minors).
  s.newton = L::band(L::band(L::gt(trA, zero), L::gt(h00, zero)),
                     L::band(L::gt(h00 * h11 - h01 * h01, zero), L::gt(det, zero)));
  const V scale = L::set1(1.0) / (L::abs(trA) + L::set1(1e-300));
  s.omega[0] = L::select(s.newton, ((c0x * g0 + c1x * g1) + c2x * g2) / det, g0 * scale);
  s.omega[1] = L::select(s.newton, ((c0y * g0 + c1y * g1) + c2y * g2) / det, g1 * scale);
  s.omega[2] = L::select(s.newton, ((c0z * g0 + c1z * g1) + c2z * g2) / det, g2 * scale);
  s.w = L::sqrt((s.omega[0] * s.omega[0] + s.omega[1] * s.omega[1]) + s.omega[2] * s.omega[2]);
  s.trA = trA;
  s.det = det;
  return s;
}

/// Whether the angle a Newton step of length w leaves, at most 4 tr(A)^3 / det(H) w^2, is within
/// the tolerance (then the step is the last).
template <class L>
inline typename L::M isLastStep(typename L::V w, typename L::V trA, typename L::V det,
                                double tolerance) {
  return L::le(((((w * w) * L::set1(4.0)) * trA) * trA) * trA, L::set1(tolerance) * det);
}

/// q <- d q (Hamilton product), then q normalised; d = (dw, dx, dy, dz).
template <class L>
inline void rotateAndNormalise(typename L::V dw, typename L::V dx, typename L::V dy,
                               typename L::V dz, typename L::V& qw, typename L::V& qx,
                               typename L::V& qy, typename L::V& qz) {
  using V = typename L::V;
  const V w = ((dw * qw - dx * qx) - dy * qy) - dz * qz;
  const V x = ((dw * qx + dx * qw) + dy * qz) - dz * qy;
  const V y = ((dw * qy + dy * qw) + dz * qx) - dx * qz;
  const V z = ((dw * qz + dz * qw) + dx * qy) - dy * qx;
  const V n2 = ((w * w + x * x) + y * y) + z * z;
  const auto positive = L::gt(n2, L::set1(0.0));
  const V n = L::sqrt(n2);
  qw = L::select(positive, w / n, w);
  qx = L::select(positive, x / n, x);
  qy = L::select(positive, y / n, y);
  qz = L::select(positive, z / n, z);
}

}  // namespace deform::fem_hex::rotation
