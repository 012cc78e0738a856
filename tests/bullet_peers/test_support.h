// Shared helpers of the Bullet peer tests: a small organ with its bottom slab pinned, and the
// standard inputs (gravity, a grasp lifting the top).
#pragma once

#include <deform/model.h>
#include <deform/phantom.h>

#include <algorithm>
#include <vector>

namespace deform::testing {

/// Indices of the rows of V whose z is within `fraction` of the height from the bottom.
inline std::vector<int> bottomSlab(const MatX3& V, Real fraction) {
  const Box b = boundingBox(V);
  std::vector<int> out;
  for (Eigen::Index i = 0; i < V.rows(); ++i)
    if (V(i, 2) <= b.lo.z() + fraction * b.size().z()) out.push_back(int(i));
  return out;
}

/// A grasp of the k nodes nearest to the top centre, moved by `lift` (m) along z.
inline GraspInput topGrasp(const MatX3& nodes, int k, Real lift) {
  const Box b = boundingBox(nodes);
  GraspInput g;
  g.nodes = nearestVertices(nodes, Vec3(b.center().x(), b.center().y(), b.hi.z()), k);
  std::sort(g.nodes.begin(), g.nodes.end());
  g.targets.resize(Eigen::Index(g.nodes.size()), 3);
  for (size_t i = 0; i < g.nodes.size(); ++i)
    g.targets.row(Eigen::Index(i)) = nodes.row(g.nodes[i]) + Vec3(0, 0, lift).transpose();
  return g;
}

inline Real maxDisplacement(const MatX3& x, const MatX3& rest) {
  return (x - rest).rowwise().norm().maxCoeff();
}

}  // namespace deform::testing
