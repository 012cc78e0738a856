// particle_bem: the paper's accuracy measure (§6, Table 2). The same load case is solved by the
// standard BEM on a fine surface (u^o_i at its vertices) and on the coarse surface, whose
// nodal displacements are carried to the fine vertices through the closest coarse triangle
// (u^imp_i, what the guided model shows: by default the gradient transfer of
// guided_particles.h, the model's default `surface_transfer`). The accuracy loss ratio is
//   R = sum_i |u^o_i - u^imp_i| / sum_i |u^o_i|
// over the fine vertices. The load must be the same physical load on both meshes, so it is a
// smooth traction field t(x) = t0 exp(-|x - c|^2 / r^2) integrated over each mesh's elements
// (integrateTractionField: the right-hand side int U* t dGamma with the same quadrature on both
// meshes, so both carry the same resultant); sampling t at the nodes instead (G p with p the
// nodal values, the old measure) is kept as a second figure. The fixed region is the nodes
// inside a box on each mesh (as fixedNodeIndices does for the model) or, by default, each node
// constrained in proportion to the fraction of its support inside the box (solveBemPartial):
// with nodal clamps R is dominated by which nodes happen to lie just inside the box's edge on
// each mesh. The ratio can also be evaluated with the box's top face shifted by small offsets
// (edgeShifts) to show that sensitivity.
#pragma once

#include "bem_assembly.h"
#include "guided_particles.h"

#include <deform/sdk/mesh.h>
#include <deform/sdk/model.h>

namespace deform::particle_bem {

/// How the fixed region enters each mesh's BEM solve.
enum class FixedSupport {
  Partial,       ///< nodes constrained in proportion to their fixed fraction (solveBemPartial)
  Clamp,         ///< nodes in the box clamped, reaction over all their faces (fixedNodeIndices)
  SupportFaces,  ///< nodes in the box clamped, reaction on the support faces only
                 ///< (SupportColumns): the exact clamp on a surface conforming to the box
  SupportFacesSingular  ///< the same with the s^(-1/2) reaction on the support faces along
                        ///< the curve (singularSupport): the model's run time
};

struct LossRatioCase {
  Vec3 center = Vec3::Zero();    ///< m
  Real radius = 0.02;            ///< m
  Vec3 traction = Vec3::Zero();  ///< Pa, peak
  Box fixedBox;                  ///< nodes inside are fixed
  Real fieldResolution = 0;      ///< m; elements subdivided down to this (<= 0: radius / 4)
  FixedSupport support = FixedSupport::Partial;
  std::vector<Real> edgeShifts;  ///< m; extra ratios with fixedBox.hi.z moved by each shift
  SurfaceTransfer transfer = SurfaceTransfer::Gradient;  ///< coarse -> fine, as the model
  /// false: only LossRatioResult::ratio and its statistics (one solve per mesh); the other
  /// figures (each a further solve per mesh) stay 0
  bool variants = true;
};

struct LossRatioResult {
  Real ratio = 0;                  ///< field load, fixed region as LossRatioCase::support says
  Real ratioLinearTransfer = 0;    ///< `ratio` with the linear coarse -> fine transfer
  Real ratioGradientTransfer = 0;  ///< `ratio` with the gradient transfer
  /// `ratio`'s fine solution carried to the coarse vertices (linear, closest point) and back
  /// (linear / gradient transfer): what the transfer alone costs
  Real roundTripLinear = 0, roundTripGradient = 0;
  Real displacementRatio = 0;  ///< sum |u^imp| / sum |u^o| of `ratio` (< 1: coarse stiffer)
  Real ratioNodalClamp = 0;    ///< field load, nodes inside the box clamped
  Real ratioNodalLoad = 0;     ///< traction sampled at the nodes, nodes in the box clamped (old)
  Real ratioPartial = 0;       ///< field load, partial constraints (FixedSupport::Partial)
  /// field load, FixedSupport::SupportFaces (when `support` is SupportFacesSingular)
  Real ratioSupportFaces = 0;
  std::vector<Real> shiftedRatios;       ///< per edgeShifts, as `ratio`
  std::vector<Real> shiftedClampRatios;  ///< per edgeShifts, as `ratioNodalClamp`
  int coarseVertices = 0, fineVertices = 0;
  int coarseFixed = 0, fineFixed = 0;
  Real meanFineDisplacement = 0;  ///< m
  Real maxFineDisplacement = 0;   ///< m
};

/// Nodal tractions (3N) of the case's field at the rows of V.
VecX gaussianTraction(const MatX3& V, const LossRatioCase& c);

LossRatioResult bemLossRatio(const SurfaceMesh& coarse, const SurfaceMesh& fine,
                             const Material& material, const LossRatioCase& c,
                             const BemQuadrature& q = {});

}  // namespace deform::particle_bem
