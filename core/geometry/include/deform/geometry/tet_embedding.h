// deformbench geometry: points embedded in a tet mesh (interior markers, Model::bindMarkers):
// each point is bound to the tet that contains it at rest, by its barycentric coordinates, and
// follows that tet's nodes: linearly for 4-node tets, with the 10-node shape functions for
// quadratic ones. The one embedding every tet-based model uses.
#pragma once

#include <deform/sdk/mesh.h>

#include <array>
#include <vector>

namespace deform {

struct TetEmbedding {
  std::vector<int> tet;                      ///< per point: the tet it is bound to
  std::vector<std::array<Real, 4>> weights;  ///< per point: barycentric coordinates in it
  /// per point: 0 when the tet contains it (within round-off), else the most negative
  /// barycentric coordinate's magnitude (the point lies outside the mesh: extrapolated from the
  /// nearest tet in barycentric terms).
  std::vector<Real> outside;
  int numOutside() const;
};

/// Binds each row of `points` to the tet of (nodes, tets) containing it; a point outside every
/// tet to the tet whose smallest barycentric coordinate is largest (the nearest, in barycentric
/// terms). Degenerate tets are skipped. Throws InputError when the mesh has no tet.
TetEmbedding embedInTets(const MatX3& nodes, const MatX4i& tets, const MatX3& points);

/// Current positions of embedded points from the tets' current corner positions (#points by 3).
MatX3 embeddedPositions(const TetEmbedding& e, const MatX3& nodes, const MatX4i& tets);

/// The same through 10-node tets: elementNodes(t, a) gives node a (corners 0..3, then the midside
/// nodes of edges (0,1), (0,2), (0,3), (1,2), (1,3), (2,3)) of tet t, and the quadratic shape
/// functions L_i (2 L_i - 1) and 4 L_i L_j weight the current node positions.
template <class ElementNode>
MatX3 embeddedPositionsQuadratic(const TetEmbedding& e, const MatX3& nodes,
                                 const ElementNode& elementNode) {
  static constexpr int kEdge[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};
  MatX3 out(Eigen::Index(e.tet.size()), 3);
  for (size_t p = 0; p < e.tet.size(); ++p) {
    const int t = e.tet[p];
    const std::array<Real, 4>& L = e.weights[p];
    Vec3 x = Vec3::Zero();
    for (int a = 0; a < 4; ++a)
      x += L[a] * (2 * L[a] - 1) * nodes.row(elementNode(t, a)).transpose();
    for (int k = 0; k < 6; ++k)
      x += 4 * L[kEdge[k][0]] * L[kEdge[k][1]] * nodes.row(elementNode(t, 4 + k)).transpose();
    out.row(Eigen::Index(p)) = x.transpose();
  }
  return out;
}

}  // namespace deform
