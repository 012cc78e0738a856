#include "triangle_distance.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

namespace deform::particle_bem {

TriangleGrid::TriangleGrid(const MatX3& V, const MatX3i& F, Real cellSize) : m_V(V), m_F(F) {
  const Box box = boundingBox(V);
  if (cellSize <= 0) {
    Real sum = 0;
    for (int f = 0; f < F.rows(); ++f)
      for (int k = 0; k < 3; ++k) sum += (V.row(F(f, k)) - V.row(F(f, (k + 1) % 3))).norm();
    cellSize = F.rows() > 0 ? 2 * sum / (3.0 * F.rows()) : 1.0;
  }
  // Cap the grid at 64 cells a side: beyond that the per-cell lists are mostly empty.
  cellSize = std::max(cellSize, box.size().maxCoeff() / 64.0);
  if (!(cellSize > 0)) cellSize = 1;
  m_cell = cellSize;
  m_lo = box.lo - Vec3::Constant(1e-9 + 1e-6 * cellSize);
  for (int k = 0; k < 3; ++k)
    m_dims[k] = std::max(1, int(std::ceil((box.hi[k] - m_lo[k]) / cellSize + 1e-9)));
  const auto cellOf = [&](const Vec3& p) {
    Eigen::Vector3i c;
    for (int k = 0; k < 3; ++k)
      c[k] = std::clamp(int(std::floor((p[k] - m_lo[k]) / m_cell)), 0, m_dims[k] - 1);
    return c;
  };
  const size_t nCells = size_t(m_dims[0]) * m_dims[1] * m_dims[2];
  std::vector<std::vector<int>> buckets(nCells);
  for (int f = 0; f < F.rows(); ++f) {
    Vec3 lo = V.row(F(f, 0)).transpose(), hi = lo;
    for (int k = 1; k < 3; ++k) {
      lo = lo.cwiseMin(V.row(F(f, k)).transpose());
      hi = hi.cwiseMax(V.row(F(f, k)).transpose());
    }
    const Eigen::Vector3i a = cellOf(lo), b = cellOf(hi);
    for (int i = a[0]; i <= b[0]; ++i)
      for (int j = a[1]; j <= b[1]; ++j)
        for (int k = a[2]; k <= b[2]; ++k)
          buckets[(size_t(k) * m_dims[1] + j) * m_dims[0] + i].push_back(f);
  }
  m_cellStart.assign(nCells + 1, 0);
  for (size_t c = 0; c < nCells; ++c) m_cellStart[c + 1] = m_cellStart[c] + int(buckets[c].size());
  m_cellTris.reserve(m_cellStart.back());
  for (const auto& b : buckets) m_cellTris.insert(m_cellTris.end(), b.begin(), b.end());

  // Pseudo-normals.
  m_faceNormal = MatX3::Zero(F.rows(), 3);
  m_vertexNormal = MatX3::Zero(V.rows(), 3);
  m_edgeNormal.assign(3 * F.rows(), Vec3::Zero());
  std::map<std::pair<int, int>, Vec3> edgeSum;
  for (int f = 0; f < F.rows(); ++f) {
    const Vec3 x0 = V.row(F(f, 0)), x1 = V.row(F(f, 1)), x2 = V.row(F(f, 2));
    Vec3 n = (x1 - x0).cross(x2 - x0);
    const Real len = n.norm();
    if (len > 0) n /= len;
    m_faceNormal.row(f) = n.transpose();
    const Vec3 xs[3] = {x0, x1, x2};
    for (int k = 0; k < 3; ++k) {
      const Vec3 e1 = (xs[(k + 1) % 3] - xs[k]).normalized();
      const Vec3 e2 = (xs[(k + 2) % 3] - xs[k]).normalized();
      const Real angle = std::acos(std::clamp(e1.dot(e2), Real(-1), Real(1)));
      m_vertexNormal.row(F(f, k)) += angle * n.transpose();
      const int a = F(f, (k + 1) % 3), b = F(f, (k + 2) % 3);
      // try_emplace: operator[] would default-construct the Eigen vector, uninitialised.
      edgeSum.try_emplace({std::min(a, b), std::max(a, b)}, Vec3::Zero()).first->second += n;
    }
  }
  for (int f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = F(f, (k + 1) % 3), b = F(f, (k + 2) % 3);
      m_edgeNormal[3 * f + k] = edgeSum[{std::min(a, b), std::max(a, b)}];
    }
  m_stamp.assign(F.rows(), -1);
}

ClosestPoint TriangleGrid::closest(const Vec3& p) const {
  ClosestPoint best;
  best.distance = std::numeric_limits<Real>::infinity();
  ++m_query;
  Eigen::Vector3i c;
  for (int k = 0; k < 3; ++k)
    c[k] = std::clamp(int(std::floor((p[k] - m_lo[k]) / m_cell)), 0, m_dims[k] - 1);
  const int maxShell = m_dims.maxCoeff();
  for (int s = 0; s <= maxShell; ++s) {
    for (int i = c[0] - s; i <= c[0] + s; ++i) {
      if (i < 0 || i >= m_dims[0]) continue;
      for (int j = c[1] - s; j <= c[1] + s; ++j) {
        if (j < 0 || j >= m_dims[1]) continue;
        for (int k = c[2] - s; k <= c[2] + s; ++k) {
          if (k < 0 || k >= m_dims[2]) continue;
          if (std::max({std::abs(i - c[0]), std::abs(j - c[1]), std::abs(k - c[2])}) != s) continue;
          const size_t cell = (size_t(k) * m_dims[1] + j) * m_dims[0] + i;
          for (int t = m_cellStart[cell]; t < m_cellStart[cell + 1]; ++t) {
            const int f = m_cellTris[t];
            if (m_stamp[f] == m_query) continue;
            m_stamp[f] = m_query;
            const TriangleClosestPoint q = closestPointOnTriangle(
                p, m_V.row(m_F(f, 0)), m_V.row(m_F(f, 1)), m_V.row(m_F(f, 2)));
            const Real d = std::sqrt(q.dist2);
            if (d < best.distance) best = {q.point, q.bary, d, f, q.feature};
          }
        }
      }
    }
    // Every cell outside shell s is at least s cells away from p's (clamped) cell.
    if (best.triangle >= 0 && best.distance <= s * m_cell) break;
  }
  return best;
}

Real TriangleGrid::signedDistance(const Vec3& p, ClosestPoint* cpOut) const {
  const ClosestPoint cp = closest(p);
  if (cpOut) *cpOut = cp;
  if (cp.triangle < 0) return std::numeric_limits<Real>::infinity();
  // m_edgeNormal[3 f + k]: the edge opposite local vertex k.
  Vec3 n = m_faceNormal.row(cp.triangle).transpose();
  switch (cp.feature) {
    case TriangleFeature::Face:
      n = m_faceNormal.row(cp.triangle).transpose();
      break;
    case TriangleFeature::EdgeBC:
      n = m_edgeNormal[3 * cp.triangle + 0];
      break;
    case TriangleFeature::EdgeCA:
      n = m_edgeNormal[3 * cp.triangle + 1];
      break;
    case TriangleFeature::EdgeAB:
      n = m_edgeNormal[3 * cp.triangle + 2];
      break;
    case TriangleFeature::VertexA:
      n = m_vertexNormal.row(m_F(cp.triangle, 0)).transpose();
      break;
    case TriangleFeature::VertexB:
      n = m_vertexNormal.row(m_F(cp.triangle, 1)).transpose();
      break;
    case TriangleFeature::VertexC:
      n = m_vertexNormal.row(m_F(cp.triangle, 2)).transpose();
      break;
  }
  return (p - cp.point).dot(n) < 0 ? -cp.distance : cp.distance;
}

}  // namespace deform::particle_bem
