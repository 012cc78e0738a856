// Hybrid FEM+PBD, processing of the external force (paper Sec. 6.1, Fig. 6(a)-(c)): the load
// point is snapped to the nearest fine surface node; when that node is not a control node (a
// vertex shared with the coarse volume mesh MV), the force is replaced for MV by equivalent
// nodal forces on the nodes of the nearest coarse surface triangle, weighted by that triangle's
// linear shape functions evaluated at the node's projection p' onto it:
//
//   f_k = N_k(p') f,  N_k = barycentric coordinates of p' (k = 1..3),  sum_k N_k = 1,
//
// so the total force is kept, and so is its moment about p' (sum_k (x_k - p') x f_k =
// (sum_k N_k x_k - p') x f = 0).
//
// Paper: "A Hybrid Model Method for Accurate Surface Deformation and Incision Based on FEM and
// PBD", Scientific Programming 2021, article 8343312, Sec. 6.1
// (/work/shared/papers/hybrid-fem-pbd-incision.md).
#pragma once

#include <deform/sdk/mesh.h>

#include <array>

namespace deform::hybrid_fem_pbd {

/// Closest point on triangle (a, b, c) to p, with its barycentric coordinates (sum 1, each >= 0):
/// core's deform::closestPointOnTriangle (a degenerate triangle gives the closest point on its
/// edges).
Vec3 closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c, Vec3& bary);

/// Where a fine node sits on the coarse surface: up to three coarse vertices and their linear
/// shape-function weights (count 1 when the fine node is a control node).
struct CoarseAttachment {
  int count = 0;
  std::array<int, 3> nodes = {-1, -1, -1};  ///< coarse vertex indices
  std::array<Real, 3> weights = {0, 0, 0};  ///< N_k, summing to 1
  Vec3 projection = Vec3::Zero();           ///< p' = sum_k N_k x_k (rest), m
};

/// Attachment of point p (m) to the coarse surface (V: #Vc by 3 rest positions, F: #Fc by 3):
/// the nearest triangle (brute force; ties to the lower index) and p's barycentric coordinates
/// on it. If controlVertex >= 0 (p is that coarse vertex) the attachment is that vertex alone.
CoarseAttachment attachToCoarseSurface(const Vec3& p, const MatX3& V, const MatX3i& F,
                                       int controlVertex = -1);

/// Equivalent nodal forces f_k = N_k f on the attachment's coarse vertices.
std::array<Vec3, 3> equivalentNodalForces(const CoarseAttachment& a, const Vec3& f);

}  // namespace deform::hybrid_fem_pbd
