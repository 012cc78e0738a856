// Mean-dilatation 10-node tetrahedra for nearly incompressible Neo-Hookean solids (P2-P0).
//
// Why. With psi = mu/2 (J^(-2/3) I1 - 3) + kappa/2 (J - 1)^2 and kappa >> mu (nu -> 1/2), the
// volumetric term asks J = 1 at every quadrature point: 4 constraints per tet against about 4
// displacement dofs per tet in a P2 mesh, so the discrete solution is over-stiff ("volumetric
// locking"; Cook's membrane at nu = 0.499 with plain P2 tets lands well below the converged tip
// displacement, tests/reference_fem/cooks_membrane_test.cpp).
//
// What. The volumetric term of each element acts on its volume instead of point by point:
//     W_e = V sum_q w_q mu/2 (J_q^(-2/3) I1_q - 3)  +  V kappa/2 (theta - 1)^2,
//     theta = v / V = sum_q w_q J_q,
// v the current element volume by the element's own 4-point rule (weights w_q = 1/4, see
// quadratic_tet.h), so there is one volume constraint per element. This is the mean-dilatation
// element (Nagtegaal, Parks & Rice, "On numerically accurate finite element solutions in the fully
// plastic range", CMAME 4(2) 1974, 153-177), in the finite-strain form of
// Simo, Taylor & Pister ("Variational and projection methods for the volume constraint in finite
// deformation elasto-plasticity", CMAME 51 1985, 177-208): the
// three-field Hu-Washizu element with an element-constant pressure and dilatation eliminated
// element by element, whose small-strain form is Hughes' B-bar ("Generalization of selective
// integration procedures to anisotropic and nonlinear media", IJNME 15(9) 1980,
// 1413-1418). As J^(-2/3) I1 is unchanged by a volumetric scaling of F, W_e is
// also the F-bar element of de Souza Neto, Peric, Dutko & Owen (IJSS 33(20-22) 1996,
// doi:10.1016/0020-7683(95)00259-6) with F-bar = (theta / J_q)^(1/3) F_q. It is still a potential
// (so Newton with a line search on it works unchanged), and it equals the displacement element
// when J is constant over the tet (a P1 field), so it passes the same patch tests.
//
// Derivatives (H_q = cof F_q = J_q F_q^(-T), dJ/dF = H, p = kappa (theta - 1)):
//     dW_e/dx_a = V sum_q w_q (P_iso(F_q) + p H_q) grad N_a(X_q),
//     d2W_e/dx dx = V sum_q w_q G_q^T (dP_iso/dF + p dH/dF)(F_q) G_q + V kappa b b^T,
//     b = sum_q w_q dJ_q/dx   (the element's dtheta/dx),
// G_q mapping the 30 node coordinates to vec(F_q). The b b^T part is PSD; the point parts are
// projected onto the PSD cone (eigenvalues clamped at 0) when a projected tangent is asked for, so
// the element tangent is then PSD.
#pragma once

#include "quadratic_tet.h"

#include <deform/kernels/fem_tet.h>

namespace deform::reference_fem {

/// Neo-Hookean with the mean-dilatation volumetric term (see the file comment).
struct MeanDilatationNeoHookean {
  NeoHookeanMaterial isochoric;  ///< the same material with zero bulk modulus
  Real kappa = 0;                ///< bulk modulus, Pa
  static MeanDilatationNeoHookean fromLame(const LameParameters& lame);
};

/// W_e, its gradient and (projected) stiffness for one P2 tet at nodal positions x (columns
/// x_0..x_9), into `out` as evaluateQuadraticTet does; energy +inf (nothing else filled) when
/// some J_q <= 0.
void evaluateMeanDilatationTet(const MeanDilatationNeoHookean& material,
                               const QuadraticTetRest& rest, const Mat3x10& x, TetEvalMode mode,
                               QuadraticTetEvaluation& out, bool projectSpd = false);

}  // namespace deform::reference_fem
