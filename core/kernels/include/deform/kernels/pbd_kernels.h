// deformbench SDK: position-based dynamics constraint kernels shared by the PBD plugin and the
// hybrid FEM+PBD plugin (moved here from plugins/pbd so that no plugin includes another). Small
// stateless functions that, given the positions and inverse masses of the particles a constraint
// touches, compute the position corrections and the change of the constraint's Lagrange
// multiplier. They see no scene and allocate nothing.
//
// One update rule serves both stiffness modes. For a constraint C(x) with gradients g_i = dC/dx_i
// and inverse masses w_i,
//
//   dlambda = k * (-C - alphaTilde * lambda) / (sum_i w_i |g_i|^2 + alphaTilde),
//   dx_i    = w_i * g_i * dlambda,          lambda += dlambda,
//
// - XPBD (Macklin, Mueller, Chentanez 2016, "XPBD: position-based simulation of compliant
//   constrained dynamics", MIG '16, doi:10.1145/2994258.2994272, Eqs. (17)-(18)): k = 1 and
//   alphaTilde = alpha / dt^2 with alpha the compliance (inverse stiffness) of the constraint.
// - classic PBD (Mueller, Heidelberger, Hennix, Ratcliff 2007, "Position based dynamics",
//   J. Vis. Commun. Image Represent. 18(2), doi:10.1016/j.jvcir.2007.01.005, Sec. 3.3):
//   alphaTilde = 0 and k the per-iteration stiffness k' = 1 - (1 - k)^(1/n) (classicStiffness()).
//
// Because sum_i g_i = 0 for every constraint here (translation invariance), the mass-weighted
// corrections sum to zero: sum_i m_i dx_i = (sum_i g_i) dlambda = 0 (linear momentum conserved).
// A kernel returns false, changing nothing, when the configuration is degenerate (zero-length
// edge, zero-area triangle, all particles immovable); the caller counts it.
#pragma once

#include <deform/sdk/types.h>

#include <cmath>
#include <numbers>

namespace deform::pbd {

/// Per-iteration stiffness for classic PBD (Mueller et al. 2007, Sec. 3.3): applying k' in each of
/// n iterations leaves the error factor (1 - k')^n = 1 - k of a single linear constraint, so the
/// effective stiffness does not depend on the iteration count.
inline Real classicStiffness(Real k, int iterations) {
  return 1.0 - std::pow(1.0 - k, 1.0 / static_cast<Real>(iterations));
}

/// Multiplier update shared by every kernel (see the header comment).
inline Real multiplierUpdate(Real C, Real gradNorm2W, Real alphaTilde, Real k, Real lambda) {
  return k * (-C - alphaTilde * lambda) / (gradNorm2W + alphaTilde);
}

/// Distance (stretch) constraint C = |x_a - x_b| - L (Mueller et al. 2007, Sec. 4.2; XPBD Sec. 4).
/// g_a = n, g_b = -n with n = (x_a - x_b) / |x_a - x_b|.
struct DistanceConstraint {
  int a = 0, b = 0;
  Real rest = 0;        ///< L, m
  Real compliance = 0;  ///< alpha, m/N (XPBD); 0 for classic
};

/// Projects one distance constraint. xa, xb: positions (m); wa, wb: inverse masses (1/kg).
/// Outputs the corrections dxa, dxb and updates lambda.
inline bool projectDistance(const Vec3& xa, const Vec3& xb, Real wa, Real wb, Real rest,
                            Real alphaTilde, Real k, Real& lambda, Vec3& dxa, Vec3& dxb) {
  const Vec3 d = xa - xb;
  const Real len = d.norm();
  const Real wsum = wa + wb;
  if (len <= tol::kDegenerateLength || wsum + alphaTilde <= 0) return false;
  const Vec3 n = d / len;
  const Real dl = multiplierUpdate(len - rest, wsum, alphaTilde, k, lambda);
  lambda += dl;
  dxa = wa * dl * n;
  dxb = -wb * dl * n;
  return true;
}

/// Dihedral-angle bending constraint across an interior edge, C = theta - theta0 wrapped to
/// (-pi, pi] (Mueller et al. 2007, Appendix A defines C = acos(n1.n2) - phi0). We keep the angle
/// constraint because organ surfaces are curved at rest, but evaluate theta with atan2 and use the
/// gradients of Bridson, Marino, Fedkiw 2003 ("Simulation of clothing with folds and wrinkles",
/// SCA '03, Sec. 4), which stay finite for flat hinges where the acos form has 1/sqrt(1-d^2).
///
/// Particles: x2, x3 span the shared edge e = x3 - x2; x0 is the wing of triangle (x0, x2, x3),
/// x1 the wing of triangle (x1, x3, x2) (both counter-clockwise seen from outside). With
/// nA = (x2-x0)x(x3-x0), nB = (x3-x1)x(x2-x1) (unnormalised):
///   g0 = |e| nA/|nA|^2,   g1 = |e| nB/|nB|^2,
///   g2 = ((x0-x3).e)/|e| nA/|nA|^2 + ((x1-x3).e)/|e| nB/|nB|^2,
///   g3 = -((x0-x2).e)/|e| nA/|nA|^2 - ((x1-x2).e)/|e| nB/|nB|^2,
/// and theta = atan2((nB^ x nA^).e^, nA^.nB^) (0 when flat, positive when folding along nA).
struct DihedralConstraint {
  int p[4] = {0, 0, 0, 0};  ///< x0, x1 wings; x2, x3 shared edge
  Real restAngle = 0;       ///< theta0, rad
  Real compliance = 0;      ///< alpha, 1/(N m) (XPBD); 0 for classic
};

/// Signed dihedral angle and its gradients (see DihedralConstraint). False when degenerate.
inline bool dihedralAngle(const Vec3& x0, const Vec3& x1, const Vec3& x2, const Vec3& x3,
                          Real& theta, Vec3 grad[4]) {
  const Vec3 e = x3 - x2;
  const Real elen2 = e.squaredNorm();
  const Vec3 nA = (x2 - x0).cross(x3 - x0);
  const Vec3 nB = (x3 - x1).cross(x2 - x1);
  const Real a2 = nA.squaredNorm(), b2 = nB.squaredNorm();
  constexpr Real kTiny = tol::kDegenerateLength * tol::kDegenerateLength;
  if (elen2 <= kTiny || a2 <= kTiny * kTiny || b2 <= kTiny * kTiny) return false;
  const Real elen = std::sqrt(elen2);
  const Vec3 uA = nA / a2, uB = nB / b2;
  grad[0] = elen * uA;
  grad[1] = elen * uB;
  grad[2] = ((x0 - x3).dot(e) / elen) * uA + ((x1 - x3).dot(e) / elen) * uB;
  grad[3] = -((x0 - x2).dot(e) / elen) * uA - ((x1 - x2).dot(e) / elen) * uB;
  const Real invAB = 1.0 / std::sqrt(a2 * b2);
  const Real cosT = nA.dot(nB) * invAB;
  const Real sinT = nB.cross(nA).dot(e) * invAB / elen;
  theta = std::atan2(sinT, cosT);
  return true;
}

/// Wraps an angle difference to (-pi, pi].
inline Real wrapAngle(Real a) {
  constexpr Real pi = std::numbers::pi_v<Real>;
  while (a > pi) a -= 2 * pi;
  while (a <= -pi) a += 2 * pi;
  return a;
}

/// Projects one dihedral constraint. x[4], w[4] in the order of DihedralConstraint::p. wd[4]:
/// the inverse masses the update divides by (sum_i wd_i |g_i|^2); particle i still moves by
/// w_i dl g_i. The hybrid FEM+PBD model passes stand-ins for its immovable particles there
/// (hingeDenominatorWeights in plugins/hybrid_fem_pbd/surface_pbd.h).
inline bool projectDihedral(const Vec3 x[4], const Real w[4], const Real wd[4], Real restAngle,
                            Real alphaTilde, Real k, Real& lambda, Vec3 dx[4]) {
  Real theta;
  Vec3 g[4];
  if (!dihedralAngle(x[0], x[1], x[2], x[3], theta, g)) return false;
  const Real denom = wd[0] * g[0].squaredNorm() + wd[1] * g[1].squaredNorm() +
                     wd[2] * g[2].squaredNorm() + wd[3] * g[3].squaredNorm();
  if (denom + alphaTilde <= 0) return false;
  const Real dl = multiplierUpdate(wrapAngle(theta - restAngle), denom, alphaTilde, k, lambda);
  lambda += dl;
  for (int i = 0; i < 4; ++i) dx[i] = w[i] * dl * g[i];
  return true;
}

/// Projects one dihedral constraint, dividing by the particles' own inverse masses.
inline bool projectDihedral(const Vec3 x[4], const Real w[4], Real restAngle, Real alphaTilde,
                            Real k, Real& lambda, Vec3 dx[4]) {
  return projectDihedral(x, w, w, restAngle, alphaTilde, k, lambda, dx);
}

}  // namespace deform::pbd
