#include "vertex_cover_simplification.h"

#include <deform/geometry/mesh_check.h>
#include <deform/sdk/error.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <queue>

namespace deform::hybrid_fem_pbd {

std::vector<char> vertexCoverFromIndependentSet(const MatX2i& E, int n) {
  std::vector<std::vector<int>> adj(n);
  for (Eigen::Index e = 0; e < E.rows(); ++e) {
    adj[E(e, 0)].push_back(E(e, 1));
    adj[E(e, 1)].push_back(E(e, 0));
  }
  // Min-degree greedy on the residual graph: take the vertex of smallest remaining degree into
  // I, delete it and its neighbours, update degrees. Lazy priority queue keyed (degree, index).
  std::vector<int> degree(n);
  for (int v = 0; v < n; ++v) degree[v] = static_cast<int>(adj[v].size());
  std::vector<char> removed(n, 0), independent(n, 0);
  using Key = std::pair<int, int>;
  std::priority_queue<Key, std::vector<Key>, std::greater<Key>> queue;
  for (int v = 0; v < n; ++v) queue.push({degree[v], v});
  while (!queue.empty()) {
    const auto [d, v] = queue.top();
    queue.pop();
    if (removed[v] || d != degree[v]) continue;
    independent[v] = 1;
    removed[v] = 1;
    for (int u : adj[v]) {
      if (removed[u]) continue;
      removed[u] = 1;
      for (int w : adj[u]) {
        if (removed[w]) continue;
        --degree[w];
        queue.push({degree[w], w});
      }
    }
  }
  std::vector<char> cover(n);
  for (int v = 0; v < n; ++v) cover[v] = independent[v] ? 0 : 1;
  return cover;
}

bool isVertexCover(const MatX2i& E, const std::vector<char>& cover) {
  for (Eigen::Index e = 0; e < E.rows(); ++e)
    if (!cover[E(e, 0)] && !cover[E(e, 1)]) return false;
  return true;
}

Real triangleQuality(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Real area2 = (b - a).cross(c - a).norm();  // twice the area
  const Real s = (b - a).squaredNorm() + (c - b).squaredNorm() + (a - c).squaredNorm();
  if (!(s > 0)) return 0;
  return 2.0 * std::sqrt(3.0) * area2 / s;
}

namespace {

// A triangle surface under edge collapses: faces with alive flags and vertex -> face lists.
struct CollapsibleSurface {
  const MatX3& V;
  std::vector<Vec3i> F;
  std::vector<char> alive;
  std::vector<std::vector<int>> vf;
  int aliveVertices = 0;

  CollapsibleSurface(const MatX3& V_, const MatX3i& F_) : V(V_) {
    F.resize(F_.rows());
    alive.assign(F_.rows(), 1);
    vf.assign(V.rows(), {});
    for (Eigen::Index f = 0; f < F_.rows(); ++f) {
      F[f] = F_.row(f).transpose();
      for (int k = 0; k < 3; ++k) vf[F[f][k]].push_back(static_cast<int>(f));
    }
    for (const auto& l : vf) aliveVertices += l.empty() ? 0 : 1;
  }

  std::vector<int> neighbours(int v) const {
    std::vector<int> out;
    for (int f : vf[v])
      for (int k = 0; k < 3; ++k)
        if (F[f][k] != v) out.push_back(F[f][k]);
    std::sort(out.begin(), out.end());
    out.erase(std::unique(out.begin(), out.end()), out.end());
    return out;
  }

  static bool has(const Vec3i& f, int v) { return f[0] == v || f[1] == v || f[2] == v; }

  // Worst quality of the faces of i after collapsing i onto j, or -1 when the collapse is
  // invalid (link condition, normal flip, fewer than 5 vertices left).
  Real collapseQuality(int i, int j, Real minNormalDot) const {
    if (aliveVertices <= 4) return -1;
    const std::vector<int> ni = neighbours(i), nj = neighbours(j);
    std::vector<int> common;
    std::set_intersection(ni.begin(), ni.end(), nj.begin(), nj.end(), std::back_inserter(common));
    std::vector<int> opposite;
    for (int f : vf[i])
      if (has(F[f], j))
        for (int k = 0; k < 3; ++k)
          if (F[f][k] != i && F[f][k] != j) opposite.push_back(F[f][k]);
    std::sort(opposite.begin(), opposite.end());
    if (opposite.size() != 2 || common != opposite) return -1;
    Real worst = std::numeric_limits<Real>::infinity();
    for (int f : vf[i]) {
      if (has(F[f], j)) continue;
      Vec3 p[3], q[3];
      for (int k = 0; k < 3; ++k) {
        p[k] = V.row(F[f][k]).transpose();
        q[k] = V.row(F[f][k] == i ? j : F[f][k]).transpose();
      }
      const Vec3 n0 = (p[1] - p[0]).cross(p[2] - p[0]);
      const Vec3 n1 = (q[1] - q[0]).cross(q[2] - q[0]);
      const Real l0 = n0.norm(), l1 = n1.norm();
      if (!(l1 > 0) || !(l0 > 0) || n0.dot(n1) < minNormalDot * l0 * l1) return -1;
      worst = std::min(worst, triangleQuality(q[0], q[1], q[2]));
    }
    return worst;
  }

  void collapse(int i, int j) {
    for (int f : vf[i]) {
      if (has(F[f], j)) {
        alive[f] = 0;
        for (int k = 0; k < 3; ++k) {
          const int v = F[f][k];
          if (v == i) continue;
          auto& l = vf[v];
          l.erase(std::remove(l.begin(), l.end(), f), l.end());
        }
      } else {
        for (int k = 0; k < 3; ++k)
          if (F[f][k] == i) F[f][k] = j;
        vf[j].push_back(f);
      }
    }
    vf[i].clear();
    --aliveVertices;
  }
};

struct PassResult {
  SurfaceMesh coarse;
  std::vector<int> kept;  // coarse vertex -> input vertex
  std::vector<char> cover;
  long long collapsed = 0, rejected = 0;
};

PassResult simplifyOnce(const SurfaceMesh& in, const SimplificationOptions& opt) {
  PassResult r;
  const int n = in.numVertices();
  const MatX2i E = uniqueEdges(in.F);
  r.cover = vertexCoverFromIndependentSet(E, n);
  CollapsibleSurface s(in.V, in.F);
  for (int i = 0; i < n; ++i) {
    if (r.cover[i]) continue;
    const std::vector<int> nb = s.neighbours(i);
    Real davg = 0;
    for (int k : nb) davg += (in.V.row(k) - in.V.row(i)).norm();
    davg /= std::max<size_t>(nb.size(), 1);
    int best = -1;
    Real bestQ = -1, bestDev = std::numeric_limits<Real>::infinity();
    for (int j : nb) {
      const Real q = s.collapseQuality(i, j, opt.minNormalDot);
      if (q < opt.minQuality) continue;
      const Real dev = std::abs((in.V.row(j) - in.V.row(i)).norm() - davg);
      // Quality first; the paper's d_avg criterion breaks near-ties (within 1e-9).
      if (best < 0 || q > bestQ + 1e-9 || (q > bestQ - 1e-9 && dev < bestDev)) {
        best = j;
        bestQ = q;
        bestDev = dev;
      }
    }
    if (best < 0) {
      ++r.rejected;
      continue;
    }
    s.collapse(i, best);
    ++r.collapsed;
  }
  std::vector<int> index(n, -1);
  for (int v = 0; v < n; ++v) {
    if (s.vf[v].empty()) continue;
    index[v] = static_cast<int>(r.kept.size());
    r.kept.push_back(v);
  }
  r.coarse.V.resize(static_cast<Eigen::Index>(r.kept.size()), 3);
  for (size_t c = 0; c < r.kept.size(); ++c) r.coarse.V.row(c) = in.V.row(r.kept[c]);
  int nf = 0;
  for (size_t f = 0; f < s.F.size(); ++f) nf += s.alive[f];
  r.coarse.F.resize(nf, 3);
  int row = 0;
  for (size_t f = 0; f < s.F.size(); ++f) {
    if (!s.alive[f]) continue;
    for (int k = 0; k < 3; ++k) r.coarse.F(row, k) = index[s.F[f][k]];
    ++row;
  }
  return r;
}

}  // namespace

SimplificationResult simplifyByVertexCover(const SurfaceMesh& fine,
                                           const SimplificationOptions& options) {
  SimplificationResult out;
  out.coarseToFine.resize(fine.numVertices());
  std::iota(out.coarseToFine.begin(), out.coarseToFine.end(), 0);
  SurfaceMesh current = fine;
  for (int level = 0; level < std::max(options.levels, 1); ++level) {
    PassResult p = simplifyOnce(current, options);
    if (level == 0) out.firstCover = p.cover;
    std::vector<int> composed(p.kept.size());
    for (size_t c = 0; c < p.kept.size(); ++c) composed[c] = out.coarseToFine[p.kept[c]];
    out.coarseToFine.swap(composed);
    out.collapsed += p.collapsed;
    out.rejected += p.rejected;
    current = std::move(p.coarse);
    if (p.collapsed == 0) break;
  }
  const MeshReport report = validateSurface(current);
  if (!report.ok()) {
    throw InputError("", "hybrid simplification",
                     "the vertex-cover simplification produced an invalid coarse surface: " +
                         report.issues.front().message);
  }
  out.coarse = std::move(current);
  return out;
}

}  // namespace deform::hybrid_fem_pbd
