// Metaballs plugin: a small inside/outside voxel grid of the organ, used by the adaptive sphere
// selection (volume samples) and by the electrostatic optimisation (Algorithm 2, "voxelize
// model"). Temporary and local to this plugin until the shared voxeliser
// (core/include/deform/voxelize.h) lands; only the inside/outside test of each voxel centre is
// needed here.
#pragma once

#include <deform/distance.h>

#include <cstdint>
#include <vector>

namespace deform::metaballs {

struct VoxelGrid {
  Vec3 origin = Vec3::Zero();  ///< centre of voxel (0,0,0), m
  Real h = 0;                  ///< voxel edge length, m
  int nx = 0, ny = 0, nz = 0;
  std::vector<uint8_t> inside;  ///< nx*ny*nz flags, x fastest: 1 when the centre is inside

  int index(int i, int j, int k) const { return i + nx * (j + ny * k); }
  Vec3 center(int i, int j, int k) const { return origin + h * Vec3(i, j, k); }
  Vec3 centerOf(int idx) const { return center(idx % nx, (idx / nx) % ny, idx / (nx * ny)); }
  long long numInside() const;
};

/// Voxelises the closed surface behind `dist` with `resolution` voxels along the longest side of
/// its bounding box (plus one voxel of margin each side). Inside = negative signed distance at the
/// voxel centre; along each x row a centre farther than one voxel from the surface decides its
/// neighbours' sign without a query.
VoxelGrid voxelizeInside(const MeshDistance& dist, int resolution);

}  // namespace deform::metaballs
