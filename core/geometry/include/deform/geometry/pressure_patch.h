// deformbench geometry: a point force read as a pressure patch on a triangle surface, and the
// quadrature of its kernel over one triangle (shared by the harness's interaction and the models
// that spread a load over their own faces, such as the reference FEM's quadratic triangles).
#pragma once

#include <deform/sdk/mesh.h>

#include <algorithm>
#include <array>
#include <utility>
#include <vector>

namespace deform {

/// The pressure kernel k(rho) = max(0, 1 - rho^2), rho = |X - centre| / radius, integrated over
/// the triangle X0 X1 X2 on kSub x kSub sub-triangles with the 6-point degree-4 rule (Strang & Fix
/// 1973, table 4.1): fn(L, k) at every quadrature point, L its barycentric coordinates (L0, L1,
/// L2) on the triangle, k the kernel times the rule's weight and the sub-triangle's area (that
/// point's share of integral k dA; 0 outside the disc). The sub-triangles follow the kink of k
/// at rho = 1.
template <class Fn>
void pressureKernelQuadrature(const Vec3& X0, const Vec3& X1, const Vec3& X2, const Vec3& centre,
                              Real radius, int kSub, Fn&& fn) {
  // Barycentric (a, a, 1 - 2a) with weight wa and (b, b, 1 - 2b) with weight wb, permuted.
  constexpr Real qa = 0.445948490915965, wa = 0.223381589678011;
  constexpr Real qb = 0.091576213509771, wb = 0.109951743655322;
  const std::array<std::pair<Vec3, Real>, 6> rule = {{{Vec3(qa, qa, 1 - 2 * qa), wa},
                                                      {Vec3(qa, 1 - 2 * qa, qa), wa},
                                                      {Vec3(1 - 2 * qa, qa, qa), wa},
                                                      {Vec3(qb, qb, 1 - 2 * qb), wb},
                                                      {Vec3(qb, 1 - 2 * qb, qb), wb},
                                                      {Vec3(1 - 2 * qb, qb, qb), wb}}};
  const Real subArea = 0.5 * (X1 - X0).cross(X2 - X0).norm() / (kSub * kSub);
  // Upward (i, j), (i+1, j), (i, j+1) and downward (i+1, j), (i+1, j+1), (i, j+1) sub-triangles
  // of the barycentric grid, in (L1, L2) grid coordinates.
  for (int i = 0; i < kSub; ++i)
    for (int j = 0; i + j < kSub; ++j)
      for (int down = 0; down < 2; ++down) {
        if (down && i + j + 2 > kSub) continue;
        const std::array<Eigen::Vector2d, 3> sub =
            down ? std::array<Eigen::Vector2d, 3>{Eigen::Vector2d(i + 1, j),
                                                  Eigen::Vector2d(i + 1, j + 1),
                                                  Eigen::Vector2d(i, j + 1)}
                 : std::array<Eigen::Vector2d, 3>{Eigen::Vector2d(i, j), Eigen::Vector2d(i + 1, j),
                                                  Eigen::Vector2d(i, j + 1)};
        for (const auto& [l, w] : rule) {
          const Eigen::Vector2d s = (l(0) * sub[0] + l(1) * sub[1] + l(2) * sub[2]) / kSub;
          const Vec3 L(1 - s(0) - s(1), s(0), s(1));
          const Vec3 X = L(0) * X0 + L(1) * X1 + L(2) * X2;
          const Real rho = (X - centre).norm() / radius;
          fn(L, std::max<Real>(0, 1 - rho * rho) * w * subArea);
        }
      }
}

/// A point force read as a pressure patch of radius R around surface vertex c:
///     t(x) = F k(|x - x_c|) / integral k dA,   k(rho) = 1 - (rho / R)^2 for rho < R, else 0,
/// a paraboloid profile (the support and shape of the Hertz pressure under a rigid sphere tip),
/// turned into consistent nodal forces on the linear surface triangles,
///     f_i = F integral N_i k dA / integral k dA,
/// integrated on 8 x 8 sub-triangles per triangle (pressureKernelQuadrature) over the triangles
/// around the vertices reachable from c through edges that stay inside the disc (so a thin
/// organ's far side is never loaded). Distances are taken at rest (a dead load with a fixed
/// distribution); the weights sum to 1. A patch too small for the quadrature to see (R far below
/// the edge length) puts the whole force on c.
struct SurfacePatch {
  std::vector<int> vertices;  ///< the centre first, then ascending
  std::vector<Real> weights;  ///< sums to 1
  Real radius = 0;            ///< R, m
};
SurfacePatch pressurePatch(const SurfaceMesh& rest, int c, Real radius);

}  // namespace deform
