// Metaballs plugin, construction stage 4 (paper Sect. 4.4, eq. 3): two spheres overlap
// "extremely" when the distance between their centres is below the radius of the smaller one;
// they are replaced by one sphere at the midpoint of their centres with radius
//     r_new = min(r, D(c_new)),                                              (3)
// r the bigger radius. Pairs are merged most-overlapping first (smallest d / r_small, ties by
// index); a sphere merges at most once per pass. One pass by default: repeating to a fixed point
// collapses chains of medial spheres (each merged sphere again overlaps its neighbour extremely).
#pragma once

#include "sphere_set.h"

#include <deform/geometry/distance.h>

namespace deform::metaballs {

struct MergeResult {
  int merged = 0;  ///< pairs merged
  int passes = 0;
};

MergeResult mergeOverlappingSpheres(SphereSet& spheres, const MeshDistance& dist,
                                    int maxPasses = 1);

}  // namespace deform::metaballs
