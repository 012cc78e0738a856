// fem_hex kernels: a sparse grid of equal cubic hexahedra built from a voxelisation, and the
// trilinear embedding of surface points in it.
#pragma once

#include <deform/geometry/voxelize.h>

#include <array>
#include <vector>

namespace deform::fem_hex {

struct HexGrid {
  Real cellSize = 0;                      ///< m, edge of every hexahedron
  MatX3 nodes;                            ///< #N by 3 rest positions (m)
  std::vector<std::array<int, 8>> hexes;  ///< #E, node a at corner hexCorner(a) of the cell
  std::vector<Vec3i> cells;               ///< #E grid cell of each hexahedron
  int numNodes() const { return static_cast<int>(nodes.rows()); }
  int numHexes() const { return static_cast<int>(hexes.size()); }
};

/// One hexahedron per active voxel cell; nodes are the cells' distinct corners, numbered in
/// ascending (z, y, x) corner order (deterministic).
HexGrid hexGridFromVoxels(const VoxelGrid& voxels);

/// Trilinear embedding: point i = sum_a weights(i, a) * nodes(nodeIds(i, a)).
struct Embedding {
  Eigen::Matrix<int, Eigen::Dynamic, 8, Eigen::RowMajor> nodeIds;
  Eigen::Matrix<Real, Eigen::Dynamic, 8, Eigen::RowMajor> weights;
  int outsidePoints = 0;  ///< points not in an active cell (clamped into the nearest hex)
};

/// Embeds points P (#P by 3, m) in the hexahedron of the cell containing each; a point outside
/// every active cell (should not happen for the voxelised surface's own vertices) is embedded in
/// the nearest hexahedron with its local coordinates clamped to [0,1]^3, and counted.
Embedding embedPoints(const HexGrid& grid, const VoxelGrid& voxels, const MatX3& P);

/// Positions of embedded points (#P by 3) for current node positions x (#N by 3).
void evaluateEmbedding(const Embedding& e, const MatX3& x, MatX3& out);

}  // namespace deform::fem_hex
