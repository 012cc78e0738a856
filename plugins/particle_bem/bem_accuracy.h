// particle_bem: the paper's accuracy measure (§6, Table 2). The same load case is solved by the
// standard BEM on a fine surface (u^o_i at its vertices) and on the coarse surface, whose
// nodal displacements are interpolated to the fine vertices through the closest coarse triangle
// (u^imp_i, what the guided model shows). The accuracy loss ratio is
//   R = sum_i |u^o_i - u^imp_i| / sum_i |u^o_i|
// over the fine vertices. The load must be the same physical load on both meshes, so it is a
// smooth traction field t(x) = t0 exp(-|x - c|^2 / r^2) sampled at each mesh's nodes; the
// fixed region is the nodes inside a box on each mesh.
#pragma once

#include "bem_assembly.h"

#include <deform/mesh.h>
#include <deform/model.h>

namespace deform::particle_bem {

struct LossRatioCase {
  Vec3 center = Vec3::Zero();    ///< m
  Real radius = 0.02;            ///< m
  Vec3 traction = Vec3::Zero();  ///< Pa, peak
  Box fixedBox;                  ///< nodes inside are fixed
};

struct LossRatioResult {
  Real ratio = 0;
  int coarseVertices = 0, fineVertices = 0;
  Real meanFineDisplacement = 0;  ///< m
  Real maxFineDisplacement = 0;   ///< m
};

/// Nodal tractions (3N) of the case's field at the rows of V.
VecX gaussianTraction(const MatX3& V, const LossRatioCase& c);
/// Indices of the rows of V inside the box.
std::vector<int> nodesInBox(const MatX3& V, const Box& b);

LossRatioResult bemLossRatio(const SurfaceMesh& coarse, const SurfaceMesh& fine,
                             const Material& material, const LossRatioCase& c,
                             const BemQuadrature& q = {});

}  // namespace deform::particle_bem
