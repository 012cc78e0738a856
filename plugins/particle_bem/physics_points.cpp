#include "physics_points.h"

#include <cmath>

namespace deform::particle_bem {

namespace {
MatX3 lattice(const SignedDistanceField& sdf, const Box& box, Real s, Real margin) {
  const Vec3 c = box.center();
  Eigen::Vector3i half;
  for (int k = 0; k < 3; ++k) half[k] = int(std::ceil(0.5 * box.size()[k] / s)) + 1;
  std::vector<Vec3> pts;
  for (int k = -half[2]; k <= half[2]; ++k)
    for (int j = -half[1]; j <= half[1]; ++j)
      for (int i = -half[0]; i <= half[0]; ++i) {
        const Vec3 p = c + s * Vec3(i, j, k);
        if (sdf.value(p) < -margin) pts.push_back(p);
      }
  MatX3 P(pts.size(), 3);
  for (size_t q = 0; q < pts.size(); ++q) P.row(q) = pts[q].transpose();
  return P;
}
}  // namespace

PhysicsPoints sampleLatticeInside(const SignedDistanceField& sdf, const MatX3& surfaceV,
                                  Real volume, int target, Real marginFraction) {
  const Box box = boundingBox(surfaceV);
  target = std::max(1, target);
  Real s = std::cbrt(volume / target);
  PhysicsPoints best;
  for (int it = 0; it < 8; ++it) {
    MatX3 P = lattice(sdf, box, s, marginFraction * s);
    if (best.points.rows() == 0 ||
        std::abs(P.rows() - target) < std::abs(best.points.rows() - target)) {
      best.points = P;
      best.spacing = s;
    }
    if (std::abs(double(P.rows()) - target) <= 0.03 * target) break;
    // count ~ V / s^3: rescale the spacing by the cube root of the ratio.
    s *= std::cbrt(std::max<double>(P.rows(), 1) / target);
  }
  return best;
}

}  // namespace deform::particle_bem
