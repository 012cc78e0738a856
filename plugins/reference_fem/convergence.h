// Mesh-convergence study of the reference FEM: the same static problem on successively finer tet
// meshes of the same surface, and a Richardson extrapolation of the surface displacement.
//
// Levels k = 0, 1, 2 have interior edge lengths h_k (h_0 > h_1 > h_2; the default element counts
// N, 2.8 N, 8 N give h ratios ~1.41). Surface vertex i is node i on every level, so the surface
// displacements u_k (#V by 3) are directly comparable. With d_01 = |u_0 - u_1| and
// d_12 = |u_1 - u_2| (max over vertices of the pointwise distance) and the ansatz
// u_k = u + C h_k^p, the observed order p solves (h_0^p - h_1^p) / (h_1^p - h_2^p) = d_01 / d_12
// (for equal ratios r: p = ln(d_01/d_12) / ln r), and the finest level's error is estimated as
// e_2 = d_12 h_2^p / (h_1^p - h_2^p) (Roache, "Quantification of uncertainty in computational fluid
// dynamics", Annu. Rev. Fluid Mech. 29, 1997, doi:10.1146/annurev.fluid.29.1.123). h_k is taken
// as (volume / #tets)^{1/3} of the mesh actually produced.
#pragma once

#include "fem_solver.h"

#include <deform/geometry/tet_mesher.h>

#include <functional>
#include <string>
#include <vector>

namespace deform::reference_fem {

struct ConvergenceLevel {
  long long elements = 0;
  long long nodes = 0;
  Real h = 0;                 ///< (V / #tets)^{1/3}, m
  Real peakDisplacement = 0;  ///< max over input surface vertices of |u|, m
  bool converged = false;     ///< Newton converged
  double meshSeconds = 0, solveSeconds = 0;
  MatX3 surfaceDisplacement;  ///< #V by 3, m
};

struct ConvergenceStudy {
  std::vector<ConvergenceLevel> levels;
  Real observedOrder = 0;   ///< p
  Real errorEstimate = 0;   ///< estimated max error of the finest level's surface displacement, m
  Real relativeError = 0;   ///< errorEstimate / peak displacement of the finest level
  bool asymptotic = false;  ///< 0.5 <= p <= 4 (monotone convergence in the asymptotic range)
  bool withinOnePercent = false;  ///< asymptotic && relativeError <= 0.01
  /// Why the extrapolation does not apply or is not trusted ("" when it is), as the harness's
  /// study words it (deform_harness/convergence.h): "not_refining", "levels_too_close" (a
  /// measured h ratio below 1.1), "coincide", "not_monotone" (d12 >= d01), "not_asymptotic".
  std::string reason;
};

/// Builds the load case for a given system (nodes 0..#V-1 are the input surface vertices; with
/// quadratic elements the midside nodes follow, see FemSystem::rest()).
using LoadCaseBuilder = std::function<LoadCase(const FemSystem&)>;

/// Meshes `surface` at each target element count (refining the surface edges with the interior,
/// see TetMeshOptions::refineSurface), solves the static problem from rest and estimates the
/// discretisation error. `excludeNear` lists points around which vertices closer than
/// `excludeRadius` are left out of the error (a point load is singular in 3D elasticity: the
/// displacement under it grows without bound as the mesh is refined).
ConvergenceStudy runConvergenceStudy(const SurfaceMesh& surface, const Material& material,
                                     MaterialModel model, const LoadCaseBuilder& loads,
                                     const std::vector<long long>& elementCounts,
                                     const SolveOptions& solve = {},
                                     const std::vector<Vec3>& excludeNear = {},
                                     Real excludeRadius = 0, const std::string& source = "",
                                     ElementOrder order = ElementOrder::Linear);

/// Richardson analysis of three already-solved levels (fills observedOrder and the estimates).
void richardson(ConvergenceStudy& study, const std::vector<char>& includeVertex);

/// Builds the study from meshes the caller made (e.g. structured meshes); mesh k must have the
/// compared points as its first `numSurface` nodes.
ConvergenceStudy runConvergenceStudyOnMeshes(const std::vector<TetMesh>& meshes, int numSurface,
                                             const Material& material, MaterialModel model,
                                             const LoadCaseBuilder& loads,
                                             const SolveOptions& solve = {},
                                             ElementOrder order = ElementOrder::Linear);

}  // namespace deform::reference_fem
