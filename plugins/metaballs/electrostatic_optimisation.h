// Metaballs plugin, construction stage 5 (paper Sect. 4.5, eq. 4, Algorithm 2): global
// optimisation by the electrostatic attraction model. The organ is voxelised; a hollow voxel is an
// inside voxel whose centre lies in no sphere. Objective (4): min sum(V_hollow). Each hollow voxel
// is a unit positive charge, each sphere a negative charge proportional to its volume; a hollow
// voxel attracts only the spheres within `range` of their surface, by Coulomb's law:
//     f_j = r_j^3 * sum_v (x_v - c_j) / |x_v - c_j|^3.
// Algorithm 2: among the attracted spheres, move one along f_j by one voxel; when the hollow count
// drops, keep the move and recompute; stop when no attracted sphere's move lowers the count.
// Choices where the paper is silent:
//  - the attracted spheres are tried in order of decreasing |f_j| (ties by index);
//  - the radius is fixed unless the surface is nearer at the new centre: r' = min(r, D(c')), so
//    stage 2's "no sphere outside" survives the optimisation (with a strictly fixed radius, a
//    sphere that touches the surface, as every sphere does after eq. 1, could never move towards
//    the hollow voxels, which lie between the spheres and the surface);
//  - a sphere whose trial failed is not retried until a move nearby changes its neighbourhood
//    (its outcome cannot change before), which makes the loop affordable; this is exact;
//  - at most maxMoves accepted moves.
#pragma once

#include "sphere_set.h"
#include "voxel_grid.h"

#include <deform/geometry/distance.h>

namespace deform::metaballs {

/// Inside voxels whose centre lies in no sphere.
long long countHollowVoxels(const SphereSet& spheres, const VoxelGrid& grid);

struct ElectrostaticParams {
  Real rangeVoxels = 2.0;  ///< attraction range beyond a sphere's surface, in voxels
  int maxMoves = 20000;
};

struct ElectrostaticResult {
  long long insideVoxels = 0;
  long long hollowBefore = 0;
  long long hollowAfter = 0;
  int moves = 0;
  int trials = 0;
};

ElectrostaticResult optimiseElectrostatic(SphereSet& spheres, const VoxelGrid& grid,
                                          const MeshDistance& dist, const ElectrostaticParams& p);

}  // namespace deform::metaballs
