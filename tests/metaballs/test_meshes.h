// Test meshes for the metaballs tests that must not wait for the phantoms: icosphere-based closed
// surfaces (closed, manifold, outward oriented).
#pragma once

#include <deform/mesh.h>

#include <map>
#include <utility>

namespace deform::metaballs::test {

inline SurfaceMesh icosphere(int level) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Vec3> v = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  for (auto& p : v) p.normalize();
  std::vector<Vec3i> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                          {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                          {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                          {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int l = 0; l < level; ++l) {
    std::map<std::pair<int, int>, int> mid;
    auto midpoint = [&](int a, int b) {
      const auto key = std::make_pair(std::min(a, b), std::max(a, b));
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[size_t(a)] + v[size_t(b)]).normalized());
      mid[key] = int(v.size()) - 1;
      return int(v.size()) - 1;
    };
    std::vector<Vec3i> nf;
    for (const auto& tri : f) {
      const int a = midpoint(tri[0], tri[1]), b = midpoint(tri[1], tri[2]),
                c = midpoint(tri[2], tri[0]);
      nf.push_back({tri[0], a, c});
      nf.push_back({tri[1], b, a});
      nf.push_back({tri[2], c, b});
      nf.push_back({a, b, c});
    }
    f.swap(nf);
  }
  SurfaceMesh m;
  m.V.resize(Eigen::Index(v.size()), 3);
  for (size_t i = 0; i < v.size(); ++i) m.V.row(Eigen::Index(i)) = v[i].transpose();
  m.F.resize(Eigen::Index(f.size()), 3);
  for (size_t i = 0; i < f.size(); ++i) m.F.row(Eigen::Index(i)) = f[i].transpose();
  return m;
}

/// Ellipsoid with semi-axes a, b, c (m).
inline SurfaceMesh ellipsoid(Real a, Real b, Real c, int level) {
  SurfaceMesh m = icosphere(level);
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) {
    m.V(i, 0) *= a;
    m.V(i, 1) *= b;
    m.V(i, 2) *= c;
  }
  return m;
}

/// A banana: an elongated ellipsoid bent along a circular arc in the x-z plane (non-convex).
inline SurfaceMesh banana(Real length, Real radius, Real bend, int level) {
  SurfaceMesh m = ellipsoid(0.5 * length, radius, radius, level);
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) m.V(i, 2) += bend * m.V(i, 0) * m.V(i, 0) / length;
  return m;
}

}  // namespace deform::metaballs::test
