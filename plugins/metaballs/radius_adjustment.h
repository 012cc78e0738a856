// Metaballs plugin, construction stage 2 (paper Sect. 4.2, eq. 1): every sphere's radius becomes
// the exact distance from its centre to the surface triangles,
//     r = D(c) = min_i d(c, Tri_i),                                          (1)
// so that no sphere reaches outside the surface. D is evaluated with MeshDistance (BVH, exact
// point-triangle distance). A centre outside the surface cannot carry an inside sphere: it is
// removed (and counted), as is a sphere whose new radius is below minRadius.
#pragma once

#include "sphere_set.h"

#include <deform/geometry/distance.h>

namespace deform::metaballs {

/// Spheres that reach outside the surface: centre outside, or r > D(c) + tol.
int countSpheresOutside(const SphereSet& spheres, const MeshDistance& dist, Real tol);

struct RadiusAdjustmentResult {
  int outsideBefore = 0;
  int removedOutsideCentre = 0;
  int removedTooSmall = 0;
};

RadiusAdjustmentResult adjustRadii(SphereSet& spheres, const MeshDistance& dist, Real minRadius,
                                   Real tol);

}  // namespace deform::metaballs
