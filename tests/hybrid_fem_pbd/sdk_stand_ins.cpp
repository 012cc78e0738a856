// TEMPORARY stand-in for fixedNodeIndices (declared in core/include/deform/model.h), whose
// implementation lands on main with the harness branch. Weak, so the real definition in
// libdeform_core wins once it exists; delete this file then.
#include <deform/model.h>

#include <algorithm>

namespace deform {

[[gnu::weak]] std::vector<int> fixedNodeIndices(const MatX3& nodes, const FixedRegion& region,
                                                const SurfaceMesh& restSurface) {
  std::vector<int> out;
  for (Eigen::Index i = 0; i < nodes.rows(); ++i)
    for (const Box& b : region.boxes)
      if (b.contains(nodes.row(i).transpose())) out.push_back(static_cast<int>(i));
  for (int v : region.surfaceVertices) out.push_back(nearestVertex(nodes, restSurface.V.row(v)));
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

}  // namespace deform
