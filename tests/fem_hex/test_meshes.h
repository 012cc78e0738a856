// Closed test surfaces for the fem_hex tests (until the phantoms land on main).
#pragma once

#include <deform/sdk/mesh.h>

#include <cmath>
#include <map>
#include <tuple>

namespace deform::fem_hex_test {

/// Axis-aligned box [lo, hi] with div(d) segments along axis d; outward oriented, closed.
inline SurfaceMesh boxSurface(const Vec3& lo, const Vec3& hi, const Vec3i& div) {
  SurfaceMesh m;
  std::map<std::tuple<int, int, int>, int> index;
  std::vector<Vec3> verts;
  std::vector<Eigen::Vector3i> faces;
  auto vertex = [&](int i, int j, int k) {
    auto key = std::make_tuple(i, j, k);
    auto it = index.find(key);
    if (it != index.end()) return it->second;
    const Vec3 t(Real(i) / div.x(), Real(j) / div.y(), Real(k) / div.z());
    verts.push_back(lo + (hi - lo).cwiseProduct(t));
    index[key] = static_cast<int>(verts.size()) - 1;
    return static_cast<int>(verts.size()) - 1;
  };
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    for (int side = 0; side < 2; ++side) {
      for (int a = 0; a < div[u]; ++a) {
        for (int b = 0; b < div[v]; ++b) {
          int q[4];
          const int du[4] = {0, 1, 1, 0}, dv[4] = {0, 0, 1, 1};
          for (int c = 0; c < 4; ++c) {
            Vec3i ijk;
            ijk[axis] = side ? div[axis] : 0;
            ijk[u] = a + du[c];
            ijk[v] = b + dv[c];
            q[c] = vertex(ijk.x(), ijk.y(), ijk.z());
          }
          // (u, v, axis) is right-handed: counter-clockwise in (u, v) faces +axis.
          if (side) {
            faces.emplace_back(q[0], q[1], q[2]);
            faces.emplace_back(q[0], q[2], q[3]);
          } else {
            faces.emplace_back(q[0], q[2], q[1]);
            faces.emplace_back(q[0], q[3], q[2]);
          }
        }
      }
    }
  }
  m.V.resize(verts.size(), 3);
  for (size_t i = 0; i < verts.size(); ++i) m.V.row(i) = verts[i].transpose();
  m.F.resize(faces.size(), 3);
  for (size_t i = 0; i < faces.size(); ++i) m.F.row(i) = faces[i].transpose();
  return m;
}

/// Ellipsoid with semi-axes r centred at c, as a UV sphere (stacks x slices), outward oriented.
inline SurfaceMesh ellipsoidSurface(const Vec3& c, const Vec3& r, int stacks, int slices) {
  SurfaceMesh m;
  const int nv = (stacks - 1) * slices + 2;
  m.V.resize(nv, 3);
  m.V.row(0) = (c + Vec3(0, 0, -r.z())).transpose();
  for (int i = 1; i < stacks; ++i) {
    const Real th = M_PI * i / stacks;
    for (int j = 0; j < slices; ++j) {
      const Real ph = 2 * M_PI * j / slices;
      m.V.row(1 + (i - 1) * slices + j) =
          (c + Vec3(r.x() * std::sin(th) * std::cos(ph), r.y() * std::sin(th) * std::sin(ph),
                    -r.z() * std::cos(th)))
              .transpose();
    }
  }
  m.V.row(nv - 1) = (c + Vec3(0, 0, r.z())).transpose();
  std::vector<Eigen::Vector3i> f;
  auto ring = [&](int i, int j) { return 1 + (i - 1) * slices + (j % slices); };
  for (int j = 0; j < slices; ++j) f.emplace_back(0, ring(1, j + 1), ring(1, j));
  for (int i = 1; i < stacks - 1; ++i) {
    for (int j = 0; j < slices; ++j) {
      f.emplace_back(ring(i, j), ring(i, j + 1), ring(i + 1, j + 1));
      f.emplace_back(ring(i, j), ring(i + 1, j + 1), ring(i + 1, j));
    }
  }
  for (int j = 0; j < slices; ++j)
    f.emplace_back(nv - 1, ring(stacks - 1, j), ring(stacks - 1, j + 1));
  m.F.resize(f.size(), 3);
  for (size_t i = 0; i < f.size(); ++i) m.F.row(i) = f[i].transpose();
  if (signedVolume(m.V, m.F) < 0) m.F.col(1).swap(m.F.col(2));
  return m;
}

/// Liver-sized stand-in: ellipsoid about 0.2 x 0.15 x 0.09 m.
inline SurfaceMesh liverLike() {
  return ellipsoidSurface(Vec3(0, 0, 0), Vec3(0.1, 0.075, 0.045), 40, 80);
}

}  // namespace deform::fem_hex_test
