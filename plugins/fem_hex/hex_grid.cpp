#include "hex_grid.h"

#include "hex_element.h"

#include <algorithm>
#include <limits>

namespace deform::fem_hex {

HexGrid hexGridFromVoxels(const VoxelGrid& vox) {
  HexGrid g;
  g.cellSize = vox.cellSize;
  const Vec3i nd = vox.dims + Vec3i::Ones();
  auto cornerIndex = [&](const Vec3i& c) {
    return c.x() +
           static_cast<long long>(nd.x()) * (c.y() + static_cast<long long>(nd.y()) * c.z());
  };
  std::vector<long long> corners;
  corners.reserve(vox.cells.size() * 8);
  for (const Vec3i& c : vox.cells) {
    for (int a = 0; a < 8; ++a) corners.push_back(cornerIndex(c + hexCorner(a)));
  }
  std::sort(corners.begin(), corners.end());
  corners.erase(std::unique(corners.begin(), corners.end()), corners.end());
  g.nodes.resize(static_cast<Eigen::Index>(corners.size()), 3);
  for (size_t n = 0; n < corners.size(); ++n) {
    const long long id = corners[n];
    const Vec3i c(static_cast<int>(id % nd.x()), static_cast<int>((id / nd.x()) % nd.y()),
                  static_cast<int>(id / (static_cast<long long>(nd.x()) * nd.y())));
    g.nodes.row(n) = (vox.origin + vox.cellSize * c.cast<Real>()).transpose();
  }
  g.cells = vox.cells;
  g.hexes.resize(vox.cells.size());
  for (size_t e = 0; e < vox.cells.size(); ++e) {
    for (int a = 0; a < 8; ++a) {
      const long long id = cornerIndex(vox.cells[e] + hexCorner(a));
      g.hexes[e][a] =
          static_cast<int>(std::lower_bound(corners.begin(), corners.end(), id) - corners.begin());
    }
  }
  return g;
}

Embedding embedPoints(const HexGrid& grid, const VoxelGrid& vox, const MatX3& P) {
  Embedding emb;
  emb.nodeIds.resize(P.rows(), 8);
  emb.weights.resize(P.rows(), 8);
  std::vector<int> hexOfCell(vox.state.size(), -1);
  for (int e = 0; e < grid.numHexes(); ++e) hexOfCell[vox.linearIndex(grid.cells[e])] = e;
  const Real h = grid.cellSize;
  for (Eigen::Index i = 0; i < P.rows(); ++i) {
    const Vec3 p = P.row(i);
    const Vec3i c = vox.cellOf(p);
    int e = vox.contains(c) ? hexOfCell[vox.linearIndex(c)] : -1;
    if (e < 0) {
      ++emb.outsidePoints;
      Real best = std::numeric_limits<Real>::infinity();
      for (int k = 0; k < grid.numHexes(); ++k) {
        const Real d = (vox.cellBox(grid.cells[k]).center() - p).squaredNorm();
        if (d < best) best = d, e = k;
      }
    }
    const Vec3 lo = vox.cellBox(grid.cells[e]).lo;
    const Vec3 t = ((p - lo) / h).cwiseMax(0.0).cwiseMin(1.0);
    const Eigen::Matrix<Real, 8, 1> w = hexTrilinearWeights(t);
    for (int a = 0; a < 8; ++a) {
      emb.nodeIds(i, a) = grid.hexes[e][a];
      emb.weights(i, a) = w[a];
    }
  }
  return emb;
}

void evaluateEmbedding(const Embedding& e, const MatX3& x, MatX3& out) {
  for (Eigen::Index i = 0; i < e.nodeIds.rows(); ++i) {
    Vec3 p = Vec3::Zero();
    for (int a = 0; a < 8; ++a) p += e.weights(i, a) * x.row(e.nodeIds(i, a)).transpose();
    out.row(i) = p.transpose();
  }
}

}  // namespace deform::fem_hex
