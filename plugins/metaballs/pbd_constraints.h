// Metaballs plugin, run-time kernels of paper Sect. 5.3 (Algorithm 3): position-based constraints
// on the sphere centres. Stateless: positions, inverse masses and rest data in, corrections out;
// each returns false (and changes nothing) when the configuration is degenerate.
#pragma once

#include <deform/sdk/types.h>

#include <cmath>

namespace deform::metaballs {

/// Stretching constraint, eqs. (6)-(8): C = |c1 - c2| - d. Classic PBD with stiffness k in [0,1]:
///   dc1 = -k w1/(w1+w2) C n,   dc2 = +k w2/(w1+w2) C n,   n = (c1-c2)/|c1-c2|.
inline bool projectStretch(const Vec3& c1, const Vec3& c2, Real w1, Real w2, Real rest, Real k,
                           Vec3& dc1, Vec3& dc2) {
  const Vec3 d = c1 - c2;
  const Real len = d.norm();
  const Real wsum = w1 + w2;
  if (!(len > 1e-12) || !(wsum > 0)) return false;
  const Vec3 n = d / len;
  const Real s = k * (len - rest) / wsum;
  dc1 = -w1 * s * n;
  dc2 = w2 * s * n;
  return true;
}

/// XPBD form of eqs. (6)-(8) (Macklin, Mueller, Chentanez 2016): compliance alpha (m/N), time step
/// dt, accumulated multiplier lambda (updated in place):
///   dlambda = (-C - alpha~ lambda) / (w1 + w2 + alpha~),  alpha~ = alpha / dt^2,
///   dc1 = w1 dlambda n,  dc2 = -w2 dlambda n.
inline bool projectStretchXpbd(const Vec3& c1, const Vec3& c2, Real w1, Real w2, Real rest,
                               Real alphaTilde, Real& lambda, Vec3& dc1, Vec3& dc2) {
  const Vec3 d = c1 - c2;
  const Real len = d.norm();
  const Real denom = w1 + w2 + alphaTilde;
  if (!(len > 1e-12) || !(denom > 0)) return false;
  const Vec3 n = d / len;
  const Real dl = (-(len - rest) - alphaTilde * lambda) / denom;
  lambda += dl;
  dc1 = w1 * dl * n;
  dc2 = -w2 * dl * n;
  return true;
}

/// Laplacian coordinate of sphere m, eqs. (9)-(10): L_m = c_m - (1/n) sum_i c_i over its n linked
/// spheres.
/// Constraint (11) as a vector PBD constraint C = c_m - (1/n) sum_i c_i - R L_m (R the local
/// rotation, identity for the paper's fixed frame). Gradients: I for c_m, -I/n for each c_i;
/// generalised inverse mass W = w_m + sum_i w_i / n^2. Classic PBD with stiffness k:
///   dc_m = -k w_m C / W,   dc_i = +k (w_i / n) C / W.
/// With immovable neighbours (w_i = 0) and k = 1 this is exactly the paper's update (11),
/// c'_m = L_m + c'_center. Returns the scale s = k / W (0 when degenerate): dc_m = -w_m s C.
inline Real laplacianScale(Real wm, Real sumNeighbourW, int n, Real k) {
  if (n <= 0) return 0;
  const Real W = wm + sumNeighbourW / Real(n * n);
  return W > 0 ? k / W : 0;
}
/// XPBD vector form: dlambda = (-C - alpha~ lambda) / (W + alpha~), dc_m = w_m dlambda,
/// dc_i = -(w_i/n) dlambda. Returns dlambda and updates lambda.
inline Vec3 laplacianXpbd(const Vec3& C, Real wm, Real sumNeighbourW, int n, Real alphaTilde,
                          Vec3& lambda) {
  const Real W = wm + sumNeighbourW / Real(n * n);
  if (n <= 0 || !(W + alphaTilde > 0)) return Vec3::Zero();
  const Vec3 dl = (-C - alphaTilde * lambda) / (W + alphaTilde);
  lambda += dl;
  return dl;
}

/// Local volume preservation, eq. (12): the radii of the contacted sphere and its linked spheres
/// scale by sqrt(sum d(c) / sum d(c')), sum d the summed distances from the contacted sphere to its
/// linked spheres at rest (restSum) and now (currentSum). A stretched neighbourhood (the tube
/// lengthens) thins so that length * radius^2 stays constant; a compressed one thickens.
inline Real volumeRadiusScale(Real restSum, Real currentSum) {
  if (!(restSum > 0) || !(currentSum > 0)) return 1.0;
  return std::sqrt(restSum / currentSum);
}

/// Rotational part of A (3x3), warm-started from q and written back to q: the iteration of
/// Mueller, Bender, Chentanez, Macklin 2016, "A robust method to extract the rotational part of
/// deformations" (MIG). Used to rotate the Laplacian coordinates and the skinning offsets into the
/// current local frame (see README). Exactly the identity for a symmetric A and q = identity.
inline void extractRotation(const Mat3& A, Eigen::Quaternion<Real>& q, int maxIter) {
  for (int it = 0; it < maxIter; ++it) {
    const Mat3 R = q.matrix();
    const Vec3 omega =
        (R.col(0).cross(A.col(0)) + R.col(1).cross(A.col(1)) + R.col(2).cross(A.col(2))) /
        (std::abs(R.col(0).dot(A.col(0)) + R.col(1).dot(A.col(1)) + R.col(2).dot(A.col(2))) +
         1e-30);
    const Real w = omega.norm();
    if (w < 1e-9) break;
    q = Eigen::Quaternion<Real>(Eigen::AngleAxis<Real>(w, omega / w)) * q;
    q.normalize();
  }
}

}  // namespace deform::metaballs
