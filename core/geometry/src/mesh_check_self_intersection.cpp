#include <deform/geometry/mesh_check.h>
#include <deform/sdk/error.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <limits>

namespace deform {
namespace {

/// Relative tolerance: a distance below this times the pair's longest edge counts as zero.
constexpr Real kRelTol = 1e-9;
/// A flat fold across a shared edge: the opposite corner's distance to the other plane is below
/// this times its distance to the edge's line (a dihedral angle under ~1e-7 rad).
constexpr Real kFoldTol = 1e-7;
/// Grid cell size over the mean triangle box size (measured: see self_intersection_bench).
constexpr Real kCellScale = 2.0;

struct Tri {
  std::array<int, 3> v;
  std::array<Vec3, 3> p;
  Vec3 unitNormal;
  Real maxEdge = 0;
  Vec3 lo, hi;
};

int signOf(Real d, Real tol) {
  return d > tol ? 1 : (d < -tol ? -1 : 0);
}

Real planeDistance(const Tri& t, const Vec3& x) {
  return t.unitNormal.dot(x - t.p[0]);
}

/// Projection onto the coordinate plane that drops the largest component of n (keeps areas
/// non-degenerate for triangles with normal n); the result is right-handed w.r.t. n.
struct Projector {
  int a = 0, b = 1;
  explicit Projector(const Vec3& n) {
    int k = 0;
    n.cwiseAbs().maxCoeff(&k);
    a = (k + 1) % 3;
    b = (k + 2) % 3;
  }
  Eigen::Vector2d operator()(const Vec3& x) const { return {x[a], x[b]}; }
};

Real cross2(const Eigen::Vector2d& u, const Eigen::Vector2d& v) {
  return u.x() * v.y() - u.y() * v.x();
}

/// Signed distance of c from the line through a, b (positive on the left), 2-D.
Real lineSide(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  const Real len = (b - a).norm();
  return len > 0 ? cross2(b - a, c - a) / len : 0;
}

/// c strictly inside the 2-D triangle t (orientation s = +-1), by more than tol.
bool strictlyInside2(const std::array<Eigen::Vector2d, 3>& t, Real s, const Eigen::Vector2d& c,
                     Real tol) {
  for (int k = 0; k < 3; ++k) {
    if (!(s * lineSide(t[size_t(k)], t[size_t((k + 1) % 3)], c) > tol)) return false;
  }
  return true;
}

/// Segments pq and rs cross at a single interior point of both, 2-D.
bool properCross2(const Eigen::Vector2d& p, const Eigen::Vector2d& q, const Eigen::Vector2d& r,
                  const Eigen::Vector2d& s, Real tol) {
  const int a = signOf(lineSide(p, q, r), tol), b = signOf(lineSide(p, q, s), tol);
  const int c = signOf(lineSide(r, s, p), tol), d = signOf(lineSide(r, s, q), tol);
  return a * b < 0 && c * d < 0;
}

/// Coplanar triangles without a shared index: positive-area overlap.
bool coplanarOverlap(const Tri& A, const Tri& B, Real tol) {
  const Projector proj(A.unitNormal);
  std::array<Eigen::Vector2d, 3> a, b;
  for (size_t k = 0; k < 3; ++k) a[k] = proj(A.p[k]), b[k] = proj(B.p[k]);
  const Real sa = cross2(a[1] - a[0], a[2] - a[0]) > 0 ? 1 : -1;
  const Real sb = cross2(b[1] - b[0], b[2] - b[0]) > 0 ? 1 : -1;
  for (size_t i = 0; i < 3; ++i)
    for (size_t j = 0; j < 3; ++j)
      if (properCross2(a[i], a[(i + 1) % 3], b[j], b[(j + 1) % 3], tol)) return true;
  for (size_t k = 0; k < 3; ++k) {
    if (strictlyInside2(b, sb, a[k], tol) || strictlyInside2(a, sa, b[k], tol)) return true;
  }
  // Same triangle on different indices (no crossing, no corner strictly inside).
  const Eigen::Vector2d ca = (a[0] + a[1] + a[2]) / 3, cb = (b[0] + b[1] + b[2]) / 3;
  return strictlyInside2(b, sb, ca, tol) || strictlyInside2(a, sa, cb, tol);
}

/// Interval that triangle T (corner distances d, signs s to the other plane) cuts on the common
/// line with direction D. T has corners strictly on both sides.
std::array<Real, 2> lineInterval(const Tri& T, const std::array<Real, 3>& d,
                                 const std::array<int, 3>& s, const Vec3& D) {
  Real lo = std::numeric_limits<Real>::infinity(), hi = -lo;
  auto add = [&](const Vec3& x) {
    const Real t = D.dot(x);
    lo = std::min(lo, t);
    hi = std::max(hi, t);
  };
  for (size_t i = 0; i < 3; ++i) {
    const size_t j = (i + 1) % 3;
    if (s[i] == 0) add(T.p[i]);
    if (s[i] * s[j] < 0) add(T.p[i] + (T.p[j] - T.p[i]) * (d[i] / (d[i] - d[j])));
  }
  return {lo, hi};
}

bool crossesNoShared(const Tri& A, const Tri& B, Real tol) {
  std::array<Real, 3> dA, dB;
  std::array<int, 3> sA, sB;
  for (size_t k = 0; k < 3; ++k) {
    dB[k] = planeDistance(A, B.p[k]);
    sB[k] = signOf(dB[k], tol);
    dA[k] = planeDistance(B, A.p[k]);
    sA[k] = signOf(dA[k], tol);
  }
  auto allZero = [](const std::array<int, 3>& s) { return s[0] == 0 && s[1] == 0 && s[2] == 0; };
  if (allZero(sA) || allZero(sB)) return coplanarOverlap(A, B, tol);
  auto straddles = [](const std::array<int, 3>& s) {
    const bool pos = s[0] > 0 || s[1] > 0 || s[2] > 0;
    const bool neg = s[0] < 0 || s[1] < 0 || s[2] < 0;
    return pos && neg;
  };
  // An interior strictly on one side of the other plane cannot meet the other's interior.
  if (!straddles(sA) || !straddles(sB)) return false;
  Vec3 D = A.unitNormal.cross(B.unitNormal);
  const Real len = D.norm();
  if (!(len > kRelTol)) return coplanarOverlap(A, B, tol);  // near-parallel planes
  D /= len;
  const auto ia = lineInterval(A, dA, sA, D), ib = lineInterval(B, dB, sB, D);
  return std::min(ia[1], ib[1]) - std::max(ia[0], ib[0]) > tol;
}

/// Segment xy pierces the interior of T (x and y strictly on opposite sides of its plane, the
/// crossing point strictly inside).
bool segmentPierces(const Vec3& x, const Vec3& y, const Tri& T, Real tol) {
  const Real dx = planeDistance(T, x), dy = planeDistance(T, y);
  if (signOf(dx, tol) * signOf(dy, tol) >= 0) return false;
  const Vec3 p = x + (y - x) * (dx / (dx - dy));
  for (size_t k = 0; k < 3; ++k) {
    const Vec3 e = T.p[(k + 1) % 3] - T.p[k];
    const Real el = e.norm();
    if (!(e.cross(p - T.p[k]).dot(T.unitNormal) > tol * el)) return false;
  }
  return true;
}

/// A = (v, a1, a2), B = (v, b1, b2) share exactly the corner v (ia, ib: its slot in A and B).
bool crossesSharedVertex(const Tri& A, size_t ia, const Tri& B, size_t ib, Real tol) {
  const Vec3& v = A.p[ia];
  const Vec3 &a1 = A.p[(ia + 1) % 3], &a2 = A.p[(ia + 2) % 3];
  const Vec3 &b1 = B.p[(ib + 1) % 3], &b2 = B.p[(ib + 2) % 3];
  const bool coplanar =
      signOf(planeDistance(A, b1), tol) == 0 && signOf(planeDistance(A, b2), tol) == 0 &&
      signOf(planeDistance(B, a1), tol) == 0 && signOf(planeDistance(B, a2), tol) == 0;
  if (!coplanar) return segmentPierces(a1, a2, B, tol) || segmentPierces(b1, b2, A, tol);
  // Coplanar: near v each triangle fills its angular sector, so the interiors overlap iff the
  // sectors do (with a positive angle).
  const Projector proj(A.unitNormal);
  const Eigen::Vector2d o = proj(v);
  auto dir = [&](const Vec3& x) {
    const Eigen::Vector2d d = proj(x) - o;
    const Real n = d.norm();
    return n > 0 ? Eigen::Vector2d(d / n) : d;
  };
  const Eigen::Vector2d da1 = dir(a1), da2 = dir(a2), db1 = dir(b1), db2 = dir(b2);
  constexpr Real kSin = 1e-9;
  auto inside = [&](const Eigen::Vector2d& e1, const Eigen::Vector2d& e2,
                    const Eigen::Vector2d& d) {
    const Real s = cross2(e1, e2) > 0 ? 1 : -1;
    return s * cross2(e1, d) > kSin && s * cross2(d, e2) > kSin;
  };
  return inside(da1, da2, db1) || inside(da1, da2, db2) ||
         inside(da1, da2, (db1 + db2).normalized()) || inside(db1, db2, da1) ||
         inside(db1, db2, da2) || inside(db1, db2, (da1 + da2).normalized());
}

/// A and B share the edge u-w; a is A's opposite corner, b is B's. Only a flat fold overlaps.
bool crossesSharedEdge(const Tri& A, const Vec3& a, const Vec3& b, const Vec3& u, const Vec3& w) {
  const Vec3 e = w - u;
  const Real el = e.norm();
  if (!(el > 0)) return false;
  const Real lineDist = e.cross(b - u).norm() / el;
  if (!(std::abs(planeDistance(A, b)) <= kFoldTol * lineDist)) return false;
  const Vec3 n = A.unitNormal;
  const Real sa = e.cross(a - u).dot(n), sb = e.cross(b - u).dot(n);
  return sa * sb > 0;
}

bool crosses(const Tri& A, const Tri& B) {
  const Real tol = kRelTol * std::max(A.maxEdge, B.maxEdge);
  int shared = 0;
  std::array<size_t, 3> slotA{}, slotB{};
  for (size_t i = 0; i < 3; ++i)
    for (size_t j = 0; j < 3; ++j)
      if (A.v[i] == B.v[j]) {
        slotA[size_t(shared)] = i;
        slotB[size_t(shared)] = j;
        ++shared;
      }
  if (shared == 0) return crossesNoShared(A, B, tol);
  if (shared == 1) return crossesSharedVertex(A, slotA[0], B, slotB[0], tol);
  if (shared == 2) {
    const size_t oa = 3 - slotA[0] - slotA[1], ob = 3 - slotB[0] - slotB[1];
    return crossesSharedEdge(A, A.p[oa], B.p[ob], A.p[slotA[0]], A.p[slotA[1]]);
  }
  return false;  // the same three vertices: a duplicate triangle (validateSurface reports it)
}

}  // namespace

std::string SelfIntersectionReport::message() const {
  if (ok()) return "";
  std::string s = std::to_string(pairs) + (pairs == 1 ? " pair of self-intersecting triangles"
                                                      : " pairs of self-intersecting triangles");
  if (!listed.empty()) {
    s += " (" + std::string(pairs == 1 ? "" : "first: ") + std::to_string(listed[0][0]) + " and " +
         std::to_string(listed[0][1]) + ")";
  }
  return s;
}

SelfIntersectionReport findSelfIntersections(const SurfaceMesh& mesh, int maxListed) {
  SelfIntersectionReport report;
  const int nv = mesh.numVertices();
  std::vector<Tri> tris;
  std::vector<int> faceOf;
  tris.reserve(size_t(mesh.numFaces()));
  Vec3 lo = Vec3::Constant(std::numeric_limits<Real>::infinity()), hi = -lo;
  for (int f = 0; f < mesh.numFaces(); ++f) {
    Tri t;
    bool valid = true;
    for (int k = 0; k < 3; ++k) {
      const int i = mesh.F(f, k);
      if (i < 0 || i >= nv || !mesh.V.row(i).allFinite()) {
        valid = false;
        break;
      }
      t.v[size_t(k)] = i;
      t.p[size_t(k)] = mesh.V.row(i).transpose();
    }
    if (!valid || t.v[0] == t.v[1] || t.v[1] == t.v[2] || t.v[0] == t.v[2]) continue;
    const Vec3 n = (t.p[1] - t.p[0]).cross(t.p[2] - t.p[0]);
    const Real area2 = n.norm();
    t.maxEdge =
        std::max({(t.p[1] - t.p[0]).norm(), (t.p[2] - t.p[1]).norm(), (t.p[0] - t.p[2]).norm()});
    // Zero area (relative to the longest edge) or an overflowing cross product: skipped.
    if (!(area2 > 1e-14 * t.maxEdge * t.maxEdge) || !std::isfinite(area2)) continue;
    t.unitNormal = n / area2;
    t.lo = t.p[0].cwiseMin(t.p[1]).cwiseMin(t.p[2]);
    t.hi = t.p[0].cwiseMax(t.p[1]).cwiseMax(t.p[2]);
    lo = lo.cwiseMin(t.lo);
    hi = hi.cwiseMax(t.hi);
    tris.push_back(t);
    faceOf.push_back(f);
  }
  const size_t n = tris.size();
  if (n < 2) return report;

  // Uniform grid: cell size from the mean box size, grown until the entries stay linear in n.
  Real mean = 0;
  for (const Tri& t : tris) mean += (t.hi - t.lo).maxCoeff();
  mean /= Real(n);
  const Vec3 extent = hi - lo;
  Real h = std::max(kCellScale * mean, extent.maxCoeff() / Real(1 << 20));
  if (!(h > 0) || !std::isfinite(h)) h = std::numeric_limits<Real>::infinity();
  auto cellRange = [&](const Vec3& a, const Vec3& b, std::array<std::int64_t, 3>& c0,
                       std::array<std::int64_t, 3>& c1) {
    for (int k = 0; k < 3; ++k) {
      const Real top = Real((1 << 20) - 1);
      const Real x0 = std::isfinite(h) ? std::floor((a[k] - lo[k]) / h) : 0;
      const Real x1 = std::isfinite(h) ? std::floor((b[k] - lo[k]) / h) : 0;
      c0[size_t(k)] = std::int64_t(std::clamp(std::isfinite(x0) ? x0 : 0, Real(0), top));
      c1[size_t(k)] = std::int64_t(std::clamp(std::isfinite(x1) ? x1 : 0, Real(0), top));
    }
  };
  auto entriesFor = [&]() {
    long double total = 0;
    std::array<std::int64_t, 3> c0, c1;
    for (const Tri& t : tris) {
      cellRange(t.lo, t.hi, c0, c1);
      total += (long double)(c1[0] - c0[0] + 1) * (c1[1] - c0[1] + 1) * (c1[2] - c0[2] + 1);
    }
    return total;
  };
  for (int grow = 0; grow < 60 && std::isfinite(h) && entriesFor() > 16.0L * n + 1024; ++grow)
    h *= 2;

  auto key = [](std::int64_t x, std::int64_t y, std::int64_t z) {
    return (std::uint64_t(x) << 40) | (std::uint64_t(y) << 20) | std::uint64_t(z);
  };
  std::vector<std::pair<std::uint64_t, int>> entries;
  entries.reserve(4 * n);
  std::array<std::int64_t, 3> c0, c1;
  for (size_t i = 0; i < n; ++i) {
    cellRange(tris[i].lo, tris[i].hi, c0, c1);
    for (std::int64_t x = c0[0]; x <= c1[0]; ++x)
      for (std::int64_t y = c0[1]; y <= c1[1]; ++y)
        for (std::int64_t z = c0[2]; z <= c1[2]; ++z) entries.emplace_back(key(x, y, z), int(i));
  }
  std::sort(entries.begin(), entries.end());

  std::vector<std::array<int, 2>> found;
  for (size_t s = 0; s < entries.size();) {
    size_t e = s;
    while (e < entries.size() && entries[e].first == entries[s].first) ++e;
    for (size_t i = s; i < e; ++i) {
      const Tri& A = tris[size_t(entries[i].second)];
      for (size_t j = i + 1; j < e; ++j) {
        const Tri& B = tris[size_t(entries[j].second)];
        const Vec3 olo = A.lo.cwiseMax(B.lo), ohi = A.hi.cwiseMin(B.hi);
        if ((olo.array() > ohi.array()).any()) continue;
        // Test the pair only in the cell holding the low corner of the boxes' overlap.
        std::array<std::int64_t, 3> o0, o1;
        cellRange(olo, olo, o0, o1);
        if (key(o0[0], o0[1], o0[2]) != entries[s].first) continue;
        ++report.candidates;
        if (crosses(A, B)) {
          int f = faceOf[size_t(entries[i].second)], g = faceOf[size_t(entries[j].second)];
          if (f > g) std::swap(f, g);
          found.push_back({f, g});
        }
      }
    }
    s = e;
  }
  std::sort(found.begin(), found.end());
  report.pairs = (long long)found.size();
  if (maxListed >= 0 && found.size() > size_t(maxListed)) found.resize(size_t(maxListed));
  report.listed = std::move(found);
  return report;
}

std::vector<std::string> UntangleReport::lines() const {
  if (pairsBefore == 0) return {};
  const auto mm = [](Real v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.3g mm", 1e3 * v);
    return std::string(buf);
  };
  const std::string pairs = std::to_string(pairsBefore) + (pairsBefore == 1 ? " pair" : " pairs") +
                            " of self-intersecting triangles";
  if (ok()) {
    return {"untangled " + pairs + " by smoothing " + std::to_string(movedVertices) +
            " vertices (largest move " + mm(maxMove) + ")"};
  }
  return {"could not untangle " + pairs + " by local smoothing (" + std::to_string(rounds) +
          " rounds, largest move " + mm(maxMove) + "): surface left unchanged"};
}

UntangleReport untangleSelfIntersections(SurfaceMesh& mesh, int maxRounds, Real maxMoveEdges,
                                         Real maxRegionFraction) {
  UntangleReport rep;
  SelfIntersectionReport si = findSelfIntersections(mesh, -1);
  rep.pairsBefore = rep.pairsAfter = si.pairs;
  if (si.ok()) return rep;

  const int nv = mesh.numVertices();
  std::vector<std::vector<int>> ring(static_cast<size_t>(nv));
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int a = mesh.F(f, k), b = mesh.F(f, (k + 1) % 3);
      if (a < 0 || b < 0 || a >= nv || b >= nv) continue;
      ring[size_t(a)].push_back(b);
      ring[size_t(b)].push_back(a);
    }
  }
  for (auto& r : ring) {
    std::sort(r.begin(), r.end());
    r.erase(std::unique(r.begin(), r.end()), r.end());
  }

  const MatX3 original = mesh.V;
  Real edgeSum = 0;
  long long edges = 0;
  for (int i = 0; i < nv; ++i)
    for (int j : ring[size_t(i)])
      if (j > i) {
        edgeSum += (original.row(i) - original.row(j)).norm();
        ++edges;
      }
  const Real maxMove = maxMoveEdges * (edges ? edgeSum / Real(edges) : Real(0));
  const size_t maxRegion = static_cast<size_t>(maxRegionFraction * nv);
  std::vector<char> seed(size_t(nv), 0);
  const auto addPairs = [&](const SelfIntersectionReport& r) {
    for (const auto& pr : r.listed)
      for (int f : pr)
        for (int k = 0; k < 3; ++k) seed[size_t(mesh.F(f, k))] = 1;
  };
  addPairs(si);

  std::vector<int> region;
  std::vector<char> inRegion(size_t(nv), 0);
  MatX3 next;
  int rings = 1;
  for (int round = 1; round <= maxRounds; ++round) {
    rep.rounds = round;
    if (round % 3 == 0) ++rings;
    // The region: the seed vertices grown by `rings` rings (breadth first, sorted: deterministic).
    std::fill(inRegion.begin(), inRegion.end(), 0);
    region.clear();
    for (int i = 0; i < nv; ++i)
      if (seed[size_t(i)]) {
        inRegion[size_t(i)] = 1;
        region.push_back(i);
      }
    for (int r = 0; r < rings; ++r) {
      const size_t end = region.size();
      for (size_t q = 0; q < end; ++q)
        for (int j : ring[size_t(region[q])])
          if (!inRegion[size_t(j)]) {
            inRegion[size_t(j)] = 1;
            region.push_back(j);
          }
    }
    if (region.size() > maxRegion) break;
    std::sort(region.begin(), region.end());
    for (int sweep = 0; sweep < 3; ++sweep) {
      next = mesh.V;
      for (int i : region) {
        const auto& nb = ring[size_t(i)];
        if (nb.empty()) continue;
        Vec3 mean = Vec3::Zero();
        for (int j : nb) mean += mesh.V.row(j).transpose();
        mean /= Real(nb.size());
        next.row(i) = mesh.V.row(i) + 0.5 * (mean.transpose() - mesh.V.row(i));
      }
      mesh.V.swap(next);
    }
    rep.maxMove = (mesh.V - original).rowwise().norm().maxCoeff();
    if (rep.maxMove > maxMove) break;
    si = findSelfIntersections(mesh, -1);
    if (si.ok()) {
      rep.pairsAfter = 0;
      for (int i = 0; i < nv; ++i) rep.movedVertices += mesh.V.row(i) != original.row(i);
      return rep;
    }
    addPairs(si);
  }
  mesh.V = original;
  rep.pairsAfter = rep.pairsBefore;
  return rep;
}

void requireNoSelfIntersections(const SurfaceMesh& mesh, const std::string& file) {
  const SelfIntersectionReport r = findSelfIntersections(mesh, 1);
  if (r.ok()) return;
  throw InputError(file, "",
                   r.message() +
                       "; \"repair\": true in the scene's organ untangles small folds by local "
                       "smoothing; otherwise remesh or edit the surface so that it bounds a "
                       "valid volume");
}

std::vector<char> heldRegionAndEdge(const MatX3i& F, const std::vector<char>& held) {
  std::vector<char> edge(held.size(), 0);
  for (Eigen::Index t = 0; t < F.rows(); ++t)
    if (held[size_t(F(t, 0))] || held[size_t(F(t, 1))] || held[size_t(F(t, 2))])
      for (int k = 0; k < 3; ++k) edge[size_t(F(t, k))] = 1;
  return edge;
}

SelfIntersectionCount countSelfIntersections(const SurfaceMesh& moved,
                                             const std::vector<char>& nearHeld) {
  SelfIntersectionCount out;
  const SelfIntersectionReport s = findSelfIntersections(moved, std::numeric_limits<int>::max());
  const auto atHeld = [&](int t) {
    const auto f = moved.F.row(t);
    return nearHeld[size_t(f(0))] || nearHeld[size_t(f(1))] || nearHeld[size_t(f(2))];
  };
  for (const auto& [a, b] : s.listed) (atHeld(a) || atHeld(b) ? out.atHeld : out.free)++;
  return out;
}

}  // namespace deform
