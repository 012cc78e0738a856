// Metaballs plugin: the whole offline construction of paper Sect. 4 and 5.1, stage by stage,
// with a measurable report of each stage, and its cache payload.
//   1. sphere packing from the medial axis          (sphere_packing.h,             Sect. 4.1)
//   2. radius adjustment, eq. 1                      (radius_adjustment.h,          Sect. 4.2)
//   3. vacant space filling, Algorithm 1, eq. 2      (vacant_space_filling.h,       Sect. 4.3)
//   4. merging of extremely overlapping spheres, eq. 3 (sphere_merging.h,          Sect. 4.4)
//   5. electrostatic global optimisation, Alg. 2     (electrostatic_optimisation.h, Sect. 4.5)
//   6. topology, eq. 5                               (topology.h,                   Sect. 5.1)
#pragma once

#include "sphere_set.h"
#include "topology.h"

#include <deform/sdk/cache.h>
#include <deform/sdk/mesh.h>

#include <string>
#include <vector>

namespace deform::metaballs {

/// Bumped whenever any stage's result can change for the same inputs.
inline constexpr const char* kConstructionVersion = "metaballs-construction/3";

struct ConstructionParams {
  int targetSpheres = 900;        ///< stage 1 selection budget (liver: ~580 after merging)
  int voxelResolution = 48;       ///< voxels along the longest side (stages 1 and 5)
  int fillNeighbours = 6;         ///< k of Algorithm 1
  Real fillMinRadiusRatio = 0.5;  ///< stage 3 minimum radius, as a fraction of the median radius
  int fillMaxGenerations = 4;
  Real attractionRangeVoxels = 2.0;
  int maxOptimisationMoves = 20000;
  int topologyNeighbours = 9;  ///< N of eq. (5)
};

struct ConstructionReport {
  // stage 1
  int medialCandidates = 0;
  int packedSpheres = 0;
  int degenerateTets = 0;
  // stage 2
  int outsideBeforeAdjustment = 0;
  int outsideAfterAdjustment = 0;  ///< must be 0
  int removedByAdjustment = 0;
  // stage 3, 4
  int filledSpheres = 0;
  int mergedPairs = 0;
  // stage 5
  long long insideVoxels = 0;
  long long hollowBefore = 0;
  long long hollowAfter = 0;
  int optimisationMoves = 0;
  int outsideAfterOptimisation = 0;  ///< must be 0
  // stage 6
  int spheres = 0;
  int links = 0;
  int bridges = 0;
  // seconds per stage: packing (incl. voxelisation and BVH), adjustment, filling, merging,
  // optimisation, topology
  double seconds[6] = {0, 0, 0, 0, 0, 0};
  double totalSeconds() const;
  double hollowFractionBefore() const {
    return insideVoxels ? double(hollowBefore) / double(insideVoxels) : 0.0;
  }
  double hollowFractionAfter() const {
    return insideVoxels ? double(hollowAfter) / double(insideVoxels) : 0.0;
  }
};

struct Metaballs {
  SphereSet spheres;
  Topology topology;
  ConstructionReport report;
};

/// Runs stages 1-6 on a closed, outward-oriented surface (m). Deterministic, and the same for the
/// same shape in any units and at any place (the stages run on the surface centred, divided by its
/// longest side and rounded to 2^-32 of it; the spheres are mapped back).
Metaballs constructMetaballs(const SurfaceMesh& surface, const ConstructionParams& p);

/// Cache key: surface, every construction parameter and kConstructionVersion.
CacheKey constructionKey(const SurfaceMesh& surface, const ConstructionParams& p);
std::vector<char> serialiseMetaballs(const Metaballs& m);
/// Throws std::runtime_error on a malformed payload (the cache treats it as corrupt).
Metaballs deserialiseMetaballs(const std::vector<char>& bytes);

/// Cached construction: a hit returns the stored result (report included, with the seconds
/// measured when it was built); *hit says which.
Metaballs constructMetaballsCached(const SurfaceMesh& surface, const ConstructionParams& p,
                                   Cache& cache, bool* hit = nullptr);

}  // namespace deform::metaballs
