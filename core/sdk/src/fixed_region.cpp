// The fixed region's nodes (model.h).
#include <deform/sdk/model.h>

#include <algorithm>

namespace deform {

std::vector<int> fixedNodeIndices(const MatX3& nodes, const FixedRegion& region,
                                  const SurfaceMesh& restSurface) {
  std::vector<int> out;
  for (Eigen::Index n = 0; n < nodes.rows(); ++n) {
    const Vec3 p = nodes.row(n).transpose();
    for (const Box& b : region.boxes) {
      if (b.contains(p)) {
        out.push_back(static_cast<int>(n));
        break;
      }
    }
  }
  for (int v : region.surfaceVertices) {
    if (v < 0 || v >= restSurface.numVertices()) continue;
    const int n = nearestVertex(nodes, restSurface.V.row(v).transpose());
    if (n >= 0) out.push_back(n);
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

std::vector<std::pair<int, int>> rollerNodeAxes(const MatX3& nodes, const FixedRegion& region) {
  std::vector<std::pair<int, int>> out;
  if (region.rollers.empty()) return out;
  for (Eigen::Index n = 0; n < nodes.rows(); ++n) {
    const Vec3 p = nodes.row(n).transpose();
    int axes = 0;
    for (const RollerBox& r : region.rollers)
      if (r.box.contains(p)) axes |= r.axes;
    if (axes) out.emplace_back(static_cast<int>(n), axes);
  }
  return out;
}

}  // namespace deform
