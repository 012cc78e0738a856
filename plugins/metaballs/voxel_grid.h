// Metaballs plugin: the organ's voxelisation for stage 1 (inside voxel centres as packing samples)
// and stage 5 (Algorithm 2, "voxelize model"), on the shared voxeliser
// (deform/geometry/voxelize.h). Grid: `resolution` voxels along the longest side of the surface's
// bounding box, one voxel of margin on each side, centred on the box. A voxel is "inside" when its
// centre is (VoxelGrid::centreInside, winding number), whether or not the surface crosses the
// voxel: the electrostatic model counts hollow space by voxel centres.
#pragma once

#include <deform/geometry/voxelize.h>

namespace deform::metaballs {

/// Voxel size h = longest bounding-box side / resolution; dims = ceil(size / h) + 2 per axis.
VoxelGrid voxelizeInside(const SurfaceMesh& surface, int resolution);

/// Centre of the voxel with linear index v (m).
inline Vec3 voxelCenter(const VoxelGrid& g, long long v) {
  return g.cellCenter(g.cellAt(v));
}

}  // namespace deform::metaballs
