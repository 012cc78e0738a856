// deformbench SDK: what a sliding plate holds, for models that prescribe single coordinates of
// surface vertices (a sliding plate's normal lies along a coordinate axis: slideAxis()).
#pragma once

#include <deform/sdk/error.h>
#include <deform/sdk/model.h>

#include <algorithm>
#include <string>
#include <vector>

namespace deform {

/// The vertices a sliding plate holds and their target coordinates along its axis.
struct SlidingPick {
  int axis = -1;           ///< 0 x, 1 y, 2 z
  std::vector<int> verts;  ///< in the grasp's order
  VecX targets;            ///< #verts: each vertex's target coordinate along the axis
};

/// The vertices of sliding grasp g below numVertices that no bonded grasp holds (bondedSorted:
/// the bonded grasps' vertices, sorted), with their targets along the plate's axis. Throws
/// InputError naming `model` when the plate's normal is not along x, y or z.
inline SlidingPick slidingPick(const GraspInput& g, Eigen::Index numVertices,
                               const std::vector<int>& bondedSorted, const std::string& model) {
  SlidingPick p;
  p.axis = slideAxis(g);
  if (p.axis < 0)
    throw InputError(model, "grasp of tool " + std::to_string(g.tool),
                     "a sliding plate's normal must lie along x, y or z");
  std::vector<Real> targets;
  for (size_t k = 0; k < g.vertices.size(); ++k) {
    const int v = g.vertices[k];
    if (v < 0 || v >= numVertices || Eigen::Index(k) >= g.targets.rows() ||
        std::binary_search(bondedSorted.begin(), bondedSorted.end(), v))
      continue;
    p.verts.push_back(v);
    targets.push_back(g.targets(Eigen::Index(k), p.axis));
  }
  p.targets = Eigen::Map<const VecX>(targets.data(), Eigen::Index(targets.size()));
  return p;
}

}  // namespace deform
