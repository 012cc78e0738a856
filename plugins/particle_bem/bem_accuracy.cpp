#include "bem_accuracy.h"

#include "guided_particles.h"

#include <cmath>

namespace deform::particle_bem {

VecX gaussianTraction(const MatX3& V, const LossRatioCase& c) {
  VecX p = VecX::Zero(3 * V.rows());
  for (Eigen::Index j = 0; j < V.rows(); ++j) {
    const Real d2 = (V.row(j).transpose() - c.center).squaredNorm();
    p.segment<3>(3 * j) = c.traction * std::exp(-d2 / (c.radius * c.radius));
  }
  return p;
}

std::vector<int> nodesInBox(const MatX3& V, const Box& b) {
  std::vector<int> out;
  for (Eigen::Index j = 0; j < V.rows(); ++j)
    if (b.contains(V.row(j).transpose())) out.push_back(int(j));
  return out;
}

LossRatioResult bemLossRatio(const SurfaceMesh& coarse, const SurfaceMesh& fine,
                             const Material& material, const LossRatioCase& c,
                             const BemQuadrature& q) {
  LossRatioResult r;
  r.coarseVertices = coarse.numVertices();
  r.fineVertices = fine.numVertices();
  const auto solve = [&](const SurfaceMesh& s) {
    const BemMatrices bem = assembleBem(s, material.young, material.poisson, q);
    return solveBem(bem, s, nodesInBox(s.V, c.fixedBox), gaussianTraction(s.V, c));
  };
  const VecX uf = solve(fine), uc = solve(coarse);
  MatX3 coarseDisp(coarse.numVertices(), 3);
  for (int j = 0; j < coarse.numVertices(); ++j) coarseDisp.row(j) = uc.segment<3>(3 * j);
  const TriangleGrid grid(coarse.V, coarse.F);
  const SurfaceMap map = mapToSurface(grid, fine.V);
  MatX3 interp;
  interpolateDisplacement(map, coarse.F, MatX3::Zero(fine.numVertices(), 3), coarseDisp, interp);
  Real num = 0, den = 0;
  for (int v = 0; v < fine.numVertices(); ++v) {
    const Vec3 uo = uf.segment<3>(3 * v);
    num += (uo - interp.row(v).transpose()).norm();
    den += uo.norm();
    r.maxFineDisplacement = std::max(r.maxFineDisplacement, uo.norm());
  }
  r.ratio = den > 0 ? num / den : 0;
  r.meanFineDisplacement = den / std::max(1, fine.numVertices());
  return r;
}

}  // namespace deform::particle_bem
