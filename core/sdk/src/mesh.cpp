#include <deform/sdk/mesh.h>

#include <algorithm>
#include <array>
#include <map>
#include <numeric>

namespace deform {

Box boundingBox(const MatX3& V) {
  Box b;
  if (V.rows() == 0) return b;
  b.lo = V.colwise().minCoeff().transpose();
  b.hi = V.colwise().maxCoeff().transpose();
  return b;
}

std::vector<int> rowsInBox(const MatX3& V, const Box& box) {
  std::vector<int> out;
  for (Eigen::Index v = 0; v < V.rows(); ++v)
    if (box.contains(V.row(v).transpose())) out.push_back(int(v));
  return out;
}

MatX2i uniqueEdges(const MatX3i& F) {
  std::vector<std::pair<int, int>> e;
  e.reserve(3 * F.rows());
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      int a = F(f, k), b = F(f, (k + 1) % 3);
      e.emplace_back(std::min(a, b), std::max(a, b));
    }
  }
  std::sort(e.begin(), e.end());
  e.erase(std::unique(e.begin(), e.end()), e.end());
  MatX2i E(e.size(), 2);
  for (size_t i = 0; i < e.size(); ++i) E.row(i) << e[i].first, e[i].second;
  return E;
}

MatX2i edgeFaces(const MatX3i& F, const MatX2i& E) {
  MatX2i EF = MatX2i::Constant(E.rows(), 2, -1);
  std::vector<std::array<int, 3>> keyed;  // (a, b, face), a < b
  keyed.reserve(3 * F.rows());
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      int a = F(f, k), b = F(f, (k + 1) % 3);
      keyed.push_back({std::min(a, b), std::max(a, b), static_cast<int>(f)});
    }
  }
  std::sort(keyed.begin(), keyed.end());
  size_t j = 0;
  for (Eigen::Index e = 0; e < E.rows(); ++e) {
    while (j < keyed.size() &&
           (keyed[j][0] < E(e, 0) || (keyed[j][0] == E(e, 0) && keyed[j][1] < E(e, 1)))) {
      ++j;
    }
    int slot = 0;
    while (j < keyed.size() && keyed[j][0] == E(e, 0) && keyed[j][1] == E(e, 1)) {
      if (slot < 2) EF(e, slot++) = keyed[j][2];
      ++j;
    }
  }
  return EF;
}

Real signedVolume(const MatX3& V, const MatX3i& F) {
  Real vol = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Vec3 a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
    vol += a.dot(b.cross(c));
  }
  return vol / 6.0;
}

Real surfaceArea(const MatX3& V, const MatX3i& F) {
  Real area = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Vec3 a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
    area += 0.5 * (b - a).cross(c - a).norm();
  }
  return area;
}

MatX3 vertexNormals(const MatX3& V, const MatX3i& F) {
  MatX3 N = MatX3::Zero(V.rows(), 3);
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Vec3 a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
    const Vec3 n = (b - a).cross(c - a);  // twice the area times the unit normal
    for (int k = 0; k < 3; ++k) N.row(F(f, k)) += n.transpose();
  }
  for (Eigen::Index i = 0; i < N.rows(); ++i) {
    const Real len = N.row(i).norm();
    if (len > 0) N.row(i) /= len;
  }
  return N;
}

Real tetVolume(const Vec3& x0, const Vec3& x1, const Vec3& x2, const Vec3& x3) {
  return (x1 - x0).dot((x2 - x0).cross(x3 - x0)) / 6.0;
}

void orientTetsPositive(TetMesh& mesh) {
  for (int t = 0; t < mesh.numTets(); ++t) {
    const auto r = mesh.T.row(t);
    if (tetVolume(mesh.V.row(r(0)), mesh.V.row(r(1)), mesh.V.row(r(2)), mesh.V.row(r(3))) < 0)
      std::swap(mesh.T(t, 2), mesh.T(t, 3));
  }
}

SurfaceMesh tetBoundary(const TetMesh& tets) {
  // Faces of a positively oriented tet (0,1,2,3), each counter-clockwise seen from outside.
  static constexpr int kFaces[4][3] = {{0, 2, 1}, {0, 1, 3}, {0, 3, 2}, {1, 2, 3}};
  std::map<std::array<int, 3>, std::pair<int, std::array<int, 3>>> count;
  for (Eigen::Index t = 0; t < tets.T.rows(); ++t) {
    for (const auto& lf : kFaces) {
      std::array<int, 3> f = {tets.T(t, lf[0]), tets.T(t, lf[1]), tets.T(t, lf[2])};
      std::array<int, 3> key = f;
      std::sort(key.begin(), key.end());
      auto [it, inserted] = count.try_emplace(key, 0, f);
      it->second.first++;
    }
  }
  std::vector<std::array<int, 3>> faces;
  for (const auto& [key, val] : count) {
    if (val.first == 1) faces.push_back(val.second);
  }
  SurfaceMesh s;
  s.V = tets.V;
  s.F.resize(faces.size(), 3);
  for (size_t i = 0; i < faces.size(); ++i) s.F.row(i) << faces[i][0], faces[i][1], faces[i][2];
  return s;
}

int nearestVertex(const MatX3& V, const Vec3& p) {
  if (V.rows() == 0) return -1;
  Eigen::Index best = 0;
  (V.rowwise() - p.transpose()).rowwise().squaredNorm().minCoeff(&best);
  return static_cast<int>(best);
}

std::vector<int> nearestVertices(const MatX3& V, const Vec3& p, int k) {
  const int n = static_cast<int>(V.rows());
  k = std::clamp(k, 0, n);
  VecX d2 = (V.rowwise() - p.transpose()).rowwise().squaredNorm();
  std::vector<int> idx(n);
  std::iota(idx.begin(), idx.end(), 0);
  auto less = [&](int a, int b) { return d2[a] < d2[b] || (d2[a] == d2[b] && a < b); };
  std::partial_sort(idx.begin(), idx.begin() + k, idx.end(), less);
  idx.resize(k);
  return idx;
}

}  // namespace deform
