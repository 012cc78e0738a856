#include "load_processing.h"

#include <limits>

namespace deform::hybrid {

Vec3 closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c,
                            Vec3& bary) {
  // Region tests on the Voronoi regions of the vertices, edges and face (Ericson, "Real-Time
  // Collision Detection", 2005, Sec. 5.1.5).
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const Real d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) {
    bary = Vec3(1, 0, 0);
    return a;
  }
  const Vec3 bp = p - b;
  const Real d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) {
    bary = Vec3(0, 1, 0);
    return b;
  }
  const Real vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const Real v = d1 / (d1 - d3);
    bary = Vec3(1 - v, v, 0);
    return a + v * ab;
  }
  const Vec3 cp = p - c;
  const Real d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) {
    bary = Vec3(0, 0, 1);
    return c;
  }
  const Real vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const Real w = d2 / (d2 - d6);
    bary = Vec3(1 - w, 0, w);
    return a + w * ac;
  }
  const Real va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const Real w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    bary = Vec3(0, 1 - w, w);
    return b + w * (c - b);
  }
  const Real denom = va + vb + vc;
  if (!(std::abs(denom) > 0)) {  // degenerate triangle: fall back to the first vertex
    bary = Vec3(1, 0, 0);
    return a;
  }
  const Real v = vb / denom, w = vc / denom;
  bary = Vec3(1 - v - w, v, w);
  return a + v * ab + w * ac;
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

}  // namespace deform::hybrid
