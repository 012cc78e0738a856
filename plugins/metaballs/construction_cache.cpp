#include "construction.h"

#include <stdexcept>

namespace deform::metaballs {

CacheKey constructionKey(const SurfaceMesh& surface, const ConstructionParams& p) {
  CacheKey k;
  k.add(kConstructionVersion).add(surface.V).add(surface.F);
  k.add(p.targetSpheres).add(p.voxelResolution).add(p.fillNeighbours).add(p.fillMinRadiusRatio);
  k.add(p.fillMaxGenerations).add(p.attractionRangeVoxels).add(p.maxOptimisationMoves);
  k.add(p.topologyNeighbours);
  return k;
}

Metaballs constructMetaballsCached(const SurfaceMesh& surface, const ConstructionParams& p,
                                   Cache& cache, bool* hit) {
  const CacheKey key = constructionKey(surface, p);
  if (auto bytes = cache.get("metaballs.construction", key)) {
    try {
      Metaballs m = deserialiseMetaballs(*bytes);
      if (hit) *hit = true;
      return m;
    } catch (const std::runtime_error&) {
      // Unreadable entry: rebuild and overwrite it.
      cache.reject("metaballs.construction", key);
    }
  }
  Metaballs m = constructMetaballs(surface, p);
  cache.put("metaballs.construction", key, serialiseMetaballs(m));
  if (hit) *hit = false;
  return m;
}

}  // namespace deform::metaballs
