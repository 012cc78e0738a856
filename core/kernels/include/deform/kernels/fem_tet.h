// deformbench SDK: linear (4-node) tetrahedral finite elements and hyperelastic material kernels,
// shared by the reference FEM and the hybrid FEM+PBD plugin.
//
// Kinematics. A tet with rest nodes X0..X3 and current nodes x0..x3 has the constant deformation
// gradient F = Ds Dm^{-1}, Ds = [x1-x0, x2-x0, x3-x0], Dm = [X1-X0, X2-X0, X3-X0]. The shape-
// function gradients are g_a = rows of Bm = Dm^{-1} (a = 1..3) and g_0 = -(g_1 + g_2 + g_3), so
// F = sum_a x_a g_a^T. With W = V psi(F) (V rest volume), the gradient on node a is V P g_a with
// P = dpsi/dF (first Piola-Kirchhoff stress), the force is its negative, and the 12x12 stiffness
// is V G^T (dP/dF) G where G maps the 12 node coordinates to vec(F).
//
// Conventions. vec(F) is column-major: F(i, j) sits at index i + 3 j. Node coordinate k of node a
// sits at index 3 a + k. Lame parameters from Young's modulus E and Poisson ratio nu:
// mu = E / (2 (1 + nu)), lambda = E nu / ((1 + nu) (1 - 2 nu)), bulk kappa = lambda + 2 mu / 3.
//
// Materials (each a small struct: psi, P, dP/dF):
//   LinearMaterial        small strain: eps = (F + F^T)/2 - I, psi = mu eps:eps + lambda/2
//   tr(eps)^2. CorotationalMaterial  F = R S (polar decomposition, R a rotation), psi = mu |S -
//   I|^2 +
//                         lambda/2 tr(S - I)^2, P = R (2 mu (S - I) + lambda tr(S - I) I); this is
//                         the per-element rotated linear element of Mueller & Gross, "Interactive
//                         virtual materials", Graphics Interface 2004 (force f = -R K0 (R^T x -
//                         X)). Its tangent is either R K0 R^T (rotation held fixed, the standard
//                         choice, always positive semi-definite) or the exact derivative including
//                         dR (McAdams et al., "Efficient elasticity for character skinning with
//                         contact and collisions", SIGGRAPH 2011, doi:10.1145/1964921.1964932).
//   NeoHookeanMaterial    compressible Neo-Hookean with the isochoric/volumetric split:
//                         psi = mu/2 (J^{-2/3} I1 - 3) + kappa/2 (J - 1)^2, I1 = F:F, J = det F
//                         (Bonet & Wood, "Nonlinear Continuum Mechanics for Finite Element
//                         Analysis", 2nd ed. 2008, sec. 6.5, doi:10.1017/CBO9780511755446). It
//                         reduces to linear elasticity with the same mu and kappa at small strain,
//                         has no log J term (so the volumetric part stays bounded and smooth as
//                         nu -> 0.5, kappa -> inf acts as a penalty), and psi = +inf for J <= 0 so
//                         a line search backs off inverted states instead of producing NaN.
#pragma once

#include <deform/sdk/types.h>

#include <array>
#include <cmath>
#include <limits>

namespace deform {

using Vec12 = Eigen::Matrix<Real, 12, 1>;
using Mat12 = Eigen::Matrix<Real, 12, 12>;
using Mat9 = Eigen::Matrix<Real, 9, 9>;
using Vec9 = Eigen::Matrix<Real, 9, 1>;

struct LameParameters {
  Real mu = 0;      ///< shear modulus, Pa
  Real lambda = 0;  ///< first Lame parameter, Pa
  Real bulk() const { return lambda + 2.0 * mu / 3.0; }
  /// E (Pa) > 0, nu in (-1, 0.5).
  static LameParameters fromYoungPoisson(Real young, Real poisson);
};

/// Rest data of one tet: Bm = Dm^{-1} and the rest volume V (m^3). Valid only when V > 0.
struct TetRest {
  Mat3 Bm = Mat3::Identity();
  Real volume = 0;
  /// Shape-function gradients g_0..g_3 as columns (1/m).
  Eigen::Matrix<Real, 3, 4> gradients() const;
};

/// Rest data from rest positions. Returns false (and leaves volume <= 0) for a degenerate or
/// negatively oriented tet.
bool makeTetRest(const Vec3& X0, const Vec3& X1, const Vec3& X2, const Vec3& X3, TetRest& rest);

/// Deformation gradient F = Ds Bm.
Mat3 deformationGradient(const TetRest& rest, const std::array<Vec3, 4>& x);

/// Polar decomposition F = R S with R a proper rotation (det R = +1) and S symmetric (S may be
/// indefinite when F is inverted). Uses the SVD F = U Sigma V^T with the sign of the smallest
/// singular value flipped when det(U V^T) < 0.
void polarDecomposition(const Mat3& F, Mat3& R, Mat3& S);

/// Clamps the eigenvalues of a symmetric 9x9 matrix to >= 0 (projection onto the PSD cone).
Mat9 projectPositiveSemiDefinite(const Mat9& A);

/// The cofactor matrix H = cof F = J F^{-T}, by columns [F1 x F2, F2 x F0, F0 x F1].
Mat3 cofactor(const Mat3& F);
/// The cross-product matrix [w]x (W v = w x v).
Mat3 crossMatrix(const Vec3& w);
/// D += s dH/dF (9x9 on vec(F), column-major): column j of dH is a cross product of the other
/// two columns of F with those of dF.
void addCofactorDerivative(Real s, const Mat3& F, Mat9& D);

struct LinearMaterial {
  LameParameters lame;
  Real energyDensity(const Mat3& F) const;
  Mat3 stress(const Mat3& F) const;
  Mat9 stressDerivative(const Mat3& F) const;
};

enum class CorotationalTangent { FixedRotation, Exact };

struct CorotationalMaterial {
  LameParameters lame;
  CorotationalTangent tangent = CorotationalTangent::FixedRotation;
  Real energyDensity(const Mat3& F) const;
  Mat3 stress(const Mat3& F) const;
  Mat9 stressDerivative(const Mat3& F) const;
};

struct NeoHookeanMaterial {
  LameParameters lame;
  /// +inf when det F <= 0.
  Real energyDensity(const Mat3& F) const;
  Mat3 stress(const Mat3& F) const;
  Mat9 stressDerivative(const Mat3& F) const;
  /// projectPositiveSemiDefinite(stressDerivative(F)) in closed form (det F > 0), from the
  /// analytic eigensystem of an isotropic energy psi(sigma_1, sigma_2, sigma_3) of the singular
  /// values of F = U Sigma V^T (Teran, Sifakis, Irving & Fedkiw, "Robust quasistatic finite
  /// elements and flesh simulation", SCA 2005, sec. 5; Smith, de Goes & Kim, "Analytic
  /// eigensystems for isotropic distortion energies", ACM TOG 38(1) 2019, doi:10.1145/3241041):
  /// six eigenmatrices U (e_i e_j^T -+ e_j e_i^T) V^T / sqrt 2 (i < j, twist and flip) with
  /// eigenvalues (psi_i + psi_j) / (sigma_i + sigma_j) and (psi_i - psi_j) / (sigma_i - sigma_j),
  /// and three U diag(q_k) V^T with q_k, lambda_k the eigenpairs of the 3x3 Hessian
  /// d^2 psi / d sigma_i d sigma_j. For this energy psi_i = mu J^{-2/3} sigma_i + c / sigma_i,
  /// c = kappa (J - 1) J - mu/3 J^{-2/3} I1, so the pair eigenvalues are
  /// mu J^{-2/3} +- c / (sigma_i sigma_j), free of the 0/0 at repeated singular values.
  Mat9 projectedStressDerivative(const Mat3& F) const;
};

/// Element energy, gradient (= -force) and stiffness of one tet.
struct TetEvaluation {
  Real energy = 0;  ///< J
  Vec12 gradient;   ///< N, dW/dx (the elastic force on the nodes is its negative)
  Mat12 stiffness;  ///< N/m, d^2W/dx^2 (or the material's chosen tangent)
};

enum class TetEvalMode { Energy, Gradient, Stiffness };

/// dP/dF at F (9x9, vec(F) column-major), projected onto the PSD cone when projectSpd is set:
/// in closed form where the material offers projectedStressDerivative(), else by eigenvalues.
template <class Material>
Mat9 stressDerivativeAt(const Material& material, const Mat3& F, bool projectSpd) {
  if constexpr (requires { material.projectedStressDerivative(F); }) {
    return projectSpd ? material.projectedStressDerivative(F) : material.stressDerivative(F);
  } else {
    const Mat9 D = material.stressDerivative(F);
    return projectSpd ? projectPositiveSemiDefinite(D) : D;
  }
}

/// Evaluates W = V psi(F) and, as asked, its gradient and stiffness. When projectSpd is set the
/// stress derivative is projected onto the PSD cone first (so the stiffness is PSD).
template <class Material>
void evaluateTet(const Material& material, const TetRest& rest, const std::array<Vec3, 4>& x,
                 TetEvalMode mode, TetEvaluation& out, bool projectSpd = false) {
  const Mat3 F = deformationGradient(rest, x);
  out.energy = rest.volume * material.energyDensity(F);
  if (mode == TetEvalMode::Energy || !std::isfinite(out.energy)) return;
  const Eigen::Matrix<Real, 3, 4> g = rest.gradients();
  const Mat3 P = material.stress(F);
  for (int a = 0; a < 4; ++a) out.gradient.segment<3>(3 * a) = rest.volume * P * g.col(a);
  if (mode != TetEvalMode::Stiffness) return;
  const Mat9 D = stressDerivativeAt(material, F, projectSpd);
  // K = V G^T D G with G(i + 3 j, 3 a + i) = g_a(j), using G's structure: the 3-column block b
  // of D G is sum_l g_b(l) D(:, 3 l .. 3 l + 2), the 3-row block a of G^T (D G) is
  // sum_j g_a(j) (D G)(3 j .. 3 j + 2, :).
  Eigen::Matrix<Real, 9, 12> DG;
  for (int b = 0; b < 4; ++b)
    DG.middleCols<3>(3 * b) =
        g(0, b) * D.middleCols<3>(0) + g(1, b) * D.middleCols<3>(3) + g(2, b) * D.middleCols<3>(6);
  for (int a = 0; a < 4; ++a)
    out.stiffness.middleRows<3>(3 * a) =
        rest.volume * (g(0, a) * DG.middleRows<3>(0) + g(1, a) * DG.middleRows<3>(3) +
                       g(2, a) * DG.middleRows<3>(6));
}

/// Elastic nodal forces f = -dW/dx (#4 nodes by 3 packed as 12), zero energy check skipped.
template <class Material>
Vec12 tetForces(const Material& material, const TetRest& rest, const std::array<Vec3, 4>& x) {
  TetEvaluation e;
  evaluateTet(material, rest, x, TetEvalMode::Gradient, e);
  return -e.gradient;
}

}  // namespace deform
