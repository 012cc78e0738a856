#include "load_processing.h"

#include <deform/geometry/distance.h>

#include <limits>

namespace deform::hybrid_fem_pbd {

Vec3 closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c,
                            Vec3& bary) {
  const TriangleClosestPoint r = deform::closestPointOnTriangle(p, a, b, c);
  bary = r.bary;
  return r.point;
}

CoarseAttachment attachToCoarseSurface(const Vec3& p, const MatX3& V, const MatX3i& F,
                                       int controlVertex) {
  CoarseAttachment out;
  if (controlVertex >= 0) {
    out.count = 1;
    out.nodes[0] = controlVertex;
    out.weights[0] = 1;
    out.projection = V.row(controlVertex).transpose();
    return out;
  }
  Real best = std::numeric_limits<Real>::infinity();
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    Vec3 bary;
    const Vec3 q = closestPointOnTriangle(p, V.row(F(f, 0)).transpose(), V.row(F(f, 1)).transpose(),
                                          V.row(F(f, 2)).transpose(), bary);
    const Real d = (q - p).squaredNorm();
    if (d < best) {
      best = d;
      out.count = 3;
      for (int k = 0; k < 3; ++k) {
        out.nodes[k] = F(f, k);
        out.weights[k] = bary[k];
      }
      out.projection = q;
    }
  }
  return out;
}

std::array<Vec3, 3> equivalentNodalForces(const CoarseAttachment& a, const Vec3& f) {
  std::array<Vec3, 3> out = {Vec3::Zero(), Vec3::Zero(), Vec3::Zero()};
  for (int k = 0; k < a.count; ++k) out[k] = a.weights[k] * f;
  return out;
}

}  // namespace deform::hybrid_fem_pbd
