// Metaballs plugin, construction stage 4 (paper Sect. 4.4, eq. 3): two spheres overlap
// "extremely" when the distance between their centres is below the radius of the smaller one;
// they are replaced by one sphere at the midpoint of their centres with radius
//     r_new = min(r, D(c_new)),                                              (3)
// r the bigger radius. Pairs are merged most-overlapping first (smallest d / r_small, ties by
// index); a sphere merges at most once per pass; passes repeat until no pair is left (or
// maxPasses).
#pragma once

#include "sphere_set.h"

#include <deform/distance.h>

namespace deform::metaballs {

struct MergeResult {
  int merged = 0;  ///< pairs merged
  int passes = 0;
};

MergeResult mergeOverlappingSpheres(SphereSet& spheres, const MeshDistance& dist,
                                    int maxPasses = 20);

}  // namespace deform::metaballs
