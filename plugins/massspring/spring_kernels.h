// Mass-spring kernels: the force, energy and Jacobians of one linear (Hookean) spring with a
// dashpot along its axis, and the rules that derive spring constants from Young's modulus.
// Stateless, header-only, allocation-free.
//
// A spring between particles a and b with rest length L, stiffness k (N/m) and axial damping
// c (N s/m). With d = x_b - x_a, l = |d|, n = d / l:
//   energy   E = k/2 (l - L)^2
//   force on a: f_a = k (l - L) n + c ((v_b - v_a) . n) n,   f_b = -f_a
//   stiffness   df_a/dx_a = -K,  df_a/dx_b = K,  K = k [ n n^T + (1 - L/l) (I - n n^T) ]
//   damping     df_a/dv_a = -c n n^T, df_a/dv_b = c n n^T   (the dependence of n on x in the
//               damping force is dropped, as in Baraff & Witkin 1998, Sec. 4.5)
// For the implicit solve K is made positive semidefinite by clamping (1 - L/l) at 0 for a
// compressed spring (the transverse term is then negative: Choi & Ko 2002, "Stable but
// responsive cloth", Sec. 4, discuss this instability of the exact Jacobian).
#pragma once

#include <deform/sdk/types.h>

#include <algorithm>
#include <cmath>

namespace deform::massspring {

struct Spring {
  int a = 0, b = 0;
  Real rest = 0;  ///< L, m
  Real k = 0;     ///< stiffness, N/m
  Real c = 0;     ///< axial damping, N s/m
};

/// k/2 (|x_b - x_a| - L)^2, J.
inline Real springEnergy(const Vec3& xa, const Vec3& xb, Real k, Real rest) {
  const Real s = (xb - xa).norm() - rest;
  return 0.5 * k * s * s;
}

/// The spring's length l = |x_b - x_a| and direction n = (x_b - x_a) / l; false (n, l unset)
/// when it has (near) zero length and no direction.
inline bool springDirection(const Vec3& xa, const Vec3& xb, Vec3& n, Real& l) {
  const Vec3 d = xb - xa;
  l = d.norm();
  if (l <= tol::kDegenerateLength) return false;
  n = d / l;
  return true;
}

/// Force on particle a (the force on b is its negative). False, with fa = 0, when the spring has
/// (near) zero length and no direction.
inline bool springForce(const Vec3& xa, const Vec3& xb, const Vec3& va, const Vec3& vb, Real k,
                        Real c, Real rest, Vec3& fa) {
  Vec3 n;
  Real l;
  if (!springDirection(xa, xb, n, l)) {
    fa.setZero();
    return false;
  }
  fa = (k * (l - rest) + c * (vb - va).dot(n)) * n;
  return true;
}

/// The 3x3 block K of the stiffness (see the header comment); psd clamps the transverse term.
inline bool springStiffness(const Vec3& xa, const Vec3& xb, Real k, Real rest, bool psd, Mat3& K) {
  Vec3 n;
  Real l;
  if (!springDirection(xa, xb, n, l)) {
    K.setZero();
    return false;
  }
  Real t = 1.0 - rest / l;
  if (psd) t = std::max<Real>(t, 0.0);
  const Mat3 nn = n * n.transpose();
  K = k * (nn + t * (Mat3::Identity() - nn));
  return true;
}

/// Membrane rule of van Gelder 1998 ("Approximate simulation of elastic membranes by
/// triangulated spring meshes", J. Graphics Tools 3(2)): k = E t sum_{T ni e} |T| / |e|^2, with
/// the sum over the (one or two) triangles containing the edge and t the membrane thickness.
/// On a lattice of equilateral triangles it reproduces the membrane stiffness E t exactly (the
/// network's Poisson ratio is then fixed at 1/3). adjacentArea: sum of the triangles' areas, m^2.
inline Real membraneSpringStiffness(Real young, Real thickness, Real restLength,
                                    Real adjacentArea) {
  return young * thickness * adjacentArea / (restLength * restLength);
}

/// Volumetric analogue for tetrahedral meshes: k = E sum_{T ni e} V_T / |e|^2 (van Gelder 1998
/// states the 3D form; for an isotropic distribution of edge directions it gives Young's modulus
/// E with the spring network's fixed Poisson ratio 1/4, see README.md). adjacentVolume: m^3.
inline Real volumeSpringStiffness(Real young, Real restLength, Real adjacentVolume) {
  return young * adjacentVolume / (restLength * restLength);
}

/// Axial dashpot for a damping ratio zeta of the two-body oscillator: c = 2 zeta sqrt(k mu),
/// mu = m_a m_b / (m_a + m_b) the reduced mass (kg). N s/m.
inline Real springDamping(Real zeta, Real k, Real ma, Real mb) {
  if (!(ma > 0) || !(mb > 0)) return 0.0;
  return 2.0 * zeta * std::sqrt(k * ma * mb / (ma + mb));
}

}  // namespace deform::massspring
