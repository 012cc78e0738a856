// particle_bem: the run-time part of the surface-guided model (the paper's §5.2).
//
// Each step:
//  1. loads -> a sparse nodal traction vector P on the coarse surface: a force f on node k is
//     the traction p_k = f / A_k (A_k the lumped nodal area, so the resultant is exactly f);
//  2. surface computation U = M P summed over the loaded nodes' columns only (cost 9 N per
//     loaded node, not 9 N^2), eq. 6. A grasp prescribes the displacement u_g of its coarse
//     nodes: the tractions that produce it solve the small system M_gg p_g = u_g - M_gl p_l;
//  3. position correction: every particle is pulled towards its target X + U by a damped
//     virtual spring (the paper's "viscosity and creeping"), per unit mass
//        dv/dt = k (target - x) - c v,
//     integrated by backward Euler, which for one linear particle is exact to solve:
//        v' = (v + dt k (target - x)) / (1 + dt c + dt^2 k),  x' = x + dt v';
//  4. interpolation: each fine-surface vertex follows the displacement of the closest point on
//     the coarse surface (barycentric on the closest coarse triangle, precomputed).
#pragma once

#include "triangle_distance.h"

#include <Eigen/LU>
#include <vector>

namespace deform::particle_bem {

/// Fine vertex -> (coarse triangle, barycentric weights of its closest point).
struct SurfaceMap {
  std::vector<int> triangle;  ///< #fine
  MatX3 bary;                 ///< #fine by 3
};

SurfaceMap mapToSurface(const TriangleGrid& coarse, const MatX3& fine);

/// out_v = fineRest_v + sum_k bary_vk * coarseDisp_(F(tri_v, k)).
void interpolateDisplacement(const SurfaceMap& map, const MatX3i& coarseF, const MatX3& fineRest,
                             const MatX3& coarseDisp, MatX3& out);

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

/// Tractions at the grasped nodes g (3 per node) that make U_g = target given the other loads:
/// M_gg p_g = target - (M P_other)_g. The LU of M_gg is cached by the caller (GraspSolver).
class GraspSolver {
 public:
  /// Returns false when M_gg is singular (e.g. every grasped node fixed).
  bool solve(const MatX& M, const std::vector<int>& nodes, const VecX& targetMinusOther,
             VecX& tractions);

 private:
  std::vector<int> m_nodes;
  Eigen::PartialPivLU<MatX> m_lu;
  bool m_ok = false;
};

/// One backward-Euler step of the damped virtual springs for particles not in `kinematic`.
void springCorrection(MatX3& x, MatX3& v, const MatX3& target, Real stiffness, Real damping,
                      Real dt, const std::vector<char>& kinematic);

}  // namespace deform::particle_bem
