// deformbench SDK: exact point-to-triangle-mesh distance, accelerated by a bounding volume
// hierarchy over the triangles, and the sign (inside/outside) of a closed, manifold,
// outward-oriented surface by angle-weighted pseudo-normals (Baerentzen and Aanaes 2005,
// "Signed distance computation using the angle weighted pseudonormal", IEEE TVCG 11(3)).
#pragma once

#include <deform/sdk/mesh.h>

#include <vector>

namespace deform {

/// Which feature of triangle (a, b, c) holds the closest point.
enum class TriangleFeature { VertexA, VertexB, VertexC, EdgeAB, EdgeBC, EdgeCA, Face };

struct TriangleClosestPoint {
  Vec3 point = Vec3::Zero();  ///< closest point on the triangle
  Real dist2 = 0;             ///< squared distance |p - point|^2, m^2
  TriangleFeature feature = TriangleFeature::Face;
  /// Barycentric weights of a, b, c of `point` (sum 1; exactly 0 for the vertices not on the
  /// feature, e.g. (1 - t, t, 0) on edge ab).
  Vec3 bary = Vec3::Zero();
};

/// Exact closest point of p on the (closed, solid) triangle abc, by Voronoi regions of its
/// vertices, edges and face (Ericson, Real-Time Collision Detection, 5.1.5). A degenerate
/// triangle gives the closest point on its edges.
TriangleClosestPoint closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b,
                                            const Vec3& c);

/// Distance queries against one triangle surface. Builds a BVH (median split on the longest axis,
/// up to 4 triangles a leaf) at construction; queries are exact and thread-safe (const).
class MeshDistance {
 public:
  struct Result {
    Real distance = 0;  ///< unsigned, m
    Vec3 point = Vec3::Zero();
    int triangle = -1;
    TriangleFeature feature = TriangleFeature::Face;
  };

  /// mesh: copied. Pseudo-normals (for the sign) assume a closed, manifold, outward-oriented
  /// surface; the unsigned queries work on any triangle soup.
  explicit MeshDistance(const SurfaceMesh& mesh);

  /// D(p) = min_i d(p, Tri_i) with the closest point and its triangle.
  Result closest(const Vec3& p) const;
  Real distance(const Vec3& p) const { return closest(p).distance; }
  /// Negative inside, positive outside.
  Real signedDistance(const Vec3& p) const;
  bool inside(const Vec3& p) const { return signedDistance(p) < 0; }

  const SurfaceMesh& mesh() const { return m_mesh; }

 private:
  struct Node {
    Vec3 lo, hi;
    int left = -1, right = -1;  ///< children, or -1 for a leaf
    int begin = 0, end = 0;     ///< leaf range in m_order
  };
  int build(int begin, int end, const MatX3& centroids);
  static Real boxDist2(const Node& n, const Vec3& p);

  SurfaceMesh m_mesh;
  std::vector<Node> m_nodes;
  std::vector<int> m_order;
  MatX3 m_faceNormal;    ///< #F by 3 unit normals
  MatX3 m_vertexNormal;  ///< #V by 3 angle-weighted pseudo-normals
  MatX3 m_edgeNormal;    ///< #F*3 by 3: pseudo-normal of edge e (ab, bc, ca) of face f at 3f+e
};

}  // namespace deform
