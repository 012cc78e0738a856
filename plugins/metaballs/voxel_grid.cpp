#include "voxel_grid.h"

#include <algorithm>
#include <cmath>

namespace deform::metaballs {

VoxelGrid voxelizeInside(const SurfaceMesh& surface, int resolution) {
  const Box box = boundingBox(surface.V);
  const Vec3 size = box.size();
  const Real h = size.maxCoeff() / std::max(resolution, 1);
  const Vec3i dims(int(std::ceil(size.x() / h)) + 2, int(std::ceil(size.y() / h)) + 2,
                   int(std::ceil(size.z() / h)) + 2);
  // Lower corner such that the grid is centred on the box.
  const Vec3 origin = box.center() - 0.5 * h * dims.cast<Real>();
  return voxelizeGrid(surface, origin, h, dims);
}

}  // namespace deform::metaballs
