// fem_hex kernels: the 8-node trilinear hexahedron (axis-aligned box of edge lengths
// size = (hx, hy, hz)) for linear and corotational elasticity.
//
// Local node a (0..7) sits at corner (a & 1, (a >> 1) & 1, (a >> 2) & 1) of the box, natural
// coordinates xi_a = 2 * corner - 1. Shape functions N_a(xi) = 1/8 prod_d (1 + xi_a,d xi_d).
// Element vectors are 24 long, node a's x, y, z at 3a, 3a+1, 3a+2.
//
// Linear small strain:   eps = sym(grad u), sigma = lambda tr(eps) I + 2 mu eps,
//   W(u) = 1/2 int eps : sigma dV,   f = -dW/du = -K0 u,   K0 = int B^T D B dV,
// integrated with 2x2x2 Gauss points (+-1/sqrt(3)), exact for the trilinear element.
// Corotational (Müller & Gross 2004, "Interactive virtual materials", Graphics Interface;
// Nesme et al. 2005, "Efficient, physically plausible finite elements", Eurographics short):
//   f = -R K0 (R^T x - X),   K = R K0 R^T   (R block-diagonal with the element rotation),
// R the rotation of the polar decomposition F = R S of the deformation gradient at the element
// centre, F = sum_a x_a (grad N_a(0))^T.
#pragma once

#include <deform/sdk/types.h>

#include <Eigen/Geometry>

namespace deform::fem_hex {

using Mat24 = Eigen::Matrix<Real, 24, 24>;
using Vec24 = Eigen::Matrix<Real, 24, 1>;
using Mat38 = Eigen::Matrix<Real, 3, 8>;  ///< node positions/displacements, one node a column
using Quat = Eigen::Quaternion<Real>;

/// Lamé parameters (lambda, mu) from Young's modulus E (Pa) and Poisson ratio nu.
Eigen::Vector2d lameParameters(Real young, Real poisson);

/// Corner (0/1 per axis) of local node a.
inline Vec3i hexCorner(int a) {
  return Vec3i(a & 1, (a >> 1) & 1, (a >> 2) & 1);
}

/// Gradients (1/m) of the 8 shape functions at natural point xi, one column per node.
Mat38 hexShapeGradients(const Vec3& size, const Vec3& xi);

/// Trilinear weights N_a at local coordinates t in [0,1]^3 (t = (p - corner0) / size).
Eigen::Matrix<Real, 8, 1> hexTrilinearWeights(const Vec3& t);

/// Rest stiffness K0 (N/m), 24 x 24, symmetric positive semi-definite with the 6 rigid modes
/// (3 translations, 3 infinitesimal rotations) as its null space.
Mat24 hexStiffness(const Vec3& size, Real young, Real poisson);

/// Rest stiffness (N/m), 24 x 24, of the hexahedron with Wilson's incompatible modes (Wilson et
/// al. 1973, "Incompatible displacement models"; Taylor, Beresford & Wilson 1976, "A
/// non-conforming element for stress analysis", IJNME): the trilinear displacement plus the nine
/// internal bubble modes (1 - xi^2, 1 - eta^2, 1 - zeta^2 for each component), condensed out
/// statically, K = Kuu - Kua Kaa^-1 Kau. On a box the modes' gradients integrate to zero, so the
/// element passes the patch test; it represents pure bending, which the trilinear element
/// resists with spurious shear (shear locking). Same null space as hexStiffness.
Mat24 hexStiffnessIncompatible(const Vec3& size, Real young, Real poisson);

/// Strain energy W(u) (J) of displacement u by quadrature of 1/2 eps : sigma (no B matrix:
/// an independent path for testing K0).
Real hexStrainEnergy(const Vec3& size, Real young, Real poisson, const Mat38& u);

/// Elastic force -dW/du (N) by quadrature of -int (grad N_a) . sigma dV (no B matrix).
Mat38 hexElasticForce(const Vec3& size, Real young, Real poisson, const Mat38& u);

/// Deformation gradient at the element centre: F = sum_a x_a (grad N_a(0))^T.
Mat3 hexCentreGradient(const Vec3& size, const Mat38& x);

/// Outcome of one rotation extraction.
struct RotationExtraction {
  int iterations = 0;      ///< Newton (or Müller) updates taken
  bool converged = false;  ///< the last step was below the tolerance, or the SVD gave R
  bool svd = false;        ///< the iteration cap was reached and R came from the SVD of F
};

/// Rotation R of the polar decomposition of F: the proper rotation maximising tr(R^T F) (for
/// inverted F the one with the smallest singular value negated). Warm-started from q, by Newton
/// steps on that objective under R <- exp([omega]) R:
///   omega = (tr(A) I - sym(A))^-1 sum_i r_i x f_i,   A = F R^T,
/// which converge quadratically (one or two steps per time step when warm-started). Müller et
/// al. 2016 ("A robust method to extract the rotational part of deformations", MIG) replace the
/// matrix by tr(A) I; their iteration removes only about two thirds of the angle error per step
/// near the solution (the error contracts by sym(A) / tr(A)), so a cap of 8 iterations never
/// reaches a 1e-9 rad tolerance from an error above 1e-5 rad. Their step is kept where the
/// Newton matrix is not positive definite (far from the maximum); a step is clamped at 1 rad.
/// Stops when |omega| <= tolerance (rad), or after a Newton step small enough that the angle it
/// leaves, at most 4 tr(A)^3 / det(H) |omega|^2 with H = tr(A) I - sym(A), is within the
/// tolerance (so a warm start evaluates the gradient once per step taken, not once more to see it
/// vanish). When maxIterations are used up, R is taken from the SVD of F (exact; reported in
/// `svd`). Not converged only when F or q is not finite.
RotationExtraction extractRotationInfo(const Mat3& F, Quat& q, int maxIterations,
                                       Real tolerance = 1e-12);

/// The rotation matrix of the unit quaternion q, by the arithmetic of the batch paths
/// (rotation_batch.h), so that both give the same bits.
Mat3 rotationMatrixOf(const Quat& q);

/// extractRotationInfo, returning the number of iterations.
int extractRotation(const Mat3& F, Quat& q, int maxIterations, Real tolerance = 1e-12);

/// Corotational element force f = -R K0 (R^T x - X) (N), x, X: current and rest positions.
Mat38 hexCorotationalForce(const Mat24& K0, const Mat3& R, const Mat38& x, const Mat38& X);

}  // namespace deform::fem_hex
