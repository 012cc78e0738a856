// particle_bem: physics points inside an organ (the paper's §3: "the discrete physics points are
// extracted from each segmented organ"). Regular cubic lattice, centred on the bounding box,
// keeping the nodes whose signed distance is below -margin * spacing; the spacing is adjusted
// (a few secant steps on count ~ spacing^-3) so the count is near the requested one.
#pragma once

#include "distance_field.h"

namespace deform::particle_bem {

struct PhysicsPoints {
  MatX3 points;      ///< #P by 3, m
  Real spacing = 0;  ///< lattice spacing, m
};

/// surface: the organ (closed, outward). target: wanted count (>= 1). marginFraction: keep
/// points at least marginFraction * spacing inside the surface (0 = any point inside).
PhysicsPoints sampleLatticeInside(const SignedDistanceField& sdf, const MatX3& surfaceV,
                                  Real volume, int target, Real marginFraction = 0.0);

}  // namespace deform::particle_bem
