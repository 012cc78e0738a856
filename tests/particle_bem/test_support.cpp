#include "test_support.h"

#include <algorithm>
#include <cmath>
#include <map>

namespace deform::particle_bem::testing {

SurfaceMesh icosphere(int levels, Real r, const Vec3& c) {
  const Real t = (1 + std::sqrt(5.0)) / 2;
  std::vector<Vec3> v = {{-1, t, 0},  {1, t, 0},  {-1, -t, 0}, {1, -t, 0}, {0, -1, t},  {0, 1, t},
                         {0, -1, -t}, {0, 1, -t}, {t, 0, -1},  {t, 0, 1},  {-t, 0, -1}, {-t, 0, 1}};
  std::vector<Vec3i> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                          {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                          {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                          {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (Vec3& p : v) p.normalize();
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<int, int>, int> mid;
    const auto midpoint = [&](int a, int b) {
      const auto key = std::make_pair(std::min(a, b), std::max(a, b));
      auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[a] + v[b]).normalized());
      mid[key] = int(v.size()) - 1;
      return int(v.size()) - 1;
    };
    std::vector<Vec3i> g;
    for (const Vec3i& tri : f) {
      const int a = midpoint(tri[0], tri[1]), b = midpoint(tri[1], tri[2]),
                c2 = midpoint(tri[2], tri[0]);
      g.push_back({tri[0], a, c2});
      g.push_back({tri[1], b, a});
      g.push_back({tri[2], c2, b});
      g.push_back({a, b, c2});
    }
    f = g;
  }
  SurfaceMesh s;
  s.V.resize(v.size(), 3);
  for (size_t i = 0; i < v.size(); ++i) s.V.row(i) = (c + r * v[i]).transpose();
  s.F.resize(f.size(), 3);
  for (size_t i = 0; i < f.size(); ++i) s.F.row(i) = f[i].transpose();
  return s;
}

SurfaceMesh ellipsoid(int levels, const Vec3& radii) {
  SurfaceMesh s = icosphere(levels, 1.0);
  for (Eigen::Index i = 0; i < s.V.rows(); ++i)
    s.V.row(i) = s.V.row(i).cwiseProduct(radii.transpose());
  return s;
}

int badEdges(const SurfaceMesh& s) {
  std::map<std::pair<int, int>, int> directed;
  for (int f = 0; f < s.numFaces(); ++f)
    for (int k = 0; k < 3; ++k) ++directed[{s.F(f, k), s.F(f, (k + 1) % 3)}];
  int bad = 0;
  for (const auto& [e, count] : directed) {
    auto it = directed.find({e.second, e.first});
    if (count != 1 || it == directed.end() || it->second != 1) ++bad;
  }
  return bad;
}

}  // namespace deform::particle_bem::testing
