// Simple closed shapes for tests and benchmarks of the reference FEM (no phantom needed):
// structured Kuhn tet meshes of boxes and their boundary surfaces (icospheres: tests/support).
#pragma once

#include <deform/sdk/mesh.h>

#include <array>
#include <map>

namespace deform::reference_fem {

/// Structured tet mesh of the box [lo, hi] with n = (nx, ny, nz) cells, each cell split into six
/// tets around its main diagonal (Kuhn), conforming across cells. Nodes in lexicographic order
/// (x fastest). All tets positively oriented.
inline TetMesh structuredBoxTets(const Vec3& lo, const Vec3& hi, const Vec3i& n) {
  TetMesh m;
  const int nx = n(0) + 1, ny = n(1) + 1, nz = n(2) + 1;
  m.V.resize(nx * ny * nz, 3);
  auto id = [&](int i, int j, int k) { return i + nx * (j + ny * k); };
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i)
        m.V.row(id(i, j, k)) << lo(0) + (hi(0) - lo(0)) * i / n(0),
            lo(1) + (hi(1) - lo(1)) * j / n(1), lo(2) + (hi(2) - lo(2)) * k / n(2);
  static const int perms[6][3] = {{0, 1, 2}, {0, 2, 1}, {1, 0, 2}, {1, 2, 0}, {2, 0, 1}, {2, 1, 0}};
  m.T.resize(6 * n(0) * n(1) * n(2), 4);
  int t = 0;
  for (int k = 0; k < n(2); ++k)
    for (int j = 0; j < n(1); ++j)
      for (int i = 0; i < n(0); ++i)
        for (const auto& p : perms) {
          Vec3i c(0, 0, 0);
          std::array<int, 4> v;
          v[0] = id(i, j, k);
          for (int s = 0; s < 3; ++s) {
            c(p[s]) = 1;
            v[s + 1] = id(i + c(0), j + c(1), k + c(2));
          }
          if (tetVolume(m.V.row(v[0]), m.V.row(v[1]), m.V.row(v[2]), m.V.row(v[3])) < 0)
            std::swap(v[2], v[3]);
          m.T.row(t++) << v[0], v[1], v[2], v[3];
        }
  return m;
}

/// Renumbers a tet mesh so that its boundary nodes come first (in their old relative order);
/// returns the boundary surface over those first nodes (as a closed SurfaceMesh).
inline SurfaceMesh boundaryFirst(TetMesh& m) {
  const SurfaceMesh b = tetBoundary(m);
  std::vector<char> onBoundary(m.numVertices(), 0);
  for (int f = 0; f < b.numFaces(); ++f)
    for (int k = 0; k < 3; ++k) onBoundary[b.F(f, k)] = 1;
  std::vector<int> newIndex(m.numVertices());
  int next = 0;
  for (int i = 0; i < m.numVertices(); ++i)
    if (onBoundary[i]) newIndex[i] = next++;
  const int nb = next;
  for (int i = 0; i < m.numVertices(); ++i)
    if (!onBoundary[i]) newIndex[i] = next++;
  MatX3 V(m.numVertices(), 3);
  for (int i = 0; i < m.numVertices(); ++i) V.row(newIndex[i]) = m.V.row(i);
  for (int t = 0; t < m.numTets(); ++t)
    for (int k = 0; k < 4; ++k) m.T(t, k) = newIndex[m.T(t, k)];
  m.V = V;
  SurfaceMesh s;
  s.V = V.topRows(nb);
  s.F.resize(b.numFaces(), 3);
  for (int f = 0; f < b.numFaces(); ++f)
    for (int k = 0; k < 3; ++k) s.F(f, k) = newIndex[b.F(f, k)];
  return s;
}

/// Closed surface of a box with n cells per axis (the boundary of structuredBoxTets).
inline SurfaceMesh boxSurface(const Vec3& lo, const Vec3& hi, const Vec3i& n) {
  TetMesh m = structuredBoxTets(lo, hi, n);
  return boundaryFirst(m);
}

}  // namespace deform::reference_fem
