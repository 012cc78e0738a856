// deformbench geometry: the lumped mass and the edges of a triangle surface model (a mass-spring
// or position-based membrane over the organ's surface).
#pragma once

#include <deform/sdk/mesh.h>

namespace deform {

/// A surface's lumped masses and edges. The mass is that of the enclosed volume (density times
/// |signedVolume|) for a closed surface, or of a shell of the given thickness over the area for
/// an open one, spread by vertex area (a third of each triangle).
struct LumpedSurface {
  VecX faceArea;        ///< #F, m^2
  Real totalArea = 0;   ///< m^2
  VecX mass;            ///< #V, kg
  MatX2i edges;         ///< uniqueEdges(F)
  MatX2i edgeFaces;     ///< edgeFaces(F, edges): the one or two faces beside each edge
  bool closed = false;  ///< every edge has two faces
  /// The area of the faces beside edge e, m^2.
  Real edgeArea(Eigen::Index e) const {
    Real adj = 0;
    for (int k = 0; k < 2; ++k)
      if (edgeFaces(e, k) >= 0) adj += faceArea[edgeFaces(e, k)];
    return adj;
  }
};
LumpedSurface lumpSurface(const SurfaceMesh& S, Real density, Real thickness);

}  // namespace deform
