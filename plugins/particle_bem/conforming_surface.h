// particle_bem: a surface that conforms to the fixed region's boundary.
//
// The support of a BEM model is a set of boxes (the scene's fixed region). On a surface whose
// elements cross a box's face, "the nodes inside the box" clamp a region that jumps by a whole
// element whenever a node crosses the face, and the loss ratio of Table 2 (§6) then measures
// where the coarse and the fine mesh happen to put that edge (docs/notes/particle_bem-history.md).
// Here the surface is instead cut along the box faces: every triangle crossed by a face plane
// x_k = c is split at the crossing points (placed on the plane exactly), so afterwards every
// triangle lies in one closed cell of the planes: inside the box or outside it. Clamping the
// nodes in the (closed) box then fixes exactly the inside triangles, u = 0 on the support with
// linear elements and free elsewhere, with no free constant. decimateQuadric keeps that
// partition (surface_decimation.h), so coarse and fine surfaces clamp the same region.
#pragma once

#include <deform/sdk/mesh.h>

#include <vector>

namespace deform::particle_bem {

struct ConformStats {
  int splitEdges = 0;       ///< edges cut by a box face plane (one new vertex each)
  int snappedVertices = 0;  ///< vertices within the snap tolerance moved onto a plane
  int planesCut = 0;        ///< box face planes that crossed the surface
};

/// Cuts a closed, manifold, outward surface along the face planes of the boxes. A vertex closer
/// to a plane than snapFraction x its shortest incident edge is moved onto the plane (no sliver
/// triangles); an edge with its ends strictly on both sides gets a vertex on the plane (its
/// plane coordinate set exactly to the plane's value); each crossed triangle becomes 2 or 3
/// triangles with the same orientation (a quadrilateral part is split along its shorter
/// diagonal). The result is closed, manifold and outward, and every triangle lies on one closed
/// side of every plane. Deterministic.
SurfaceMesh conformToBoxes(const SurfaceMesh& in, const std::vector<Box>& boxes,
                           ConformStats* stats = nullptr, Real snapFraction = 0.02);

/// Per triangle: 1 when it lies in the (closed) union of the boxes (all three vertices in one
/// box), 0 otherwise. On a conforming surface this is the support of the fixed region.
std::vector<char> facesInBoxes(const MatX3& V, const MatX3i& F, const std::vector<Box>& boxes);

/// Is the triangle consistent with the partition: inside (tag 1) = its vertices in one closed
/// box; outside (tag 0) = for every box, all three vertices on the closed outer side of one of
/// its face planes (so it does not enter any box's interior) and not all three on a box.
bool triangleConforms(const Vec3& x0, const Vec3& x1, const Vec3& x2, bool inside,
                      const std::vector<Box>& boxes);

/// Number of triangles of a surface that do not conform (triangleConforms with the tags of
/// facesInBoxes): 0 for a conforming surface.
int nonConformingFaces(const SurfaceMesh& s, const std::vector<Box>& boxes);

}  // namespace deform::particle_bem
