#include "guided_particles.h"

#include <cmath>

namespace deform::particle_bem {

SurfaceMap mapToSurface(const TriangleGrid& coarse, const MatX3& fine) {
  SurfaceMap m;
  m.triangle.resize(fine.rows());
  m.bary.resize(fine.rows(), 3);
  for (Eigen::Index v = 0; v < fine.rows(); ++v) {
    const ClosestPoint cp = coarse.closest(fine.row(v).transpose());
    m.triangle[v] = cp.triangle;
    m.bary.row(v) = cp.bary.transpose();
  }
  return m;
}

void interpolateDisplacement(const SurfaceMap& map, const MatX3i& coarseF, const MatX3& fineRest,
                             const MatX3& coarseDisp, MatX3& out) {
  out.resize(fineRest.rows(), 3);
  for (Eigen::Index v = 0; v < fineRest.rows(); ++v) {
    const int t = map.triangle[v];
    out.row(v) = fineRest.row(v) + map.bary(v, 0) * coarseDisp.row(coarseF(t, 0)) +
                 map.bary(v, 1) * coarseDisp.row(coarseF(t, 1)) +
                 map.bary(v, 2) * coarseDisp.row(coarseF(t, 2));
  }
}

void SparseTraction::add(int node, const Vec3& p) {
  for (size_t k = 0; k < nodes.size(); ++k)
    if (nodes[k] == node) {
      values[k] += p;
      return;
    }
  nodes.push_back(node);
  values.push_back(p);
}

void accumulateDisplacement(const MatX& M, const SparseTraction& P, VecX& U) {
  for (size_t k = 0; k < P.nodes.size(); ++k)
    U.noalias() += M.middleCols<3>(3 * P.nodes[k]) * P.values[k];
}

bool GraspSolver::solve(const MatX& M, const std::vector<int>& nodes, const VecX& rhs,
                        VecX& tractions) {
  if (nodes != m_nodes) {
    m_nodes = nodes;
    const int g = int(nodes.size());
    MatX Mgg(3 * g, 3 * g);
    for (int a = 0; a < g; ++a)
      for (int b = 0; b < g; ++b)
        Mgg.block<3, 3>(3 * a, 3 * b) = M.block<3, 3>(3 * nodes[a], 3 * nodes[b]);
    m_lu.compute(Mgg);
    // Partial-pivot LU cannot report rank; a tiny |det| relative to the scale flags singular.
    const Real scale = Mgg.cwiseAbs().maxCoeff();
    m_ok = g > 0 && scale > 0 && std::isfinite(m_lu.determinant()) &&
           m_lu.matrixLU().diagonal().cwiseAbs().minCoeff() > 1e-12 * scale;
  }
  if (!m_ok) return false;
  tractions = m_lu.solve(rhs);
  return tractions.allFinite();
}

void springCorrection(MatX3& x, MatX3& v, const MatX3& target, Real stiffness, Real damping,
                      Real dt, const std::vector<char>& kinematic) {
  const Real denom = 1 / (1 + dt * damping + dt * dt * stiffness);
  for (Eigen::Index i = 0; i < x.rows(); ++i) {
    if (kinematic[i]) continue;
    v.row(i) = (v.row(i) + dt * stiffness * (target.row(i) - x.row(i))) * denom;
    x.row(i) += dt * v.row(i);
  }
}

}  // namespace deform::particle_bem
