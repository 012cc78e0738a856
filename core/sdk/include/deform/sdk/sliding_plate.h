// deformbench SDK: what a sliding plate holds, for models that prescribe single coordinates of
// surface vertices (a sliding plate's normal lies along a coordinate axis: slideAxis()).
#pragma once

#include <deform/sdk/error.h>
#include <deform/sdk/model.h>

#include <algorithm>
#include <string>
#include <vector>

namespace deform {

/// The bonded grasps of a step: `grasps` itself when none slides, else its bonded ones copied to
/// scratch (kept by the model, so a step allocates only when a plate slides).
inline const std::vector<GraspInput>& bondedGrasps(const std::vector<GraspInput>& grasps,
                                                   std::vector<GraspInput>& scratch) {
  if (std::none_of(grasps.begin(), grasps.end(), [](const GraspInput& g) { return g.sliding(); }))
    return grasps;
  scratch.clear();
  for (const GraspInput& g : grasps)
    if (!g.sliding()) scratch.push_back(g);
  return scratch;
}

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
