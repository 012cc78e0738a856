#include "voxel_grid.h"

#include <algorithm>
#include <cmath>

namespace deform::metaballs {

long long VoxelGrid::numInside() const {
  long long n = 0;
  for (uint8_t v : inside) n += v;
  return n;
}

VoxelGrid voxelizeInside(const MeshDistance& dist, int resolution) {
  const Box box = boundingBox(dist.mesh().V);
  VoxelGrid g;
  g.h = box.size().maxCoeff() / std::max(resolution, 1);
  const Vec3 size = box.size();
  g.nx = int(std::ceil(size.x() / g.h)) + 2;
  g.ny = int(std::ceil(size.y() / g.h)) + 2;
  g.nz = int(std::ceil(size.z() / g.h)) + 2;
  // Centre the grid on the box.
  const Vec3 extent = g.h * Vec3(g.nx - 1, g.ny - 1, g.nz - 1);
  g.origin = box.center() - 0.5 * extent;
  g.inside.assign(size_t(g.nx) * size_t(g.ny) * size_t(g.nz), 0);
  for (int k = 0; k < g.nz; ++k) {
    for (int j = 0; j < g.ny; ++j) {
      int i = 0;
      while (i < g.nx) {
        const Real s = dist.signedDistance(g.center(i, j, k));
        const uint8_t in = s < 0 ? 1 : 0;
        // |s| bounds the distance to the surface: cells within |s| along the row share the sign.
        const int skip = std::max(1, int(std::floor(std::abs(s) / g.h)));
        const int last = std::min(g.nx, i + skip);
        for (int ii = i; ii < last; ++ii) g.inside[size_t(g.index(ii, j, k))] = in;
        i = last;
      }
    }
  }
  return g;
}

}  // namespace deform::metaballs
