#include <deform/geometry/pressure_patch.h>

#include <algorithm>
#include <map>

namespace deform {

SurfacePatch pressurePatch(const SurfaceMesh& rest, int c, Real radius) {
  SurfacePatch patch;
  patch.radius = radius;
  const int nv = rest.numVertices();
  if (c < 0 || c >= nv) return patch;
  const Vec3 centre = rest.V.row(c).transpose();
  std::vector<std::vector<int>> faces(static_cast<size_t>(nv)), neighbors(static_cast<size_t>(nv));
  for (int f = 0; f < rest.numFaces(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = rest.F(f, k), b = rest.F(f, (k + 1) % 3);
      faces[size_t(a)].push_back(f);
      neighbors[size_t(a)].push_back(b);
      neighbors[size_t(b)].push_back(a);
    }
  // Vertices reachable from c through edges whose ends lie inside the disc; their triangles.
  std::vector<char> seen(size_t(nv), 0);
  std::vector<int> reach = {c};
  seen[size_t(c)] = 1;
  for (size_t head = 0; head < reach.size(); ++head)
    for (int n : neighbors[size_t(reach[head])]) {
      if (seen[size_t(n)] || (rest.V.row(n).transpose() - centre).norm() >= radius) continue;
      seen[size_t(n)] = 1;
      reach.push_back(n);
    }
  std::vector<int> tris;
  for (int v : reach) tris.insert(tris.end(), faces[size_t(v)].begin(), faces[size_t(v)].end());
  std::sort(tris.begin(), tris.end());
  tris.erase(std::unique(tris.begin(), tris.end()), tris.end());

  constexpr int kSub = 8;  // sub-triangles per edge: k has a kink at rho = R
  std::map<int, Real> load;
  Real total = 0;
  for (int f : tris) {
    const int i0 = rest.F(f, 0), i1 = rest.F(f, 1), i2 = rest.F(f, 2);
    const Vec3 X0 = rest.V.row(i0), X1 = rest.V.row(i1), X2 = rest.V.row(i2);
    Vec3 fi = Vec3::Zero();
    pressureKernelQuadrature(X0, X1, X2, centre, radius, kSub, [&](const Vec3& N, Real k) {
      fi += k * N;
      total += k;
    });
    load[i0] += fi(0);
    load[i1] += fi(1);
    load[i2] += fi(2);
  }
  if (!(total > 0)) {
    patch.vertices = {c};
    patch.weights = {1.0};
    return patch;
  }
  patch.vertices.push_back(c);
  patch.weights.push_back(load[c] / total);
  for (const auto& [v, f] : load) {
    if (v == c || f <= 0) continue;
    patch.vertices.push_back(v);
    patch.weights.push_back(f / total);
  }
  return patch;
}

}  // namespace deform
