// Metaballs plugin, construction stage 1 (paper Sect. 4.1, "Spheres packing"): initial spheres
// from the medial axis of the organ. The paper uses Bradshaw and O'Sullivan's Sphere Tree
// Construction Toolkit (medial axis from the Voronoi diagram of surface samples, spheres packed
// from it). Here: the Delaunay tetrahedralisation of the surface samples (Qhull, reentrant API)
// gives the Voronoi vertices (circumcentres); for each sample its inner pole (the inside Voronoi
// vertex of largest Voronoi-ball radius among its Delaunay tetrahedra; Amenta et al.'s power crust)
// is a medial-sphere candidate. A greedy maximum-coverage selection (the rule of Bradshaw and
// O'Sullivan's adaptive medial-axis approximation, ACM TOG 23(1) 2004, restated as coverage of
// samples) then picks `target` candidates: repeatedly the candidate that covers the most samples
// not yet covered, where the samples are the inside voxel centres (covered when within D(c) of the
// centre) and the surface vertices (covered when within D(c) + slack).
#pragma once

#include "sphere_set.h"
#include "voxel_grid.h"

#include <deform/geometry/distance.h>

namespace deform::metaballs {

struct MedialCandidates {
  SphereSet poleBalls;     ///< centres = inner poles; radii = Voronoi-ball (circum)radius
  VecX distance;           ///< D(c) of each centre (eq. 1)
  int degenerateTets = 0;  ///< flat Delaunay tetrahedra skipped
  int delaunayTets = 0;
};

/// Inner Voronoi poles of the surface vertices. Throws InputError when Qhull fails.
MedialCandidates medialCandidates(const SurfaceMesh& surface, const MeshDistance& dist,
                                  Real minRadius);

struct PackingResult {
  SphereSet spheres;  ///< selected candidates, with their Voronoi-ball radii (may protrude)
  int candidates = 0;
  long long samples = 0;
  long long coveredSamples = 0;
  int degenerateTets = 0;
};

/// Stage 1: candidates, then greedy coverage down to `target` spheres (fewer when every sample is
/// covered earlier). Deterministic (ties go to the lower candidate index).
PackingResult packSpheres(const SurfaceMesh& surface, const MeshDistance& dist,
                          const VoxelGrid& grid, int target);

}  // namespace deform::metaballs
