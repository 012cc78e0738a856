#include <deform/sdk/model.h>

namespace deform {

std::vector<int> graspedSurfaceVertices(const MatX3& rest, const Vec3& p, Real r) {
  std::vector<int> out;
  const Real r2 = r * r;
  for (Eigen::Index v = 0; v < rest.rows(); ++v)
    if ((rest.row(v).transpose() - p).squaredNorm() <= r2) out.push_back(int(v));
  if (out.empty()) {
    const int n = nearestVertex(rest, p);
    if (n >= 0) out.push_back(n);
  }
  return out;
}

}  // namespace deform
