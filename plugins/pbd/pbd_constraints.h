// PBD / XPBD constraint kernels: small stateless functions that, given the positions and inverse
// masses of the particles a constraint touches, compute the position corrections and the change
// of the constraint's Lagrange multiplier. They see no scene and allocate nothing.
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

#include <deform/types.h>

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

/// A run of distance constraints in structure-of-arrays form, as the solver stores them: one
/// entry per constraint, with the per-step data alphaTilde = alpha/dt^2 and the multiplier scale
/// k / (w_a + w_b + alphaTilde) precomputed.
struct DistanceBatch {
  const int* a;
  const int* b;
  const Real* rest;
  const Real* alphaTilde;
  const Real* scale;
  Real* lambda;
  const Real* wa;  ///< inverse mass of a, per constraint
  const Real* wb;  ///< inverse mass of b, per constraint
};

/// Projects constraints [begin, end) of a batch whose constraints share no particle (one colour of
/// a greedy colouring), so that projecting them together equals projecting them one after the
/// other with projectDistance(). Positions x4 are padded to four doubles per particle
/// (x, y, z, 0) and the inverse masses come from batch.wa / batch.wb. With simd (and a CPU with
/// AVX2) four constraints are projected per vector step: one vector load and store per particle
/// instead of three scalar ones. Arithmetic is the same operation for operation (no FMA
/// contraction), so the SIMD and scalar paths give identical results. Returns the number of
/// degenerate (skipped) constraints.
long long projectDistanceColourPadded(Real* x4, const DistanceBatch& batch, size_t begin,
                                      size_t end, bool simd = true);

/// Whether projectDistanceColourPadded(simd = true) uses AVX2 on this CPU.
bool distanceSimdAvailable();

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

/// Projects one dihedral constraint. x[4], w[4] in the order of DihedralConstraint::p.
inline bool projectDihedral(const Vec3 x[4], const Real w[4], Real restAngle, Real alphaTilde,
                            Real k, Real& lambda, Vec3 dx[4]) {
  Real theta;
  Vec3 g[4];
  if (!dihedralAngle(x[0], x[1], x[2], x[3], theta, g)) return false;
  const Real denom = w[0] * g[0].squaredNorm() + w[1] * g[1].squaredNorm() +
                     w[2] * g[2].squaredNorm() + w[3] * g[3].squaredNorm();
  if (denom + alphaTilde <= 0) return false;
  const Real dl = multiplierUpdate(wrapAngle(theta - restAngle), denom, alphaTilde, k, lambda);
  lambda += dl;
  for (int i = 0; i < 4; ++i) dx[i] = w[i] * dl * g[i];
  return true;
}

/// Tetrahedron volume constraint C = V(x) - V0 with V = (x1-x0).((x2-x0)x(x3-x0)) / 6
/// (Mueller et al. 2007, Sec. 4.4 uses the same form for tetrahedra). Gradients:
/// g1 = (x2-x0)x(x3-x0)/6, g2 = (x3-x0)x(x1-x0)/6, g3 = (x1-x0)x(x2-x0)/6, g0 = -(g1+g2+g3).
struct TetVolumeConstraint {
  int p[4] = {0, 0, 0, 0};
  Real restVolume = 0;  ///< V0, m^3 (positive for a positively oriented tet)
  Real compliance = 0;  ///< alpha, m^5/N (XPBD: V0 / K); 0 for classic
};

inline bool projectTetVolume(const Vec3 x[4], const Real w[4], Real restVolume, Real alphaTilde,
                             Real k, Real& lambda, Vec3 dx[4]) {
  const Vec3 e1 = x[1] - x[0], e2 = x[2] - x[0], e3 = x[3] - x[0];
  Vec3 g[4];
  g[1] = e2.cross(e3) / 6.0;
  g[2] = e3.cross(e1) / 6.0;
  g[3] = e1.cross(e2) / 6.0;
  g[0] = -(g[1] + g[2] + g[3]);
  const Real vol = e1.dot(g[1]);
  Real denom = 0, gsum = 0;
  for (int i = 0; i < 4; ++i) {
    const Real g2 = g[i].squaredNorm();
    gsum += g2;
    denom += w[i] * g2;
  }
  // A tet collapsed to a point or a segment has vanishing gradients (|g|^2 ~ V0^(4/3) at rest).
  const Real scale = std::cbrt(std::abs(restVolume));
  if (denom + alphaTilde <= 0 || gsum <= 1e-20 * scale * scale * scale * scale) return false;
  const Real dl = multiplierUpdate(vol - restVolume, denom, alphaTilde, k, lambda);
  lambda += dl;
  for (int i = 0; i < 4; ++i) dx[i] = w[i] * dl * g[i];
  return true;
}

/// Global volume constraint of a closed, outward-oriented triangle surface, C = V(x) - V0 with
/// V = (1/6) sum_T x_a.(x_b x x_c) (Mueller et al. 2007, Sec. 4.4, Eq. for closed meshes), so
/// g_i = (1/6) sum over triangles T containing i of (x_b x x_c) with (i, b, c) T's vertices in
/// cyclic order.
///
/// x: #N by 3 positions, w: #N inverse masses, F: #F by 3 triangles, grad: #N by 3 scratch
/// (overwritten with the gradient), dx: #N by 3 output corrections. Returns false when no
/// particle can move or the gradient vanishes.
bool projectSurfaceVolume(const MatX3& x, const VecX& w, const MatX3i& F, Real restVolume,
                          Real alphaTilde, Real k, Real& lambda, MatX3& grad, MatX3& dx);

/// The same projection applied in place to x (the solver's form: no dx array).
bool projectSurfaceVolumeInPlace(MatX3& x, const VecX& w, const MatX3i& F, Real restVolume,
                                 Real alphaTilde, Real k, Real& lambda, MatX3& grad);

}  // namespace deform::pbd
