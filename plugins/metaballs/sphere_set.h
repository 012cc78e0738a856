// Metaballs plugin: the sphere set every construction stage reads and writes.
// Pan, Zhao, Zhao, Hao, Qin 2015, "Metaballs-based physical modeling and deformation of organs
// for virtual surgery", The Visual Computer 31, doi:10.1007/s00371-015-1092-2.
#pragma once

#include <deform/sdk/types.h>

namespace deform::metaballs {

/// centers: #S by 3 sphere centres (m). radii: #S radii (m).
struct SphereSet {
  MatX3 centers;
  VecX radii;

  int size() const { return int(radii.size()); }
  Vec3 center(int i) const { return centers.row(i).transpose(); }
  void append(const Vec3& c, Real r) {
    const Eigen::Index n = centers.rows();
    centers.conservativeResize(n + 1, 3);
    radii.conservativeResize(n + 1);
    centers.row(n) = c.transpose();
    radii(n) = r;
  }
  /// Keeps the spheres whose keep flag is set, in order.
  template <class Flags>
  void keep(const Flags& flags) {
    int k = 0;
    for (int i = 0; i < size(); ++i) {
      if (!flags[size_t(i)]) continue;
      centers.row(k) = centers.row(i);
      radii(k) = radii(i);
      ++k;
    }
    centers.conservativeResize(k, 3);
    radii.conservativeResize(k);
  }
};

}  // namespace deform::metaballs
