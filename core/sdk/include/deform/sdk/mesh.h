// deformbench SDK: surface and tetrahedral mesh types and the small geometric queries every
// model needs (edges, volume, bounding box, boundary extraction).
#pragma once

#include <deform/sdk/types.h>

#include <vector>

namespace deform {

/// A triangle surface. V: #V by 3 vertex positions (m). F: #F by 3 vertex indices, counter-
/// clockwise seen from outside, so that the outward normal is (v1-v0)×(v2-v0).
struct SurfaceMesh {
  MatX3 V;
  MatX3i F;

  int numVertices() const { return static_cast<int>(V.rows()); }
  int numFaces() const { return static_cast<int>(F.rows()); }
};

/// A tetrahedral volume. V: #V by 3 node positions (m). T: #T by 4 node indices, positively
/// oriented (see MatX4i).
struct TetMesh {
  MatX3 V;
  MatX4i T;

  int numVertices() const { return static_cast<int>(V.rows()); }
  int numTets() const { return static_cast<int>(T.rows()); }
};

/// Axis-aligned bounding box.
struct Box {
  Vec3 lo = Vec3::Constant(0);
  Vec3 hi = Vec3::Constant(0);
  Vec3 size() const { return hi - lo; }
  Vec3 center() const { return 0.5 * (lo + hi); }
  Real diagonal() const { return size().norm(); }
  bool contains(const Vec3& p) const {
    return (p.array() >= lo.array()).all() && (p.array() <= hi.array()).all();
  }
};

/// Bounding box of the rows of V (an empty V gives a zero box at the origin).
Box boundingBox(const MatX3& V);

/// Indices of the rows of V inside the box (boundary included), ascending.
std::vector<int> rowsInBox(const MatX3& V, const Box& box);

/// Unique undirected edges of a triangle list, each as (min index, max index), sorted
/// lexicographically. #E by 2.
MatX2i uniqueEdges(const MatX3i& F);

/// For each unique edge (as returned by uniqueEdges), the two faces sharing it; -1 where a
/// boundary edge has only one. Edges shared by more than two faces keep the first two.
/// Output: #E by 2.
MatX2i edgeFaces(const MatX3i& F, const MatX2i& E);

/// Signed volume enclosed by a closed triangle surface (positive when outward oriented), m^3.
Real signedVolume(const MatX3& V, const MatX3i& F);

/// Surface area, m^2.
Real surfaceArea(const MatX3& V, const MatX3i& F);

/// Area-weighted unit vertex normals, #V by 3.
MatX3 vertexNormals(const MatX3& V, const MatX3i& F);

/// Signed volume of one tetrahedron: (x1-x0)·((x2-x0)×(x3-x0)) / 6.
Real tetVolume(const Vec3& x0, const Vec3& x1, const Vec3& x2, const Vec3& x3);

/// Positive orientation for every tet: the last two nodes of each tet with tetVolume < 0 swap.
void orientTetsPositive(TetMesh& mesh);

/// Boundary triangles of a tetrahedral mesh (faces used by exactly one tet), outward oriented.
/// The result indexes T's nodes; unreferenced interior nodes are kept, so V is T.V unchanged.
SurfaceMesh tetBoundary(const TetMesh& tets);

/// Index of the row of V nearest to p (brute force; -1 for empty V).
int nearestVertex(const MatX3& V, const Vec3& p);

/// Indices of the k rows of V nearest to p, nearest first (k is clamped to #V). Ties are broken
/// by index so the result is deterministic.
std::vector<int> nearestVertices(const MatX3& V, const Vec3& p, int k);

}  // namespace deform
