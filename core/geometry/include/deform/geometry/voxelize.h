// deformbench SDK: voxelisation of a closed triangle surface into a regular grid of cubic cells.
//
// A cell is "crossing" when a surface triangle overlaps its closed box (separating-axis test,
// Akenine-Möller 2001, "Fast 3D triangle-box overlap testing", J. Graphics Tools 6(1)), and
// "inside" when it crosses no triangle and its centre is inside the surface. Inside-ness is the
// winding number along +x rays through the cell centres of each grid row:
//   w(p) = sum over triangles t crossed by the ray ending at p of -sign(n_t · e_x),
// counted with a symbolically perturbed point-in-triangle test whose per-edge orientation is
// evaluated once per undirected edge (by ascending vertex index), so that a ray through a shared
// edge or vertex is counted exactly once on a closed mesh (no double or missed crossing).
// p is inside when w(p) != 0 (so inward- or outward-oriented closed meshes both work).
//
// Used by the hexahedral FEM (the grid of hexahedra) and the metaballs construction (inside voxel
// centres as packing samples and for the electrostatic optimisation, on its own grid through
// voxelizeGrid and centreInside).
#pragma once

#include <deform/sdk/mesh.h>

#include <cstdint>
#include <vector>

namespace deform {

enum class CellState : std::uint8_t { Outside = 0, Crossing = 1, Inside = 2 };

struct VoxelGrid {
  Vec3 origin = Vec3::Zero();  ///< m, lower corner of cell (0,0,0)
  Real cellSize = 0;           ///< m, edge length h of every cell
  Vec3i dims = Vec3i::Zero();  ///< number of cells along x, y, z
  /// dims.prod() states, cell (i,j,k) at i + dims.x*(j + dims.y*k).
  std::vector<CellState> state;
  /// #C by 3 cells intersecting the organ (Crossing or Inside), in ascending linear index.
  std::vector<Vec3i> cells;
  /// dims.prod() flags, same indexing as state: 1 when the cell's centre is inside the surface
  /// (winding number != 0), for every cell whatever its state (the centre of a Crossing cell may
  /// lie on either side).
  std::vector<std::uint8_t> centreInside;

  long long linearIndex(const Vec3i& c) const {
    return c.x() +
           static_cast<long long>(dims.x()) * (c.y() + static_cast<long long>(dims.y()) * c.z());
  }
  CellState at(const Vec3i& c) const { return state[linearIndex(c)]; }
  bool contains(const Vec3i& c) const {
    return (c.array() >= 0).all() && (c.array() < dims.array()).all();
  }
  /// Cell containing p (floor of (p - origin)/h), not clamped.
  Vec3i cellOf(const Vec3& p) const;
  Box cellBox(const Vec3i& c) const;
  /// Centre of cell c: origin + h (c + 1/2).
  Vec3 cellCenter(const Vec3i& c) const;
  /// Cell of a linear index (inverse of linearIndex).
  Vec3i cellAt(long long index) const;
  int numCells() const { return static_cast<int>(cells.size()); }
  int numInside() const;               ///< cells fully inside the surface
  int numCrossing() const;             ///< cells the surface passes through
  long long numCentresInside() const;  ///< cells whose centre is inside (centreInside)
};

/// Voxelises a closed surface with cells of edge cellSize (m). The grid is centred on the surface's
/// bounding box with at least a fraction of a cell of margin on every side, so every surface
/// vertex lies strictly inside a Crossing cell. Throws InputError for an empty mesh, cellSize <= 0
/// or a grid of more than maxGridCells cells.
VoxelGrid voxelize(const SurfaceMesh& surface, Real cellSize, long long maxGridCells = 200000000);

/// Voxelises a closed surface on a grid the caller chooses: lower corner origin (m), cubic cells of
/// edge cellSize (m), dims cells along x, y, z (the grid need not contain the whole surface; cells
/// outside it are simply not represented). Same classification as voxelize(). Throws InputError
/// for an empty mesh, cellSize <= 0, dims < 1 or more than maxGridCells cells.
VoxelGrid voxelizeGrid(const SurfaceMesh& surface, const Vec3& origin, Real cellSize,
                       const Vec3i& dims, long long maxGridCells = 200000000);

/// Number of cells voxelize() would mark Crossing or Inside.
long long voxelCount(const SurfaceMesh& surface, Real cellSize);

/// Cell size (m) whose voxelisation has the count nearest to targetCells, found by bisection on the
/// cell size (the count is a non-increasing staircase in h, up to grid-alignment jitter).
/// Deterministic. Throws InputError for targetCells < 1.
Real cellSizeForCount(const SurfaceMesh& surface, long long targetCells, int iterations = 40);

/// Whether the closed box [boxCenter - halfSize, boxCenter + halfSize] and triangle (a, b, c)
/// overlap (separating-axis theorem, 13 axes).
bool triangleBoxOverlap(const Vec3& boxCenter, const Vec3& halfSize, const Vec3& a, const Vec3& b,
                        const Vec3& c);

}  // namespace deform
