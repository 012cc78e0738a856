// Quadratic (10-node, P2) straight-sided tetrahedra for the reference FEM.
//
// Nodes 0..3 are the corners, 4..9 the midpoints of the edges (0,1), (0,2), (0,3), (1,2), (1,3),
// (2,3) (kQuadraticEdges). With barycentric coordinates L_0..L_3 (L_0 = 1 - L_1 - L_2 - L_3) the
// shape functions are
//     N_a = L_a (2 L_a - 1) (corners),   N_ab = 4 L_a L_b (edge a-b),
// (Zienkiewicz, Taylor & Zhu, "The Finite Element Method: Its Basis and Fundamentals", 7th ed.
// 2013, sec. 6.6, doi:10.1016/C2009-0-24909-9). The sides are straight (midside nodes at the edge
// midpoints at rest), so the map from L to X is affine, grad L_a = g_a is the constant P1
// gradient of deform/kernels/fem_tet.h, and
//     grad N_a = (4 L_a - 1) g_a,   grad N_ab = 4 (L_a g_b + L_b g_a).
// The deformation gradient F(X) = sum_i x_i grad N_i^T is linear in X. The element energy
//     W = integral_T psi(F) dV ~= V sum_q w_q psi(F(X_q))
// uses the 4-point degree-2 rule (Hammer, Marlowe & Stroud 1956; points at barycentric
// (a, b, b, b) and permutations, a = (5 + 3 sqrt 5)/20, b = (5 - sqrt 5)/20, weights 1/4). Why
// this rule: (1) for the linear material the stiffness integrand grad N^T C grad N is quadratic,
// so the rule is exact and the element is the textbook P2 element; (2) a rule exact for degree
// 2k - 2 keeps the optimal convergence order of P_k elements (Strang & Fix, "An Analysis of the
// Finite Element Method", 1973, sec. 4.3; Ciarlet, "The Finite Element Method for Elliptic
// Problems", 1978, thm. 4.1.6), so for k = 2 degree 2 suffices for the nonlinear materials too;
// (3) its 4 x 6 strain samples give the element full rank (24 = 30 - 6 rigid modes, no hourglass
// modes); (4) its weights are positive, so W is a positive combination of psi at the points (the
// Neo-Hookean barrier psi = +inf for J <= 0 is checked at every point, and the PSD projection of
// dP/dF per point keeps the element stiffness PSD), which the degree-3 5-point rule (weight
// -4/5) would break.
//
// The gradient and stiffness reuse the material point evaluation of deform/kernels/fem_tet.h: at
// each point, dW/dx_i = w_q V P grad N_i and d^2W/dx_i dx_j = w_q V G_i^T (dP/dF) G_j.
#pragma once

#include <deform/geometry/organ_tets.h>
#include <deform/kernels/fem_tet.h>

#include <array>
#include <cmath>
#include <limits>

namespace deform::reference_fem {

using Vec30 = Eigen::Matrix<Real, 30, 1>;
using Mat30 = Eigen::Matrix<Real, 30, 30>;
using Mat3x10 = Eigen::Matrix<Real, 3, 10>;

/// Corner pairs of the midside nodes 4..9 (deform/geometry/organ_tets.h).
inline constexpr const int (&kQuadraticEdges)[6][2] = kQuadraticTetEdges;

/// Barycentric coordinates of the 4-point degree-2 rule (weights 1/4 each).
std::array<Vec4, 4> quadraticTetQuadrature();

/// Shape function values N_0..N_9 at barycentric coordinates L.
Eigen::Matrix<Real, 10, 1> quadraticShape(const Vec4& L);

/// Shape function gradients (1/m) as columns, from the P1 gradients g (columns g_0..g_3).
Mat3x10 quadraticShapeGradients(const Eigen::Matrix<Real, 3, 4>& g, const Vec4& L);

/// Rest data: the shape-function gradients at each quadrature point and the volume.
struct QuadraticTetRest {
  Real volume = 0;
  std::array<Mat3x10, 4> gradients;
};

/// From the corner rest data (valid when linear.volume > 0).
QuadraticTetRest makeQuadraticTetRest(const TetRest& linear);

/// Consistent integrals of the shape functions over the element, as fractions of its volume:
/// corners -1/20, midside nodes 1/5 (they sum to 1).
inline constexpr Real kQuadraticCornerShare = -1.0 / 20.0, kQuadraticMidsideShare = 1.0 / 5.0;
/// HRZ lumped mass fractions (Hinton, Rock & Zienkiewicz, "A note on mass lumping and related
/// processes in the finite element method", Earthquake Eng. Struct. Dyn. 4(3) 1976,
/// doi:10.1002/eqe.4290040305): the consistent mass diagonal (integral N_i^2 = V/70 at corners,
/// 8V/105 at midside nodes) scaled to the element mass: corners 1/36, midside nodes 4/27.
inline constexpr Real kQuadraticCornerMass = 1.0 / 36.0, kQuadraticMidsideMass = 4.0 / 27.0;

struct QuadraticTetEvaluation {
  Real energy = 0;  ///< J
  Vec30 gradient;   ///< N, dW/dx (node-major: 3 a + k)
  Mat30 stiffness;  ///< N/m
};

/// W, dW/dx and d^2W/dx^2 of one P2 tet at nodal positions x (columns x_0..x_9). energy is +inf
/// (and nothing else is filled) when psi is +inf at a quadrature point.
/// K += w G^T D G, the stiffness of one quadrature point of weight w (m^3) with shape gradients G
/// and stress derivative D = dP/dF (vec(F)(i + 3 j) = F(i, j)). vec(F)(i + 3 j) depends on
/// x_b(k) through delta_ik G(j, b): DG(r, 3 b + k) = sum_l D(r, k + 3 l) G(l, b), and
/// K(3 a + i, c) += w sum_j G(j, a) DG(i + 3 j, c): column c of K, read as a 3 x 10 matrix, gains
/// w V_c G with V_c column c of DG read as a 3 x 3 matrix (contiguous, no strided rows).
inline void addPointStiffness(const Mat9& D, const Mat3x10& G, Real w, Mat30& K) {
  Eigen::Matrix<Real, 9, 30> DG;
  for (int b = 0; b < 10; ++b)
    for (int k = 0; k < 3; ++k)
      DG.col(3 * b + k) = D.col(k) * G(0, b) + D.col(k + 3) * G(1, b) + D.col(k + 6) * G(2, b);
  const Mat3x10 wG = w * G;
  for (int c = 0; c < 30; ++c)
    Eigen::Map<Mat3x10>(K.col(c).data()).noalias() += Eigen::Map<const Mat3>(DG.col(c).data()) * wG;
}

template <class Material>
void evaluateQuadraticTet(const Material& material, const QuadraticTetRest& rest, const Mat3x10& x,
                          TetEvalMode mode, QuadraticTetEvaluation& out, bool projectSpd = false) {
  const Real w = rest.volume / 4.0;
  out.energy = 0;
  if (mode != TetEvalMode::Energy) out.gradient.setZero();
  if (mode == TetEvalMode::Stiffness) out.stiffness.setZero();
  for (int q = 0; q < 4; ++q) {
    const Mat3x10& G = rest.gradients[size_t(q)];
    const Mat3 F = x * G.transpose();
    const Real psi = material.energyDensity(F);
    if (!std::isfinite(psi)) {
      out.energy = std::numeric_limits<Real>::infinity();
      return;
    }
    out.energy += w * psi;
    if (mode == TetEvalMode::Energy) continue;
    const Mat3x10 PG = (w * material.stress(F)) * G;
    for (int a = 0; a < 10; ++a) out.gradient.segment<3>(3 * a) += PG.col(a);
    if (mode != TetEvalMode::Stiffness) continue;
    addPointStiffness(stressDerivativeAt(material, F, projectSpd), G, w, out.stiffness);
  }
}

}  // namespace deform::reference_fem
