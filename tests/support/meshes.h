// Test meshes generated in code (no data files, no phantoms), shared by the tests and the
// benchmarks of several plugins: icospheres and ellipsoids, a liver-sized UV ellipsoid, a flat
// equilateral sheet and a structured tet box. Tests include it as "../support/meshes.h",
// the benchmarks as "support/meshes.h" (with tests/ on their include path).
#pragma once

#include <deform/sdk/mesh.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <utility>
#include <vector>

namespace deform::testing {

/// Icosphere of radius r centred at c: the icosahedron with `levels` 4-way subdivisions, new
/// vertices projected onto the sphere (12, 42, 162, 642, 2562 vertices). Closed, outward.
inline SurfaceMesh icosphere(int levels, Real r = 1.0, const Vec3& c = Vec3::Zero()) {
  const Real t = (1.0 + std::sqrt(5.0)) / 2.0;
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
      const auto it = mid.find(key);
      if (it != mid.end()) return it->second;
      v.push_back((v[size_t(a)] + v[size_t(b)]).normalized());
      mid[key] = int(v.size()) - 1;
      return int(v.size()) - 1;
    };
    std::vector<Vec3i> g;
    for (const Vec3i& tri : f) {
      const int a = midpoint(tri[0], tri[1]), b = midpoint(tri[1], tri[2]),
                e = midpoint(tri[2], tri[0]);
      g.push_back({tri[0], a, e});
      g.push_back({tri[1], b, a});
      g.push_back({tri[2], e, b});
      g.push_back({a, b, e});
    }
    f.swap(g);
  }
  SurfaceMesh s;
  s.V.resize(Eigen::Index(v.size()), 3);
  for (size_t i = 0; i < v.size(); ++i) s.V.row(Eigen::Index(i)) = (c + r * v[i]).transpose();
  s.F.resize(Eigen::Index(f.size()), 3);
  for (size_t i = 0; i < f.size(); ++i) s.F.row(Eigen::Index(i)) = f[i].transpose();
  return s;
}

/// Closed 2-manifold check: every undirected edge in exactly two faces, used once per direction.
/// Returns the number of bad (directed) edges; 0 for a closed, consistently oriented surface.
inline int badEdges(const SurfaceMesh& s) {
  std::map<std::pair<int, int>, int> directed;
  for (int f = 0; f < s.numFaces(); ++f)
    for (int k = 0; k < 3; ++k) ++directed[{s.F(f, k), s.F(f, (k + 1) % 3)}];
  int bad = 0;
  for (const auto& [e, count] : directed) {
    const auto it = directed.find({e.second, e.first});
    if (count != 1 || it == directed.end() || it->second != 1) ++bad;
  }
  return bad;
}

/// The unit icosphere scaled by the semi-axes `radii` (m), centred at the origin.
inline SurfaceMesh ellipsoid(int levels, const Vec3& radii) {
  SurfaceMesh s = icosphere(levels);
  for (Eigen::Index i = 0; i < s.V.rows(); ++i)
    s.V.row(i) = s.V.row(i).cwiseProduct(radii.transpose());
  return s;
}

/// Closed UV ellipsoid with semi-axes (ax, by, cz), m: 2 + (rings) * segments vertices, outward
/// oriented. rings >= 2, segments >= 3.
inline SurfaceMesh uvEllipsoid(int rings, int segments, Real ax, Real by, Real cz) {
  const Real pi = std::numbers::pi_v<Real>;
  SurfaceMesh m;
  const int nv = 2 + rings * segments;
  m.V.resize(nv, 3);
  m.V.row(0) << 0, 0, cz;
  for (int i = 0; i < rings; ++i) {
    const Real th = pi * (i + 1) / (rings + 1);
    for (int j = 0; j < segments; ++j) {
      // Stagger alternate rings by half a segment: better-shaped triangles.
      const Real ph = 2 * pi * (j + 0.5 * (i % 2)) / segments;
      m.V.row(1 + i * segments + j) << ax * std::sin(th) * std::cos(ph),
          by * std::sin(th) * std::sin(ph), cz * std::cos(th);
    }
  }
  m.V.row(nv - 1) << 0, 0, -cz;
  auto ring = [&](int i, int j) {
    return 1 + i * segments + ((j % segments) + segments) % segments;
  };
  std::vector<Vec3i> f;
  for (int j = 0; j < segments; ++j) f.emplace_back(0, ring(0, j), ring(0, j + 1));
  for (int i = 0; i + 1 < rings; ++i) {
    for (int j = 0; j < segments; ++j) {
      if (i % 2 == 0) {  // ring i+1 is shifted by +half a segment
        f.emplace_back(ring(i, j), ring(i + 1, j), ring(i, j + 1));
        f.emplace_back(ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1));
      } else {  // ring i is shifted
        f.emplace_back(ring(i, j), ring(i + 1, j), ring(i + 1, j + 1));
        f.emplace_back(ring(i, j), ring(i + 1, j + 1), ring(i, j + 1));
      }
    }
  }
  for (int j = 0; j < segments; ++j)
    f.emplace_back(nv - 1, ring(rings - 1, j + 1), ring(rings - 1, j));
  m.F.resize(static_cast<Eigen::Index>(f.size()), 3);
  for (size_t k = 0; k < f.size(); ++k) m.F.row(k) = f[k].transpose();
  if (signedVolume(m.V, m.F) < 0) m.F.col(1).swap(m.F.col(2));
  return m;
}

/// Liver-sized closed surface with about 2.2k vertices and 6.6k edges (46 rings x 48 segments).
inline SurfaceMesh liverSizedSurface() {
  return uvEllipsoid(46, 48, 0.10, 0.075, 0.04);
}

/// Flat sheet of equilateral triangles in the z = 0 plane: rows x cols vertices, spacing a (m),
/// odd rows shifted by a/2. Normals point to +z.
inline SurfaceMesh equilateralSheet(int rows, int cols, Real a) {
  SurfaceMesh m;
  m.V.resize(rows * cols, 3);
  const Real h = a * std::sqrt(3.0) / 2.0;
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) m.V.row(r * cols + c) << a * (c + 0.5 * (r % 2)), h * r, 0.0;
  std::vector<Vec3i> f;
  auto id = [&](int r, int c) { return r * cols + c; };
  for (int r = 0; r + 1 < rows; ++r) {
    for (int c = 0; c + 1 < cols; ++c) {
      if (r % 2 == 0) {
        f.emplace_back(id(r, c), id(r, c + 1), id(r + 1, c));
        f.emplace_back(id(r, c + 1), id(r + 1, c + 1), id(r + 1, c));
      } else {
        f.emplace_back(id(r, c), id(r + 1, c + 1), id(r + 1, c));
        f.emplace_back(id(r, c), id(r, c + 1), id(r + 1, c + 1));
      }
    }
  }
  m.F.resize(static_cast<Eigen::Index>(f.size()), 3);
  for (size_t k = 0; k < f.size(); ++k) m.F.row(k) = f[k].transpose();
  return m;
}

/// Box [0,lx]x[0,ly]x[0,lz] split into nx*ny*nz cubes of 6 positively oriented tets each
/// (Kuhn subdivision, conforming across cubes).
inline TetMesh tetBox(int nx, int ny, int nz, Real lx, Real ly, Real lz) {
  TetMesh t;
  auto id = [&](int i, int j, int k) { return (k * (ny + 1) + j) * (nx + 1) + i; };
  t.V.resize((nx + 1) * (ny + 1) * (nz + 1), 3);
  for (int k = 0; k <= nz; ++k)
    for (int j = 0; j <= ny; ++j)
      for (int i = 0; i <= nx; ++i) t.V.row(id(i, j, k)) << lx * i / nx, ly * j / ny, lz * k / nz;
  // The six Kuhn tets share the diagonal 0-7 of the cube; corners c[b] with bit 0 = x, 1 = y, 2 =
  // z.
  const int paths[6][4] = {{0, 1, 3, 7}, {0, 1, 5, 7}, {0, 2, 3, 7},
                           {0, 2, 6, 7}, {0, 4, 5, 7}, {0, 4, 6, 7}};
  std::vector<Vec4i> tets;
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        int c[8];
        for (int b = 0; b < 8; ++b) c[b] = id(i + (b & 1), j + ((b >> 1) & 1), k + ((b >> 2) & 1));
        for (const auto& p : paths) {
          Vec4i q(c[p[0]], c[p[1]], c[p[2]], c[p[3]]);
          if (tetVolume(t.V.row(q[0]), t.V.row(q[1]), t.V.row(q[2]), t.V.row(q[3])) < 0)
            std::swap(q[2], q[3]);
          tets.push_back(q);
        }
      }
  t.T.resize(static_cast<Eigen::Index>(tets.size()), 4);
  for (size_t k = 0; k < tets.size(); ++k) t.T.row(k) = tets[k].transpose();
  return t;
}

}  // namespace deform::testing
