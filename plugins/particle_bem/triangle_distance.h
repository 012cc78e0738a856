// particle_bem: exact point-to-triangle-mesh distance with a uniform bucket grid, and the sign
// of the distance from angle-weighted pseudo-normals (Baerentzen & Aanaes 2005). The closest
// point on one triangle (and its barycentrics) is core's deform::closestPointOnTriangle
// (deform/geometry/distance.h); the grid is kept because the plugin queries many points near one
// small surface and returns the barycentrics the interpolation needs.
#pragma once

#include <deform/geometry/distance.h>
#include <deform/sdk/mesh.h>

#include <vector>

namespace deform::particle_bem {

struct ClosestPoint {
  Vec3 point = Vec3::Zero();
  Vec3 bary = Vec3::Zero();  ///< weights of the triangle's three vertices
  Real distance = 0;         ///< unsigned, m
  int triangle = -1;
  TriangleFeature feature = TriangleFeature::Face;  ///< where on the triangle the point lies
};

/// Closed triangle surface with its triangles bucketed into a uniform grid (each triangle in
/// every cell its bounding box overlaps). Queries search cells in growing shells, so a query
/// costs O(triangles near p). Not thread-safe (queries reuse a visit stamp).
class TriangleGrid {
 public:
  /// V: #V by 3, F: #F by 3 (outward). cellSize <= 0: twice the mean edge length.
  TriangleGrid(const MatX3& V, const MatX3i& F, Real cellSize = 0);

  ClosestPoint closest(const Vec3& p) const;
  /// Negative inside the closed surface. Sign from the pseudo-normal of the closest feature
  /// (face normal, edge: sum of the two face normals, vertex: angle-weighted normal).
  Real signedDistance(const Vec3& p, ClosestPoint* cp = nullptr) const;

  const MatX3& vertices() const { return m_V; }
  const MatX3i& faces() const { return m_F; }

 private:
  MatX3 m_V;
  MatX3i m_F;
  Vec3 m_lo;
  Real m_cell = 1;
  Eigen::Vector3i m_dims;
  std::vector<int> m_cellStart, m_cellTris;
  MatX3 m_faceNormal, m_vertexNormal;
  std::vector<Vec3> m_edgeNormal;    ///< per (face, local edge k = opposite vertex k)
  mutable std::vector<int> m_stamp;  ///< per triangle: last query that tested it
  mutable int m_query = 0;
};

}  // namespace deform::particle_bem
