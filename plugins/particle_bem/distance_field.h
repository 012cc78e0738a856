// particle_bem: signed distance field on a regular grid (the paper's §3, Fig. 1: "pre-compute a
// distance field in the local Eulerian grid as in [1], [3] and [11]"). Values at grid nodes are
// exact signed distances to the surface (TriangleGrid); queries interpolate trilinearly, and the
// gradient (the outward direction) comes from the trilinear interpolant's derivative. Used for
// collision handling (push a particle out along the gradient by -phi) and for the inside test
// when sampling physics points.
#pragma once

#include "triangle_distance.h"

namespace deform::particle_bem {

class SignedDistanceField {
 public:
  SignedDistanceField() = default;
  /// Grid over the surface's bounding box grown by `margin` (m) on each side, with `cells`
  /// cells along the longest axis (cubic cells). Negative inside.
  SignedDistanceField(const TriangleGrid& surface, int cells, Real margin);

  /// Trilinear value (m); outside the grid: the nearest node's value plus the distance to the
  /// grid (an over-estimate, positive far away).
  Real value(const Vec3& p) const;
  /// Gradient of the trilinear interpolant (unit length near the surface).
  Vec3 gradient(const Vec3& p) const;
  /// Collision response: if phi(p) < clearance, p moved along the gradient to phi = clearance.
  /// Returns true when p moved.
  bool pushOut(Vec3& p, Real clearance = 0) const;

  const Eigen::Vector3i& dims() const { return m_n; }  ///< nodes per axis
  Real cellSize() const { return m_h; }
  long long nodeCount() const { return (long long)m_n[0] * m_n[1] * m_n[2]; }

 private:
  Real node(int i, int j, int k) const { return m_phi[(size_t(k) * m_n[1] + j) * m_n[0] + i]; }
  Vec3 m_lo = Vec3::Zero();
  Real m_h = 1;
  Eigen::Vector3i m_n = Eigen::Vector3i::Zero();
  std::vector<Real> m_phi;
};

}  // namespace deform::particle_bem
