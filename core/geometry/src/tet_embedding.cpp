// Points embedded in a tet mesh by barycentric coordinates (tet_embedding.h).
#include <deform/geometry/tet_embedding.h>
#include <deform/sdk/error.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace deform {

int TetEmbedding::numOutside() const {
  return static_cast<int>(
      std::count_if(outside.begin(), outside.end(), [](Real o) { return o > 0; }));
}

namespace {

/// Barycentric coordinates of p in tet (a, b, c, d); false for a degenerate tet.
bool barycentric(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d, const Vec3& p,
                 std::array<Real, 4>& L) {
  Mat3 M;
  M.col(0) = b - a;
  M.col(1) = c - a;
  M.col(2) = d - a;
  const Real det = M.determinant();
  const Real scale = (b - a).norm() * (c - a).norm() * (d - a).norm();
  if (!(std::fabs(det) > 1e-12 * scale)) return false;
  const Vec3 l = M.inverse() * (p - a);
  L = {1 - l.sum(), l(0), l(1), l(2)};
  return true;
}

}  // namespace

TetEmbedding embedInTets(const MatX3& nodes, const MatX4i& tets, const MatX3& points) {
  if (tets.rows() == 0) throw InputError("", "", "cannot embed points: the mesh has no tet");
  const Eigen::Index nt = tets.rows();
  // Bounding boxes of the tets, for a cheap rejection before the barycentric solve.
  std::vector<Box> boxes(static_cast<size_t>(nt));
  for (Eigen::Index t = 0; t < nt; ++t) {
    Box& b = boxes[size_t(t)];
    b.lo = b.hi = nodes.row(tets(t, 0)).transpose();
    for (int k = 1; k < 4; ++k) {
      b.lo = b.lo.cwiseMin(nodes.row(tets(t, k)).transpose());
      b.hi = b.hi.cwiseMax(nodes.row(tets(t, k)).transpose());
    }
  }
  const Real tol = 1e-9;
  TetEmbedding e;
  e.tet.assign(size_t(points.rows()), -1);
  e.weights.assign(size_t(points.rows()), {0, 0, 0, 0});
  e.outside.assign(size_t(points.rows()), 0);
  for (Eigen::Index p = 0; p < points.rows(); ++p) {
    const Vec3 x = points.row(p).transpose();
    Real best = -std::numeric_limits<Real>::infinity();
    int bestTet = -1;
    std::array<Real, 4> bestL{};
    bool inside = false;
    // Inside: the first tet (in index order) that contains x, so the choice is deterministic.
    for (Eigen::Index t = 0; t < nt && !inside; ++t) {
      const Box& b = boxes[size_t(t)];
      const Vec3 pad = Vec3::Constant(1e-9 * std::max<Real>(b.diagonal(), 1e-30));
      if (((x - b.lo).array() < -pad.array()).any() || ((x - b.hi).array() > pad.array()).any())
        continue;
      std::array<Real, 4> L;
      if (!barycentric(nodes.row(tets(t, 0)), nodes.row(tets(t, 1)), nodes.row(tets(t, 2)),
                       nodes.row(tets(t, 3)), x, L))
        continue;
      const Real m = *std::min_element(L.begin(), L.end());
      if (m >= -tol) {
        best = m;
        bestTet = int(t);
        bestL = L;
        inside = true;
      }
    }
    if (!inside) {
      // Outside the mesh: the tet whose smallest coordinate is largest.
      for (Eigen::Index t = 0; t < nt; ++t) {
        std::array<Real, 4> L;
        if (!barycentric(nodes.row(tets(t, 0)), nodes.row(tets(t, 1)), nodes.row(tets(t, 2)),
                         nodes.row(tets(t, 3)), x, L))
          continue;
        const Real m = *std::min_element(L.begin(), L.end());
        if (m > best) {
          best = m;
          bestTet = int(t);
          bestL = L;
        }
      }
      if (bestTet < 0) throw InputError("", "", "cannot embed points: every tet is degenerate");
      e.outside[size_t(p)] = -best;
    }
    e.tet[size_t(p)] = bestTet;
    e.weights[size_t(p)] = bestL;
  }
  return e;
}

MatX3 embeddedPositions(const TetEmbedding& e, const MatX3& nodes, const MatX4i& tets) {
  MatX3 out(Eigen::Index(e.tet.size()), 3);
  for (size_t p = 0; p < e.tet.size(); ++p) {
    Vec3 x = Vec3::Zero();
    for (int a = 0; a < 4; ++a) x += e.weights[p][a] * nodes.row(tets(e.tet[p], a)).transpose();
    out.row(Eigen::Index(p)) = x.transpose();
  }
  return out;
}

}  // namespace deform
