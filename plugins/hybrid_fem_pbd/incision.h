// Hybrid FEM+PBD, small incision of the fine surface MS (paper Sec. 7, Figs. 7-8). The coarse
// volume mesh MV is not cut (the paper neglects the incision's effect on MV).
//
// 1. Intersection points. The cut path (a polyline, the pin-head's track) is projected onto the
//    surface and followed triangle by triangle: in each triangle the straight line towards the
//    next path point (in the triangle's plane, i.e. the intersection of the triangle with the
//    sweep surface spanned by the path segment and the surface normal) leaves through an edge,
//    giving an edge point, or ends inside, giving a facet point (path ends). Points within
//    snapFraction of a vertex (in barycentric terms) snap to it, so no sliver triangles appear;
//    the cut then runs through that vertex.
// 2. Subdivision ([23] in the paper): an edge point splits its edge and both adjacent triangles
//    (1 -> 2 each); a facet point splits its triangle (1 -> 3). This yields the paper's three
//    element cases: a triangle crossed edge to edge becomes 3 triangles, a triangle holding a
//    path end and an edge point becomes 4, a triangle holding both path ends becomes 7 (a cut
//    within one triangle gets a midpoint so that it can open).
// 3. Opening. Every path vertex strictly inside the path is duplicated; the copy takes the
//    triangles on the left of the path. Path ends stay single (crack tips), so the surface stays
//    manifold, with one new boundary loop along the cut. A duplicated control point becomes two
//    ordinary (non-control) points.
// 4. Rest data. Each vertex remembers where it sits as a barycentric combination of original
//    (pre-cut) vertices; each triangle remembers its original parent triangle. New stretch rest
//    lengths come from the parent triangle's rest edge lengths and the barycentric coordinates by
//    the law of cosines (paper Sec. 7, Fig. 8): with l_AB, l_BC, l_CA the rest lengths,
//    cos(alpha) = (l_AB^2 + l_CA^2 - l_BC^2) / (2 l_AB l_CA) lays the rest triangle out in a
//    plane (A = 0, B = (l_AB, 0), C = l_CA (cos alpha, sin alpha)), and the rest length between
//    P = sum lambda_k X_k and Q = sum mu_k X_k is |P - Q| there; for an edge point P on AB this
//    is l_AP = lambda_B l_AB. Bending rest angles are kept: the original angle across (pieces
//    of) original edges, zero (flat) across edges inside an original triangle.
//
// Paper: "A Hybrid Model Method for Accurate Surface Deformation and Incision Based on FEM and
// PBD", Scientific Programming 2021, article 8343312, Sec. 7
// (/work/shared/papers/hybrid-fem-pbd-incision.md).
#pragma once

#include <deform/sdk/mesh.h>
#include <deform/sdk/model.h>

#include <array>
#include <string>
#include <utility>
#include <vector>

#include "surface_pbd.h"

namespace deform::hybrid_fem_pbd {

/// A vertex as a barycentric combination of (up to three) original vertices.
struct VertexOrigin {
  int count = 0;
  std::array<int, 3> v = {-1, -1, -1};
  std::array<Real, 3> w = {0, 0, 0};
};

/// A triangle surface that can be cut: current and rest positions, triangles, and the
/// bookkeeping that maps everything back to the original surface.
struct CuttableSurface {
  MatX3 x;                           ///< #V by 3 current positions, m
  MatX3 rest;                        ///< #V by 3 rest positions, m
  std::vector<Vec3i> F;              ///< current triangles (counter-clockwise seen from outside)
  std::vector<int> parentFace;       ///< #F: original triangle each triangle lies in
  std::vector<VertexOrigin> origin;  ///< #V
  MatX3i originalF;                  ///< the triangles before any cut
  int originalVertices = 0;

  static CuttableSurface fromMesh(const MatX3& x, const MatX3& rest, const MatX3i& F);
  int numVertices() const { return static_cast<int>(x.rows()); }
  MatX3i faces() const;
  /// Barycentric coordinates of vertex v in original triangle f (v must lie in it).
  Vec3 baryInOriginalFace(int v, int f) const;
};

struct CutOptions {
  Real snapFraction = 0.1;  ///< barycentric distance under which a point snaps to a vertex/edge
};

struct CutReport {
  bool applied = false;
  std::string reason;  ///< why not, when not applied
  int edgePoints = 0, facetPoints = 0, vertexPoints = 0;
  int newVertices = 0, newFaces = 0;
  std::vector<int> path;                        ///< cut vertices from start to end (before opening)
  std::vector<std::pair<int, int>> duplicates;  ///< (vertex, its copy)
};

/// Cuts s along path (points in current coordinates, m; projected onto the surface). On failure
/// (path self-intersects, leaves through a boundary, fewer than two distinct points) s is left
/// unchanged and the report says why.
CutReport cutSurface(CuttableSurface& s, const CutPath& path, const CutOptions& options = {});

/// Rest distance between points with barycentric coordinates bp, bq in a triangle ABC with rest
/// edge lengths lAB, lBC, lCA (law of cosines layout, see above), m.
Real restDistanceInTriangle(Real lAB, Real lBC, Real lCA, const Vec3& bp, const Vec3& bq);

/// Constraints of the cut surface from the original constraints: stretch rest lengths by
/// restDistanceInTriangle in each edge's parent triangle (with that triangle's original rest
/// lengths), bending rest angles kept (original angle across original edges, 0 inside a
/// triangle). original: the constraints built on s.originalF.
SurfaceConstraints constraintsAfterCut(const CuttableSurface& s,
                                       const SurfaceConstraints& original);

}  // namespace deform::hybrid_fem_pbd
