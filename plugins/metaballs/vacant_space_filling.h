// Metaballs plugin, construction stage 3 (paper Sect. 4.3, Algorithm 1, eq. 2): vacant space
// between a sphere and its k nearest neighbours is filled by a new sphere centred at the middle
// of the gap along the centre line,
//     c_new = (d + r2 - r1)/(2d) c1 + (d + r1 - r2)/(2d) c2,   d = |c1 - c2|,        (2)
// with radius r_new = D(c_new) (eq. 1). The new sphere is kept when c_new is inside the mesh and
// inside no sphere of the current set (Algorithm 1, line 9; "any sphere in Q" is read as the whole
// current set, original and added: Q pops spheres, and a popped sphere still occupies space).
// The FIFO queue of Algorithm 1 processes the spheres generation by generation; this is done in
// rounds (one round = one generation), with the k-d tree rebuilt between rounds. Two guards the
// paper leaves implicit: r_new >= minRadius (else the boundary fills with ever smaller spheres)
// and at most maxGenerations rounds.
#pragma once

#include "sphere_set.h"

#include <deform/geometry/distance.h>

namespace deform::metaballs {

/// Eq. (2): the midpoint of the gap (or of the overlap) between two spheres on their centre line.
/// Coincident centres give c1.
Vec3 gapMidpoint(const Vec3& c1, Real r1, const Vec3& c2, Real r2);

struct FillParams {
  int neighbours = 6;  ///< k of the k-nearest-neighbour search
  Real minRadius = 0;  ///< m
  int maxGenerations = 6;
};

struct FillResult {
  int added = 0;
  int generations = 0;
};

FillResult fillVacantSpace(SphereSet& spheres, const MeshDistance& dist, const FillParams& p);

}  // namespace deform::metaballs
