#include "sph_elasticity.h"

#include "spatial_hash.h"

#include <Eigen/LU>
#include <algorithm>
#include <cmath>

namespace deform::particle_bem {

MlsElasticity initMlsElasticity(const MatX3& rest, Real h, const VecX& volume, Real E, Real nu,
                                long long* degenerate) {
  MlsElasticity m;
  m.h = h;
  m.volume = volume;
  lame(E, nu, m.lambda, m.mu);
  const int n = int(rest.rows());
  SpatialHash hash(h);
  hash.build(rest);
  const Real h2 = h * h, norm = 315.0 / (64.0 * M_PI * std::pow(h, 9));
  m.start.assign(n + 1, 0);
  m.dSum.assign(n, Vec3::Zero());
  m.valid.assign(n, 0);
  std::vector<std::pair<int, Real>> local;
  for (int i = 0; i < n; ++i) {
    local.clear();
    const Vec3 xi = rest.row(i);
    hash.forEachWithin(xi, h, [&](int j, Real dist) {
      if (j != i) local.emplace_back(j, norm * std::pow(h2 - dist * dist, 3));
    });
    std::sort(local.begin(), local.end());  // deterministic order whatever the hash layout
    Mat3 A = Mat3::Zero();
    for (const auto& [j, w] : local) {
      const Vec3 xij = rest.row(j).transpose() - xi;
      A += w * xij * xij.transpose();
    }
    // Singular moment matrix: fewer than three independent directions among the neighbours.
    const Eigen::FullPivLU<Mat3> lu(A);
    const bool ok = local.size() >= 3 && lu.rank() == 3 &&
                    std::abs(A.determinant()) > 1e-12 * std::pow(A.norm(), 3);
    m.valid[i] = ok;
    if (!ok && degenerate) ++*degenerate;
    const Mat3 Ainv = ok ? Mat3(lu.inverse()) : Mat3::Zero();
    for (const auto& [j, w] : local) {
      const Vec3 dij = Ainv * (rest.row(j).transpose() - xi) * w;
      m.nbr.push_back(j);
      m.d.push_back(dij);
      m.dSum[i] += dij;
    }
    m.start[i + 1] = int(m.nbr.size());
  }
  return m;
}

void mlsDeformationGradients(const MlsElasticity& m, const MatX3& rest, const MatX3& x,
                             std::vector<Mat3>& F) {
  const int n = int(x.rows());
  F.resize(n);
  for (int i = 0; i < n; ++i) {
    Mat3 G = Mat3::Zero();
    if (m.valid[i]) {
      const Vec3 ui = (x.row(i) - rest.row(i)).transpose();
      for (int t = m.start[i]; t < m.start[i + 1]; ++t) {
        const int j = m.nbr[t];
        G += ((x.row(j) - rest.row(j)).transpose() - ui) * m.d[t].transpose();
      }
    }
    F[i] = Mat3::Identity() + G;
  }
}

Mat3 hookeStress(const Mat3& F, Real lambda, Real mu) {
  const Mat3 E = 0.5 * (F.transpose() * F - Mat3::Identity());
  return lambda * E.trace() * Mat3::Identity() + 2 * mu * E;
}

void mlsForces(const MlsElasticity& m, const std::vector<Mat3>& F, MatX3& forces) {
  const int n = int(F.size());
  forces.setZero(n, 3);
  for (int i = 0; i < n; ++i) {
    if (!m.valid[i]) continue;
    const Mat3 P = m.volume[i] * F[i] * hookeStress(F[i], m.lambda, m.mu);
    forces.row(i) += (P * m.dSum[i]).transpose();
    for (int t = m.start[i]; t < m.start[i + 1]; ++t)
      forces.row(m.nbr[t]) -= (P * m.d[t]).transpose();
  }
}

Real mlsEnergy(const MlsElasticity& m, const std::vector<Mat3>& F) {
  Real e = 0;
  for (size_t i = 0; i < F.size(); ++i) {
    if (!m.valid[i]) continue;
    const Mat3 E = 0.5 * (F[i].transpose() * F[i] - Mat3::Identity());
    e += 0.5 * m.volume[i] * (E.cwiseProduct(hookeStress(F[i], m.lambda, m.mu))).sum();
  }
  return e;
}

}  // namespace deform::particle_bem
