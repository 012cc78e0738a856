#include "surface_decimation.h"

#include "conforming_surface.h"

#include <Eigen/Cholesky>
#include <algorithm>
#include <cmath>
#include <limits>
#include <queue>

namespace deform::particle_bem {

namespace {

using Mat4 = Eigen::Matrix<Real, 4, 4>;

struct Candidate {
  Real cost;
  int a, b;
  int stampA, stampB;
  bool operator>(const Candidate& o) const {
    if (cost != o.cost) return cost > o.cost;
    if (a != o.a) return a > o.a;
    return b > o.b;
  }
};

Real quality(const Vec3& x0, const Vec3& x1, const Vec3& x2) {
  const Real area = 0.5 * (x1 - x0).cross(x2 - x0).norm();
  const Real l2 = (x1 - x0).squaredNorm() + (x2 - x1).squaredNorm() + (x0 - x2).squaredNorm();
  return l2 > 0 ? 4 * std::sqrt(3.0) * area / l2 : 0;
}

class Decimator {
 public:
  Decimator(const SurfaceMesh& in, Real eps, const std::vector<Box>& regions)
      : m_F(in.F), m_regions(regions) {
    const int nv = in.numVertices(), nf = in.numFaces();
    m_x.resize(nv);
    for (int v = 0; v < nv; ++v) m_x[v] = in.V.row(v).transpose();
    m_Q.assign(nv, Mat4::Zero());
    m_vf.assign(nv, {});
    m_faceAlive.assign(nf, 1);
    m_vertexAlive.assign(nv, 1);
    m_stamp.assign(nv, 0);
    Real areaSum = 0;
    for (int f = 0; f < nf; ++f) {
      const Vec3 n = (m_x[m_F(f, 1)] - m_x[m_F(f, 0)]).cross(m_x[m_F(f, 2)] - m_x[m_F(f, 0)]);
      const Real area2 = n.norm();
      areaSum += 0.5 * area2;
      if (area2 > 0) {
        const Vec3 u = n / area2;
        Vec4 p;
        p << u, -u.dot(m_x[m_F(f, 0)]);
        const Mat4 K = 0.5 * area2 * p * p.transpose();
        for (int k = 0; k < 3; ++k) m_Q[m_F(f, k)] += K;
      }
      for (int k = 0; k < 3; ++k) m_vf[m_F(f, k)].push_back(f);
    }
    m_reg = eps * (nf > 0 ? areaSum / nf : 0);
    m_alive = nv;
    if (!m_regions.empty()) m_inside = facesInBoxes(in.V, in.F, m_regions);
  }

  void run(int target, DecimationStats& st) {
    for (int v = 0; v < int(m_x.size()); ++v)
      for (int n : neighbours(v))
        if (n > v) push(v, n);
    while (m_alive > target && !m_heap.empty()) {
      const Candidate c = m_heap.top();
      m_heap.pop();
      if (!m_vertexAlive[c.a] || !m_vertexAlive[c.b]) continue;
      if (m_stamp[c.a] != c.stampA || m_stamp[c.b] != c.stampB) continue;
      Vec3 v;
      if (!std::isfinite(optimal(c.a, c.b, v))) {
        ++st.refusedGeometry;
        continue;
      }
      const int why = legal(c.a, c.b, v);
      if (why == 1) {
        ++st.refusedTopology;
        continue;
      }
      if (why == 2) {
        ++st.refusedGeometry;
        continue;
      }
      collapse(c.a, c.b, v);
      ++st.collapses;
    }
  }

  SurfaceMesh result() const {
    std::vector<int> remap(m_x.size(), -1);
    SurfaceMesh out;
    int nv = 0;
    for (size_t v = 0; v < m_x.size(); ++v)
      if (m_vertexAlive[v]) remap[v] = nv++;
    out.V.resize(nv, 3);
    for (size_t v = 0; v < m_x.size(); ++v)
      if (m_vertexAlive[v]) out.V.row(remap[v]) = m_x[v].transpose();
    int nf = 0;
    for (size_t f = 0; f < m_faceAlive.size(); ++f) nf += m_faceAlive[f];
    out.F.resize(nf, 3);
    int r = 0;
    for (int f = 0; f < m_F.rows(); ++f)
      if (m_faceAlive[f]) {
        for (int k = 0; k < 3; ++k) out.F(r, k) = remap[m_F(f, k)];
        ++r;
      }
    return out;
  }

 private:
  std::vector<int> neighbours(int v) const {
    std::vector<int> n;
    for (int f : m_vf[v])
      for (int k = 0; k < 3; ++k)
        if (m_F(f, k) != v) n.push_back(m_F(f, k));
    std::sort(n.begin(), n.end());
    n.erase(std::unique(n.begin(), n.end()), n.end());
    return n;
  }

  Real cost(int a, int b, const Vec3& v) const {
    const Mat4 Q = m_Q[a] + m_Q[b];
    const Vec3 mid = 0.5 * (m_x[a] + m_x[b]);
    Vec4 vh;
    vh << v, 1;
    return vh.dot(Q * vh) + m_reg * (v - mid).squaredNorm();
  }

  Real optimal(int a, int b, Vec3& v) const {
    const Mat4 Q = m_Q[a] + m_Q[b];
    const Vec3 mid = 0.5 * (m_x[a] + m_x[b]);
    const Mat3 A = Q.topLeftCorner<3, 3>() + m_reg * Mat3::Identity();
    const Vec3 rhs = -Q.topRightCorner<3, 1>() + m_reg * mid;
    v = A.ldlt().solve(rhs);
    // Far from the edge the quadric is nearly flat: stay near the edge.
    if (!v.allFinite() || (v - mid).norm() > (m_x[a] - m_x[b]).norm()) v = mid;
    if (!m_regions.empty()) return conformingPosition(a, b, v);
    return cost(a, b, v);
  }

  // Faces of vertex w of both tags: w lies on the fixed region's boundary curve.
  bool onInterface(int w) const {
    bool in = false, out = false;
    for (int f : m_vf[w]) (m_inside[f] ? in : out) = true;
    return in && out;
  }

  // Do the faces around a and b, with both moved to v, keep their side of the partition?
  bool conformsAfter(int a, int b, const Vec3& v) const {
    for (int w : {a, b})
      for (int f : m_vf[w]) {
        Vec3 y[3];
        int moved = 0;
        for (int k = 0; k < 3; ++k) {
          const int u = m_F(f, k);
          const bool isEnd = u == a || u == b;
          moved += isEnd;
          y[k] = isEnd ? v : m_x[u];
        }
        if (moved == 2) continue;  // removed by the collapse
        if (!triangleConforms(y[0], y[1], y[2], m_inside[f] != 0, m_regions)) return false;
      }
    return true;
  }

  // With a fixed-region partition, the collapse point must keep every face on its side: the
  // quadric optimum v if it does, else the cheapest of the optimum moved onto a box face plane
  // that a and b share, a, b and the midpoint that does (a vertex on the boundary curve can
  // then only slide along it). No candidate: +inf (legal() refuses it).
  Real conformingPosition(int a, int b, Vec3& v) const {
    std::vector<Vec3> cand = {v};
    for (const Box& box : m_regions)
      for (int axis = 0; axis < 3; ++axis)
        for (const Real value : {box.lo[axis], box.hi[axis]})
          if (m_x[a][axis] == value && m_x[b][axis] == value) {
            Vec3 p = v;
            p[axis] = value;
            cand.push_back(p);
          }
    cand.push_back(m_x[a]);
    cand.push_back(m_x[b]);
    cand.push_back(0.5 * (m_x[a] + m_x[b]));
    Real best = std::numeric_limits<Real>::infinity();
    Vec3 chosen = v;
    for (const Vec3& p : cand) {
      const Real c = cost(a, b, p);
      if (c < best && conformsAfter(a, b, p)) {
        best = c;
        chosen = p;
      }
    }
    v = chosen;
    return best;
  }

  void push(int a, int b) {
    Vec3 v;
    const Real cost = optimal(a, b, v) + m_reg * (m_x[a] - m_x[b]).squaredNorm();
    if (!std::isfinite(cost)) return;  // no conforming position now; retried when a or b moves
    m_heap.push(
        {cost, std::min(a, b), std::max(a, b), m_stamp[std::min(a, b)], m_stamp[std::max(a, b)]});
  }

  // 0 legal, 1 topology, 2 geometry.
  int legal(int a, int b, const Vec3& v) const {
    const std::vector<int> na = neighbours(a), nb = neighbours(b);
    std::vector<int> common;
    std::set_intersection(na.begin(), na.end(), nb.begin(), nb.end(), std::back_inserter(common));
    if (common.size() != 2) return 1;
    if (!m_regions.empty()) {
      // Two vertices of the boundary curve joined by an edge that is not part of it: the
      // collapse would pinch the fixed region.
      if (onInterface(a) && onInterface(b)) {
        const int f0 = sharedFace(a, b, -1), f1 = sharedFace(a, b, f0);
        if (f0 < 0 || f1 < 0 || m_inside[f0] == m_inside[f1]) return 1;
      }
      if (!std::isfinite(cost(a, b, v)) || !conformsAfter(a, b, v)) return 2;
    }
    int shared = 0;
    for (int f : m_vf[a])
      for (int k = 0; k < 3; ++k) shared += m_F(f, k) == b;
    if (shared != 2) return 1;
    for (int c : common)
      if (neighbours(c).size() <= 3) return 1;
    if (m_alive <= 4) return 1;
    for (int w : {a, b}) {
      for (int f : m_vf[w]) {
        bool hasBoth = false;
        for (int k = 0; k < 3; ++k) hasBoth = hasBoth || m_F(f, k) == (w == a ? b : a);
        if (hasBoth) continue;
        Vec3 x[3], y[3];
        for (int k = 0; k < 3; ++k) {
          x[k] = m_x[m_F(f, k)];
          y[k] = m_F(f, k) == w ? v : x[k];
        }
        const Vec3 n0 = (x[1] - x[0]).cross(x[2] - x[0]);
        const Vec3 n1 = (y[1] - y[0]).cross(y[2] - y[0]);
        if (n1.dot(n0) <= 0.17 * n0.norm() * n1.norm()) return 2;
        const Real q1 = quality(y[0], y[1], y[2]);
        if (q1 < 0.1 && q1 < quality(x[0], x[1], x[2])) return 2;
      }
    }
    return 0;
  }

  int sharedFace(int a, int b, int skip) const {
    for (int f : m_vf[a]) {
      if (f == skip) continue;
      for (int k = 0; k < 3; ++k)
        if (m_F(f, k) == b) return f;
    }
    return -1;
  }

  void collapse(int a, int b, const Vec3& v) {
    m_x[a] = v;
    m_Q[a] += m_Q[b];
    std::vector<int> faces;
    for (int f : m_vf[a]) {
      bool hasB = false;
      for (int k = 0; k < 3; ++k) hasB = hasB || m_F(f, k) == b;
      if (hasB) {
        m_faceAlive[f] = 0;
        for (int k = 0; k < 3; ++k) {
          const int u = m_F(f, k);
          if (u != a && u != b) {
            auto& l = m_vf[u];
            l.erase(std::remove(l.begin(), l.end(), f), l.end());
          }
        }
      } else {
        faces.push_back(f);
      }
    }
    for (int f : m_vf[b]) {
      if (!m_faceAlive[f]) continue;
      for (int k = 0; k < 3; ++k)
        if (m_F(f, k) == b) m_F(f, k) = a;
      faces.push_back(f);
    }
    std::sort(faces.begin(), faces.end());
    m_vf[a] = faces;
    m_vf[b].clear();
    m_vertexAlive[b] = 0;
    --m_alive;
    ++m_stamp[a];
    for (int n : neighbours(a)) push(a, n);
  }

  MatX3i m_F;
  std::vector<Box> m_regions;
  std::vector<char> m_inside;  ///< per face: in the fixed region (only with m_regions)
  std::vector<Vec3> m_x;
  std::vector<Mat4> m_Q;
  std::vector<std::vector<int>> m_vf;
  std::vector<char> m_faceAlive, m_vertexAlive;
  std::vector<int> m_stamp;
  std::priority_queue<Candidate, std::vector<Candidate>, std::greater<Candidate>> m_heap;
  Real m_reg = 0;
  int m_alive = 0;
};

}  // namespace

SurfaceMesh decimateQuadric(const SurfaceMesh& in, int targetVertices, DecimationStats* stats,
                            Real regulariser) {
  return decimateQuadric(in, targetVertices, {}, stats, regulariser);
}

SurfaceMesh decimateQuadric(const SurfaceMesh& in, int targetVertices,
                            const std::vector<Box>& fixedRegions, DecimationStats* stats,
                            Real regulariser) {
  DecimationStats st;
  if (in.numVertices() <= targetVertices) {
    if (stats) *stats = st;
    return in;
  }
  Decimator d(in, regulariser, fixedRegions);
  d.run(std::max(4, targetVertices), st);
  if (stats) *stats = st;
  return d.result();
}

}  // namespace deform::particle_bem
