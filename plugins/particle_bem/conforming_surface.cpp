#include "conforming_surface.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

namespace deform::particle_bem {

namespace {

int sideOf(Real d) {
  return d > 0 ? 1 : (d < 0 ? -1 : 0);
}

// One plane x_axis = value: snap, split the crossing edges, re-triangulate the crossed faces.
SurfaceMesh cutByPlane(const SurfaceMesh& in, int axis, Real value, Real snapFraction,
                       ConformStats& st) {
  const int nv = in.numVertices(), nf = in.numFaces();
  std::vector<Vec3> x(nv);
  for (int v = 0; v < nv; ++v) x[v] = in.V.row(v).transpose();
  std::vector<Real> shortest(nv, std::numeric_limits<Real>::infinity());
  for (int f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = in.F(f, k), b = in.F(f, (k + 1) % 3);
      const Real l = (x[a] - x[b]).norm();
      shortest[a] = std::min(shortest[a], l);
      shortest[b] = std::min(shortest[b], l);
    }
  std::vector<int> side(nv);
  for (int v = 0; v < nv; ++v) {
    const Real d = x[v][axis] - value;
    if (d != 0 && std::abs(d) < snapFraction * shortest[v]) {
      x[v][axis] = value;
      ++st.snappedVertices;
    }
    side[v] = sideOf(x[v][axis] - value);
  }
  // Crossing edges get one vertex each, shared by both faces (keeps the surface closed).
  std::map<std::pair<int, int>, int> cut;
  for (int f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = in.F(f, k), b = in.F(f, (k + 1) % 3);
      if (side[a] * side[b] >= 0) continue;
      const auto key = std::make_pair(std::min(a, b), std::max(a, b));
      if (cut.count(key)) continue;
      const Vec3& p = x[key.first];
      const Vec3& q = x[key.second];
      const Real t = (value - p[axis]) / (q[axis] - p[axis]);
      Vec3 m = p + t * (q - p);
      m[axis] = value;
      cut[key] = int(x.size());
      x.push_back(m);
      side.push_back(0);
      ++st.splitEdges;
    }
  std::vector<Vec3i> faces;
  faces.reserve(nf + 2 * cut.size());
  for (int f = 0; f < nf; ++f) {
    // The face as a polygon with the cut points inserted, in the face's cyclic order.
    std::vector<int> poly;
    for (int k = 0; k < 3; ++k) {
      const int a = in.F(f, k), b = in.F(f, (k + 1) % 3);
      poly.push_back(a);
      auto it = cut.find({std::min(a, b), std::max(a, b)});
      if (it != cut.end()) poly.push_back(it->second);
    }
    if (poly.size() == 3) {
      faces.push_back(in.F.row(f).transpose());
      continue;
    }
    // The plane meets the polygon in exactly two on-plane corners; the chord between them
    // splits it into two parts, one on each side.
    std::vector<int> zero;
    for (size_t i = 0; i < poly.size(); ++i)
      if (side[poly[i]] == 0) zero.push_back(int(i));
    const int n = int(poly.size());
    const auto emit = [&](int from, int to) {  // poly[from .. to] cyclically, fan / quad
      std::vector<int> part;
      for (int i = from;; i = (i + 1) % n) {
        part.push_back(poly[i]);
        if (i == to) break;
      }
      if (part.size() == 3) {
        faces.push_back(Vec3i(part[0], part[1], part[2]));
      } else {  // quadrilateral: the shorter diagonal
        const Real d02 = (x[part[0]] - x[part[2]]).squaredNorm();
        const Real d13 = (x[part[1]] - x[part[3]]).squaredNorm();
        if (d02 <= d13) {
          faces.push_back(Vec3i(part[0], part[1], part[2]));
          faces.push_back(Vec3i(part[0], part[2], part[3]));
        } else {
          faces.push_back(Vec3i(part[1], part[2], part[3]));
          faces.push_back(Vec3i(part[1], part[3], part[0]));
        }
      }
    };
    emit(zero[0], zero[1]);
    emit(zero[1], zero[0]);
  }
  SurfaceMesh out;
  out.V.resize(Eigen::Index(x.size()), 3);
  for (size_t v = 0; v < x.size(); ++v) out.V.row(Eigen::Index(v)) = x[v].transpose();
  out.F.resize(Eigen::Index(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f) out.F.row(Eigen::Index(f)) = faces[f].transpose();
  return out;
}

}  // namespace

SurfaceMesh conformToBoxes(const SurfaceMesh& in, const std::vector<Box>& boxes,
                           ConformStats* stats, Real snapFraction) {
  ConformStats st;
  SurfaceMesh s = in;
  for (const Box& b : boxes)
    for (int axis = 0; axis < 3; ++axis)
      for (const Real value : {b.lo[axis], b.hi[axis]}) {
        const Real lo = s.V.col(axis).minCoeff(), hi = s.V.col(axis).maxCoeff();
        if (!(lo < value && value < hi)) continue;
        s = cutByPlane(s, axis, value, snapFraction, st);
        ++st.planesCut;
      }
  if (stats) *stats = st;
  return s;
}

std::vector<char> facesInBoxes(const MatX3& V, const MatX3i& F, const std::vector<Box>& boxes) {
  std::vector<char> tag(F.rows(), 0);
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (const Box& b : boxes)
      if (b.contains(V.row(F(f, 0)).transpose()) && b.contains(V.row(F(f, 1)).transpose()) &&
          b.contains(V.row(F(f, 2)).transpose())) {
        tag[f] = 1;
        break;
      }
  return tag;
}

bool triangleConforms(const Vec3& x0, const Vec3& x1, const Vec3& x2, bool inside,
                      const std::vector<Box>& boxes) {
  bool inOne = false;
  for (const Box& b : boxes) {
    const bool all = b.contains(x0) && b.contains(x1) && b.contains(x2);
    inOne = inOne || all;
    if (inside) continue;
    bool separated = false;
    for (int axis = 0; axis < 3 && !separated; ++axis)
      separated = (x0[axis] >= b.hi[axis] && x1[axis] >= b.hi[axis] && x2[axis] >= b.hi[axis]) ||
                  (x0[axis] <= b.lo[axis] && x1[axis] <= b.lo[axis] && x2[axis] <= b.lo[axis]);
    if (!separated) return false;
  }
  return inside ? inOne : !inOne;
}

int nonConformingFaces(const SurfaceMesh& s, const std::vector<Box>& boxes) {
  const std::vector<char> tag = facesInBoxes(s.V, s.F, boxes);
  int bad = 0;
  for (int f = 0; f < s.numFaces(); ++f)
    bad += !triangleConforms(s.V.row(s.F(f, 0)).transpose(), s.V.row(s.F(f, 1)).transpose(),
                             s.V.row(s.F(f, 2)).transpose(), tag[f] != 0, boxes);
  return bad;
}

}  // namespace deform::particle_bem
