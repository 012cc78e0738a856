// TEMPORARY: a weak copy of deform::fixedNodeIndices (model.h) for the particle_bem tests,
// benchmark and tables program, until core's definition (harness branch) is on main. The plugin
// itself does not link this file; once core defines the function, delete this file.
// Semantics from model.h: nodes inside any box, plus the node nearest each listed surface
// vertex; sorted, unique.
#include <deform/model.h>

#include <algorithm>

namespace deform {

__attribute__((weak)) std::vector<int> fixedNodeIndices(const MatX3& nodes,
                                                        const FixedRegion& region,
                                                        const SurfaceMesh& restSurface) {
  std::vector<int> out;
  for (Eigen::Index i = 0; i < nodes.rows(); ++i)
    for (const Box& b : region.boxes)
      if (b.contains(nodes.row(i).transpose())) {
        out.push_back(int(i));
        break;
      }
  for (int v : region.surfaceVertices)
    if (v >= 0 && v < restSurface.numVertices())
      out.push_back(nearestVertex(nodes, restSurface.V.row(v).transpose()));
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

}  // namespace deform
