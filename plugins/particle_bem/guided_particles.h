// particle_bem: the run-time part of the surface-guided model (the paper's §5.2).
//
// Each step:
//  1. loads -> a sparse nodal traction vector P on the coarse surface: a force f on node k is
//     the traction p_k = f / A_k (A_k the lumped nodal area, so the resultant is exactly f); a
//     point force on the organ is a pressure patch (pressurePatchShares), by default projected
//     consistently onto the linear traction space (PatchTraction) and applied through its
//     precomputed displacement response;
//  2. surface computation U = M P summed over the loaded nodes' columns only (cost 9 N per
//     loaded node, not 9 N^2), eq. 6. A grasp prescribes the displacement u_g of its coarse
//     nodes: the tractions that produce it solve the small system M_gg p_g = u_g - M_gl p_l;
//  3. position correction: every particle is pulled towards its target X + U by a damped
//     virtual spring (the paper's "viscosity and creeping"), per unit mass
//        dv/dt = k (target - x) - c v,
//     integrated by backward Euler, which for one linear particle is exact to solve:
//        v' = (v + dt k (target - x)) / (1 + dt c + dt^2 k),  x' = x + dt v';
//  4. interpolation: each fine-surface vertex follows the displacement of the closest point p on
//     the coarse surface (barycentrics b_k on the closest coarse triangle, precomputed), either
//     linearly, u(p) = sum_k b_k u_k, or (SurfaceTransfer::Gradient, the default) with the
//     nodal displacement gradients D_k recovered from the one-ring (area-weighted mean of the
//     linear elements' gradients, Zienkiewicz-Zhu style) as a half-gradient Hermite blend
//        u(p) = sum_k b_k (u_k + 1/2 D_k (p - X_k)).
//     With exact gradients on a flat triangle this is exact for quadratic fields: the linear
//     interpolant errs by +1/2 sum_k b_k d_k^T H d_k (d_k = X_k - p) and the nodal first-order
//     extrapolations u_k + D_k (p - X_k) by -sum_k b_k d_k^T H d_k, so the half step cancels the
//     curvature term; a linear field is reproduced exactly (sum_k b_k (p - X_k) = 0). The mean
//     of the element gradients is exact for quadratics at a vertex whose one-ring is centrally
//     symmetric; on curved coarse surfaces it carries an O(h x dihedral angle) error.
#pragma once

#include "triangle_distance.h"

#include <deform/kernels/sparse.h>

#include <Eigen/LU>
#include <Eigen/SparseCholesky>
#include <memory>
#include <vector>

namespace deform::particle_bem {

/// A point force spread as a pressure patch of radius R around its surface point c (a tool's
/// contact area, the same physical patch on every mesh, so that surfaces of different resolution
/// carry the same traction field; a force on one node would load an element-sized area that
/// shrinks with refinement, around a displacement that is log-singular under a true point load):
///
///   t(x) = f w(x) / int w dGamma,   w(x) = max(0, 1 - |x - c|^2 / R^2)   (paraboloid),
///
/// as the nodal shares c_k = int N_k w dGamma / int w dGamma (sum_k c_k = 1: the resultant is f)
/// of the linear shape functions N_k over the triangles of s (rest positions), by the midpoint
/// rule on a regular subdivision of each triangle into sub-triangles of size at most R / 4.
/// Returns (node, c_k) pairs with c_k > 0, sorted by node; empty when no sample point lies within
/// R of c (R much smaller than the elements: the caller falls back to the closest triangle).
std::vector<std::pair<int, Real>> pressurePatchShares(const SurfaceMesh& s, const Vec3& c, Real R);

/// How a pressure patch's nodal shares c_k become nodal tractions p_k of the linear traction
/// space sum_k N_k p_k (both carry the resultant f exactly, since int N_k dGamma = A_k):
///  - Consistent (default): the L2 projection of the patch traction t = f w / int w onto that
///    space, i.e. the tractions whose linear field has the same nodal loads int N_k t = c_k f:
///        Mass q = c,   Mass_ij = int N_i N_j dGamma = A_e / 12 (1 + delta_ij) per triangle e,
///        p_k = q_k f  (q: traction per unit force, 1/m^2).
///    With ~2 cm elements under a 3 cm patch this is what the BEM right-hand side int U* t
///    needs: G p then equals int U* t up to the projection error (0.16% of the displacement on
///    the harness's 284-vertex liver, against 2.2% for the lumped form; history "Sixth pass");
///  - Lumped: p_k = c_k f / A_k (row-sum lumping of Mass): spreads the patch over every node it
///    touches, a wider load on coarse elements than on fine ones.
enum class PatchTraction { Consistent, Lumped };

/// Consistent surface mass matrix of linear triangles (#V x #V, m^2).
SparseMatrix surfaceMassMatrix(const SurfaceMesh& s);

/// The consistent projection: Mass factorised once per surface, solved per patch.
class PatchProjection {
 public:
  PatchProjection() = default;
  explicit PatchProjection(const SurfaceMesh& s);
  /// q (#V, 1/m^2) with Mass q = c for the shares c (pressurePatchShares); sum_k A_k q_k = 1.
  VecX tractionPerForce(const std::vector<std::pair<int, Real>>& shares) const;
  bool ok() const { return m_ok; }

 private:
  std::shared_ptr<const Eigen::SimplicialLDLT<SparseMatrix>> m_ldlt;  // not movable itself
  Eigen::Index m_n = 0;
  bool m_ok = false;
};

/// Fine vertex -> (coarse triangle, barycentric weights of its closest point).
struct SurfaceMap {
  std::vector<int> triangle;  ///< #fine
  MatX3 bary;                 ///< #fine by 3
};

SurfaceMap mapToSurface(const TriangleGrid& coarse, const MatX3& fine);

/// out_v = fineRest_v + sum_k bary_vk * coarseDisp_(F(tri_v, k)).
void interpolateDisplacement(const SurfaceMap& map, const MatX3i& coarseF, const MatX3& fineRest,
                             const MatX3& coarseDisp, MatX3& out);

/// How the fine surface follows the coarse one (step 4 above).
enum class SurfaceTransfer { Linear, Gradient };

/// Precomputed data of the gradient transfer.
struct GradientTransfer {
  using MatX9 = Eigen::Matrix<Real, Eigen::Dynamic, 9, Eigen::RowMajor>;  ///< rows contiguous
  MatX9 faceGrad;       ///< #coarse F x 9: grad N_0, grad N_1, grad N_2 of each face (1/m)
  MatX3 cornerWeight;   ///< #coarse F x 3: face area / total area around that corner's vertex
  MatX9 offsets;        ///< #fine x 9: 1/2 b_k (p - X_k) for the three corners k (m)
  std::vector<Mat3> D;  ///< workspace: recovered displacement gradient per coarse vertex
};

GradientTransfer makeGradientTransfer(const MatX3& coarseV, const MatX3i& coarseF,
                                      const SurfaceMap& map);

/// D_k = sum over faces f around k of w_fk sum_i u_(F(f,i)) grad N_i^T (3x3, D d = du).
void recoverGradients(const GradientTransfer& g, const MatX3i& coarseF, const MatX3& coarseDisp,
                      std::vector<Mat3>& D);

/// out_v = fineRest_v + sum_k (bary_vk coarseDisp_k + D_k offsets_vk), F = F(tri_v, k).
void interpolateDisplacement(const SurfaceMap& map, const MatX3i& coarseF, const MatX3& fineRest,
                             const MatX3& coarseDisp, GradientTransfer& g, MatX3& out);

/// Row v of the transfer's matrix J (fine vertex position = fineRest_v + sum_j J_vj u_j over the
/// coarse displacements u, the same scalar for x, y and z): the barycentric weights of its closest
/// coarse triangle, plus with the gradient transfer (g not null) the one-ring terms of the three
/// corners' recovered gradients, sum over faces f around corner c of
/// cornerWeight(f, c) (grad N_i(f) . offsets_vc) for each node i of f. Returns (node, J_vj)
/// pairs sorted by node, zeros dropped. The weights sum to 1 (the gradient terms to 0), so a
/// rigid translation moves the vertex with it.
std::vector<std::pair<int, Real>> transferRow(const SurfaceMap& map, const MatX3i& coarseF,
                                              const GradientTransfer* g, int v);

/// Sparse traction vector: loaded coarse nodes and their tractions (Pa).
struct SparseTraction {
  std::vector<int> nodes;
  std::vector<Vec3> values;
  void clear() {
    nodes.clear();
    values.clear();
  }
  /// Adds p at node (merging repeated nodes).
  void add(int node, const Vec3& p);
};

/// U += M P over the loaded columns (U: 3N).
void accumulateDisplacement(const MatX& M, const SparseTraction& P, VecX& U);

/// Tractions on the prescribed displacement components g that make U_g = target given the other
/// loads: M_gg p_g = target - (M P_other)_g. A component is a dof 3 node + axis: a grasped node
/// gives its three, a node under a sliding plate only the one along the plate's normal (no
/// tangential traction: frictionless). The LU of M_gg is cached by the caller (GraspSolver).
class GraspSolver {
 public:
  /// Returns false when M_gg is singular (e.g. every grasped node fixed).
  bool solve(const MatX& M, const std::vector<int>& dofs, const VecX& targetMinusOther,
             VecX& tractions);

 private:
  std::vector<int> m_dofs;
  Eigen::PartialPivLU<MatX> m_lu;
  bool m_ok = false;
};

/// One backward-Euler step of the damped virtual springs for particles not in `kinematic`.
void springCorrection(MatX3& x, MatX3& v, const MatX3& target, Real stiffness, Real damping,
                      Real dt, const std::vector<char>& kinematic);

}  // namespace deform::particle_bem
