#include "guided_particles.h"

#include <algorithm>
#include <cmath>
#include <map>

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

GradientTransfer makeGradientTransfer(const MatX3& coarseV, const MatX3i& coarseF,
                                      const SurfaceMap& map) {
  GradientTransfer g;
  const Eigen::Index nf = coarseF.rows();
  g.faceGrad = GradientTransfer::MatX9::Zero(nf, 9);
  g.cornerWeight = MatX3::Zero(nf, 3);
  VecX area = VecX::Zero(nf), around = VecX::Zero(coarseV.rows());
  for (Eigen::Index f = 0; f < nf; ++f) {
    Vec3 x[3];
    for (int k = 0; k < 3; ++k) x[k] = coarseV.row(coarseF(f, k)).transpose();
    const Vec3 n = (x[1] - x[0]).cross(x[2] - x[0]);
    const Real a2 = n.norm();
    if (!(a2 > 0)) continue;  // degenerate face: no gradient, no weight
    area[f] = 0.5 * a2;
    // grad N_i = n x (x_(i+2) - x_(i+1)) / (2A) with n the unit normal.
    for (int i = 0; i < 3; ++i)
      g.faceGrad.block<1, 3>(f, 3 * i) =
          (n.cross(x[(i + 2) % 3] - x[(i + 1) % 3]) / (a2 * a2)).transpose();
    for (int k = 0; k < 3; ++k) around[coarseF(f, k)] += area[f];
  }
  for (Eigen::Index f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const Real s = around[coarseF(f, k)];
      g.cornerWeight(f, k) = s > 0 ? area[f] / s : 0;
    }
  const Eigen::Index nv = Eigen::Index(map.triangle.size());
  g.offsets.resize(nv, 9);
  for (Eigen::Index v = 0; v < nv; ++v) {
    const int t = map.triangle[v];
    Vec3 p = Vec3::Zero();
    for (int k = 0; k < 3; ++k) p += map.bary(v, k) * coarseV.row(coarseF(t, k)).transpose();
    for (int k = 0; k < 3; ++k)
      g.offsets.block<1, 3>(v, 3 * k) =
          0.5 * map.bary(v, k) * (p - coarseV.row(coarseF(t, k)).transpose()).transpose();
  }
  g.D.assign(coarseV.rows(), Mat3::Zero());
  return g;
}

void recoverGradients(const GradientTransfer& g, const MatX3i& coarseF, const MatX3& coarseDisp,
                      std::vector<Mat3>& D) {
  D.assign(coarseDisp.rows(), Mat3::Zero());
  for (Eigen::Index f = 0; f < coarseF.rows(); ++f) {
    Mat3 Df = Mat3::Zero();
    for (int i = 0; i < 3; ++i)
      Df.noalias() += coarseDisp.row(coarseF(f, i)).transpose() * g.faceGrad.block<1, 3>(f, 3 * i);
    for (int k = 0; k < 3; ++k) D[coarseF(f, k)] += g.cornerWeight(f, k) * Df;
  }
}

void interpolateDisplacement(const SurfaceMap& map, const MatX3i& coarseF, const MatX3& fineRest,
                             const MatX3& coarseDisp, GradientTransfer& g, MatX3& out) {
  recoverGradients(g, coarseF, coarseDisp, g.D);
  out.resize(fineRest.rows(), 3);
  for (Eigen::Index v = 0; v < fineRest.rows(); ++v) {
    const int t = map.triangle[v];
    Vec3 u = fineRest.row(v).transpose();
    for (int k = 0; k < 3; ++k) {
      const int c = coarseF(t, k);
      u += map.bary(v, k) * coarseDisp.row(c).transpose() +
           g.D[c] * g.offsets.block<1, 3>(v, 3 * k).transpose();
    }
    out.row(v) = u.transpose();
  }
}

std::vector<std::pair<int, Real>> transferRow(const SurfaceMap& map, const MatX3i& coarseF,
                                              const GradientTransfer* g, int v) {
  std::map<int, Real> row;
  const int t = map.triangle[size_t(v)];
  for (int k = 0; k < 3; ++k) row[coarseF(t, k)] += map.bary(v, k);
  if (g) {
    // D_c offsets_vc = sum_f w_fc sum_i u_(F(f,i)) (grad N_i(f) . offsets_vc), f around c.
    for (int k = 0; k < 3; ++k) {
      const int c = coarseF(t, k);
      const Vec3 off = g->offsets.block<1, 3>(v, 3 * k).transpose();
      for (Eigen::Index f = 0; f < coarseF.rows(); ++f)
        for (int kc = 0; kc < 3; ++kc) {
          if (coarseF(f, kc) != c || g->cornerWeight(f, kc) == 0) continue;
          for (int i = 0; i < 3; ++i)
            row[coarseF(f, i)] +=
                g->cornerWeight(f, kc) * g->faceGrad.block<1, 3>(f, 3 * i).dot(off.transpose());
        }
    }
  }
  std::vector<std::pair<int, Real>> out;
  for (const auto& [node, w] : row)
    if (w != 0) out.emplace_back(node, w);
  return out;
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

bool GraspSolver::solve(const MatX& M, const std::vector<int>& dofs, const VecX& rhs,
                        VecX& tractions) {
  if (dofs != m_dofs) {
    m_dofs = dofs;
    const int g = int(dofs.size());
    MatX Mgg(g, g);
    for (int a = 0; a < g; ++a)
      for (int b = 0; b < g; ++b) Mgg(a, b) = M(dofs[a], dofs[b]);
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

std::vector<std::pair<int, Real>> pressurePatchShares(const SurfaceMesh& s, const Vec3& c, Real R) {
  std::map<int, Real> share;
  Real total = 0;
  if (!(R > 0)) return {};
  const Real R2 = R * R;
  for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
    const Vec3 v[3] = {s.V.row(s.F(f, 0)).transpose(), s.V.row(s.F(f, 1)).transpose(),
                       s.V.row(s.F(f, 2)).transpose()};
    // Skip triangles whose bounding sphere (about the centroid) misses the patch.
    const Vec3 g = (v[0] + v[1] + v[2]) / 3;
    const Real rg = std::max({(v[0] - g).norm(), (v[1] - g).norm(), (v[2] - g).norm()});
    if ((g - c).norm() > R + rg) continue;
    const Real area = 0.5 * (v[1] - v[0]).cross(v[2] - v[0]).norm();
    if (!(area > 0)) continue;
    const Real longest =
        std::max({(v[1] - v[0]).norm(), (v[2] - v[1]).norm(), (v[0] - v[2]).norm()});
    const int n = std::clamp(static_cast<int>(std::ceil(4 * longest / R)), 1, 64);
    const Real subArea = area / (Real(n) * n);
    // Sub-triangle centroids in lattice coordinates (a, b) -> barycentrics (1 - a/n - b/n, a/n,
    // b/n): n(n+1)/2 upward ones at (i + 1/3, j + 1/3), n(n-1)/2 downward at (i + 2/3, j + 2/3).
    const auto sample = [&](Real a, Real b) {
      const Real b1 = a / n, b2 = b / n, b0 = 1 - b1 - b2;
      const Vec3 x = b0 * v[0] + b1 * v[1] + b2 * v[2];
      const Real w = 1 - (x - c).squaredNorm() / R2;
      if (!(w > 0)) return;
      const Real ww = w * subArea;
      total += ww;
      share[s.F(f, 0)] += b0 * ww;
      share[s.F(f, 1)] += b1 * ww;
      share[s.F(f, 2)] += b2 * ww;
    };
    for (int i = 0; i < n; ++i)
      for (int j = 0; i + j < n; ++j) {
        sample(i + Real(1) / 3, j + Real(1) / 3);
        if (i + j < n - 1) sample(i + Real(2) / 3, j + Real(2) / 3);
      }
  }
  std::vector<std::pair<int, Real>> out;
  if (!(total > 0)) return out;
  for (const auto& [node, w] : share)
    if (w > 0) out.emplace_back(node, w / total);
  return out;
}

SparseMatrix surfaceMassMatrix(const SurfaceMesh& s) {
  std::vector<Triplet> t;
  t.reserve(9 * size_t(s.numFaces()));
  for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
    const Vec3 a = s.V.row(s.F(f, 0)).transpose(), b = s.V.row(s.F(f, 1)).transpose(),
               c = s.V.row(s.F(f, 2)).transpose();
    const Real area = 0.5 * (b - a).cross(c - a).norm();
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j)
        t.emplace_back(s.F(f, i), s.F(f, j), area / 12 * (i == j ? 2 : 1));
  }
  SparseMatrix m(s.numVertices(), s.numVertices());
  m.setFromTriplets(t.begin(), t.end());
  return m;
}

PatchProjection::PatchProjection(const SurfaceMesh& s) : m_n(s.numVertices()) {
  auto ldlt = std::make_shared<Eigen::SimplicialLDLT<SparseMatrix>>(surfaceMassMatrix(s));
  m_ok = ldlt->info() == Eigen::Success;
  m_ldlt = std::move(ldlt);
}

VecX PatchProjection::tractionPerForce(const std::vector<std::pair<int, Real>>& shares) const {
  VecX c = VecX::Zero(m_n);
  for (const auto& [node, share] : shares) c[node] += share;
  if (!m_ok) return VecX::Zero(m_n);
  return m_ldlt->solve(c);
}

}  // namespace deform::particle_bem
