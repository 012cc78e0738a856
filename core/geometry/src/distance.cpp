#include <deform/geometry/distance.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <unordered_map>

namespace deform {

TriangleClosestPoint closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b,
                                            const Vec3& c) {
  TriangleClosestPoint r;
  auto finish = [&](const Vec3& q, TriangleFeature f, const Vec3& bary) {
    r.point = q;
    r.dist2 = (p - q).squaredNorm();
    r.feature = f;
    r.bary = bary;
    return r;
  };
  const Vec3 ab = b - a, ac = c - a, ap = p - a;
  const Real d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return finish(a, TriangleFeature::VertexA, Vec3(1, 0, 0));
  const Vec3 bp = p - b;
  const Real d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return finish(b, TriangleFeature::VertexB, Vec3(0, 1, 0));
  const Real vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const Real v = d1 / (d1 - d3);
    return finish(a + v * ab, TriangleFeature::EdgeAB, Vec3(1 - v, v, 0));
  }
  const Vec3 cp = p - c;
  const Real d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return finish(c, TriangleFeature::VertexC, Vec3(0, 0, 1));
  const Real vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const Real w = d2 / (d2 - d6);
    return finish(a + w * ac, TriangleFeature::EdgeCA, Vec3(1 - w, 0, w));
  }
  const Real va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const Real w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
    return finish(b + w * (c - b), TriangleFeature::EdgeBC, Vec3(0, 1 - w, w));
  }
  const Real denom = va + vb + vc;
  if (!(std::abs(denom) > 0)) {
    // Degenerate (zero-area) triangle: fall back to the nearest of its three edges.
    auto param = [&](const Vec3& s0, const Vec3& s1) {
      const Vec3 d = s1 - s0;
      const Real l2 = d.squaredNorm();
      return l2 > 0 ? std::clamp((p - s0).dot(d) / l2, Real(0), Real(1)) : Real(0);
    };
    const Real t0 = param(a, b), t1 = param(b, c), t2 = param(c, a);
    const Vec3 q0 = a + t0 * (b - a), q1 = b + t1 * (c - b), q2 = c + t2 * (a - c);
    const Real e0 = (p - q0).squaredNorm(), e1 = (p - q1).squaredNorm(),
               e2 = (p - q2).squaredNorm();
    if (e0 <= e1 && e0 <= e2) return finish(q0, TriangleFeature::EdgeAB, Vec3(1 - t0, t0, 0));
    if (e1 <= e2) return finish(q1, TriangleFeature::EdgeBC, Vec3(0, 1 - t1, t1));
    return finish(q2, TriangleFeature::EdgeCA, Vec3(t2, 0, 1 - t2));
  }
  const Real v = vb / denom, w = vc / denom;
  return finish(a + ab * v + ac * w, TriangleFeature::Face, Vec3(1 - v - w, v, w));
}

MeshDistance::MeshDistance(const SurfaceMesh& mesh) : m_mesh(mesh) {
  const int nf = mesh.numFaces(), nv = mesh.numVertices();
  m_faceNormal.setZero(nf, 3);
  m_vertexNormal.setZero(nv, 3);
  m_edgeNormal.setZero(Eigen::Index(nf) * 3, 3);
  MatX3 centroids(nf, 3);
  std::unordered_map<unsigned long long, Vec3> edgeSum;
  auto key = [](int i, int j) {
    if (i > j) std::swap(i, j);
    return (static_cast<unsigned long long>(unsigned(i)) << 32) | unsigned(j);
  };
  for (int f = 0; f < nf; ++f) {
    const Vec3 x[3] = {mesh.V.row(mesh.F(f, 0)), mesh.V.row(mesh.F(f, 1)),
                       mesh.V.row(mesh.F(f, 2))};
    centroids.row(f) = (x[0] + x[1] + x[2]) / 3.0;
    Vec3 n = (x[1] - x[0]).cross(x[2] - x[0]);
    const Real len = n.norm();
    n = len > 0 ? Vec3(n / len) : Vec3::Zero();
    m_faceNormal.row(f) = n;
    for (int k = 0; k < 3; ++k) {
      const Vec3 e1 = x[(k + 1) % 3] - x[k], e2 = x[(k + 2) % 3] - x[k];
      const Real l1 = e1.norm(), l2 = e2.norm();
      if (l1 > 0 && l2 > 0) {
        const Real angle = std::acos(std::clamp(e1.dot(e2) / (l1 * l2), Real(-1), Real(1)));
        m_vertexNormal.row(mesh.F(f, k)) += angle * n;
      }
      // Eigen vectors are not zero-initialised by operator[]: insert an explicit zero.
      edgeSum.try_emplace(key(mesh.F(f, k), mesh.F(f, (k + 1) % 3)), Vec3::Zero()).first->second +=
          n;
    }
  }
  for (int f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k)
      m_edgeNormal.row(3 * f + k) = edgeSum[key(mesh.F(f, k), mesh.F(f, (k + 1) % 3))];
  m_order.resize(size_t(nf));
  std::iota(m_order.begin(), m_order.end(), 0);
  m_nodes.reserve(size_t(2 * std::max(nf, 1)));
  if (nf > 0) build(0, nf, centroids);
}

int MeshDistance::build(int begin, int end, const MatX3& centroids) {
  const int id = int(m_nodes.size());
  m_nodes.emplace_back();
  Vec3 lo = Vec3::Constant(std::numeric_limits<Real>::infinity()), hi = -lo;
  Vec3 clo = lo, chi = hi;
  for (int i = begin; i < end; ++i) {
    const int f = m_order[size_t(i)];
    for (int k = 0; k < 3; ++k) {
      const Vec3 x = m_mesh.V.row(m_mesh.F(f, k));
      lo = lo.cwiseMin(x);
      hi = hi.cwiseMax(x);
    }
    clo = clo.cwiseMin(centroids.row(f).transpose());
    chi = chi.cwiseMax(centroids.row(f).transpose());
  }
  m_nodes[size_t(id)].lo = lo;
  m_nodes[size_t(id)].hi = hi;
  if (end - begin <= 4) {
    m_nodes[size_t(id)].begin = begin;
    m_nodes[size_t(id)].end = end;
    return id;
  }
  int axis = 0;
  (chi - clo).maxCoeff(&axis);
  const int mid = (begin + end) / 2;
  std::nth_element(m_order.begin() + begin, m_order.begin() + mid, m_order.begin() + end,
                   [&](int a, int b) {
                     const Real ca = centroids(a, axis), cb = centroids(b, axis);
                     return ca < cb || (ca == cb && a < b);
                   });
  const int l = build(begin, mid, centroids);
  const int r = build(mid, end, centroids);
  m_nodes[size_t(id)].left = l;
  m_nodes[size_t(id)].right = r;
  return id;
}

Real MeshDistance::boxDist2(const Node& n, const Vec3& p) {
  const Vec3 d = (n.lo - p).cwiseMax(p - n.hi).cwiseMax(Vec3::Zero());
  return d.squaredNorm();
}

MeshDistance::Result MeshDistance::closest(const Vec3& p) const {
  Result best;
  Real bestD2 = std::numeric_limits<Real>::infinity();
  if (m_nodes.empty()) {
    best.distance = bestD2;
    return best;
  }
  int stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& n = m_nodes[size_t(stack[--top])];
    if (boxDist2(n, p) >= bestD2) continue;
    if (n.left < 0) {
      for (int i = n.begin; i < n.end; ++i) {
        const int f = m_order[size_t(i)];
        const TriangleClosestPoint c =
            closestPointOnTriangle(p, m_mesh.V.row(m_mesh.F(f, 0)), m_mesh.V.row(m_mesh.F(f, 1)),
                                   m_mesh.V.row(m_mesh.F(f, 2)));
        if (c.dist2 < bestD2 || (c.dist2 == bestD2 && f < best.triangle)) {
          bestD2 = c.dist2;
          best.point = c.point;
          best.triangle = f;
          best.feature = c.feature;
        }
      }
      continue;
    }
    // Visit the nearer child first (pushed last).
    const Real dl = boxDist2(m_nodes[size_t(n.left)], p);
    const Real dr = boxDist2(m_nodes[size_t(n.right)], p);
    if (dl <= dr) {
      stack[top++] = n.right;
      stack[top++] = n.left;
    } else {
      stack[top++] = n.left;
      stack[top++] = n.right;
    }
  }
  best.distance = std::sqrt(bestD2);
  return best;
}

Real MeshDistance::signedDistance(const Vec3& p) const {
  const Result r = closest(p);
  if (r.triangle < 0) return r.distance;
  const int f = r.triangle;
  Vec3 n;
  switch (r.feature) {
    case TriangleFeature::VertexA:
      n = m_vertexNormal.row(m_mesh.F(f, 0));
      break;
    case TriangleFeature::VertexB:
      n = m_vertexNormal.row(m_mesh.F(f, 1));
      break;
    case TriangleFeature::VertexC:
      n = m_vertexNormal.row(m_mesh.F(f, 2));
      break;
    case TriangleFeature::EdgeAB:
      n = m_edgeNormal.row(3 * f + 0);
      break;
    case TriangleFeature::EdgeBC:
      n = m_edgeNormal.row(3 * f + 1);
      break;
    case TriangleFeature::EdgeCA:
      n = m_edgeNormal.row(3 * f + 2);
      break;
    default:
      n = m_faceNormal.row(f);
      break;
  }
  return (p - r.point).dot(n) < 0 ? -r.distance : r.distance;
}

}  // namespace deform
