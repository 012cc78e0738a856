#include "radius_adjustment.h"

#include <vector>

namespace deform::metaballs {

int countSpheresOutside(const SphereSet& spheres, const MeshDistance& dist, Real tol) {
  int n = 0;
  for (int i = 0; i < spheres.size(); ++i) {
    const Real s = dist.signedDistance(spheres.center(i));
    if (s >= 0 || spheres.radii(i) > -s + tol) ++n;
  }
  return n;
}

RadiusAdjustmentResult adjustRadii(SphereSet& spheres, const MeshDistance& dist, Real minRadius,
                                   Real tol) {
  RadiusAdjustmentResult res;
  std::vector<uint8_t> keep(size_t(spheres.size()), 1);
  for (int i = 0; i < spheres.size(); ++i) {
    const Real s = dist.signedDistance(spheres.center(i));
    if (s >= 0 || spheres.radii(i) > -s + tol) ++res.outsideBefore;
    if (s >= 0) {
      keep[size_t(i)] = 0;
      ++res.removedOutsideCentre;
    } else if (-s < minRadius) {
      keep[size_t(i)] = 0;
      ++res.removedTooSmall;
    } else {
      spheres.radii(i) = -s;
    }
  }
  spheres.keep(keep);
  return res;
}

}  // namespace deform::metaballs
