#include "incision.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>

#include "load_processing.h"

namespace deform::hybrid_fem_pbd {

CuttableSurface CuttableSurface::fromMesh(const MatX3& x, const MatX3& rest, const MatX3i& F) {
  CuttableSurface s;
  s.x = x;
  s.rest = rest;
  s.originalF = F;
  s.originalVertices = static_cast<int>(x.rows());
  s.F.resize(F.rows());
  s.parentFace.resize(F.rows());
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    s.F[f] = F.row(f).transpose();
    s.parentFace[f] = static_cast<int>(f);
  }
  s.origin.resize(x.rows());
  for (Eigen::Index v = 0; v < x.rows(); ++v) {
    s.origin[v].count = 1;
    s.origin[v].v[0] = static_cast<int>(v);
    s.origin[v].w[0] = 1;
  }
  return s;
}

MatX3i CuttableSurface::faces() const {
  MatX3i out(static_cast<Eigen::Index>(F.size()), 3);
  for (size_t f = 0; f < F.size(); ++f) out.row(f) = F[f].transpose();
  return out;
}

Vec3 CuttableSurface::baryInOriginalFace(int v, int f) const {
  Vec3 b = Vec3::Zero();
  const VertexOrigin& o = origin[v];
  for (int i = 0; i < o.count; ++i)
    for (int k = 0; k < 3; ++k)
      if (originalF(f, k) == o.v[i]) b[k] += o.w[i];
  return b;
}

Real restDistanceInTriangle(Real lAB, Real lBC, Real lCA, const Vec3& bp, const Vec3& bq) {
  // Law of cosines at A: the angle between AB and AC from the three rest lengths.
  Real cosA = 1;
  if (lAB > 0 && lCA > 0) cosA = (lAB * lAB + lCA * lCA - lBC * lBC) / (2 * lAB * lCA);
  cosA = std::clamp<Real>(cosA, -1, 1);
  const Real sinA = std::sqrt(std::max<Real>(0, 1 - cosA * cosA));
  const Eigen::Matrix<Real, 2, 1> B(lAB, 0), C(lCA * cosA, lCA * sinA);
  const Vec3 d = bp - bq;  // A sits at the origin, so only B's and C's weights matter
  return (d[1] * B + d[2] * C).norm();
}

namespace {

constexpr int kNone = -1;

// Incremental edits of a CuttableSurface with a vertex -> triangle index.
struct Editor {
  CuttableSurface& s;
  std::vector<std::vector<int>> vf;
  explicit Editor(CuttableSurface& surface) : s(surface) {
    vf.assign(s.x.rows(), {});
    for (size_t f = 0; f < s.F.size(); ++f)
      for (int k = 0; k < 3; ++k) vf[s.F[f][k]].push_back(static_cast<int>(f));
  }

  Vec3 pos(int v) const { return s.x.row(v).transpose(); }

  int addVertex(const int* src, const Real* w, int n) {
    const int id = static_cast<int>(s.x.rows());
    Vec3 x = Vec3::Zero(), r = Vec3::Zero();
    std::map<int, Real> o;
    for (int i = 0; i < n; ++i) {
      x += w[i] * s.x.row(src[i]).transpose();
      r += w[i] * s.rest.row(src[i]).transpose();
      const VertexOrigin& so = s.origin[src[i]];
      for (int k = 0; k < so.count; ++k) o[so.v[k]] += w[i] * so.w[k];
    }
    s.x.conservativeResize(id + 1, 3);
    s.rest.conservativeResize(id + 1, 3);
    s.x.row(id) = x.transpose();
    s.rest.row(id) = r.transpose();
    VertexOrigin vo;
    for (const auto& [v, wt] : o) {
      if (std::abs(wt) <= 1e-15 || vo.count == 3) continue;  // > 3 cannot happen inside a face
      vo.v[vo.count] = v;
      vo.w[vo.count] = wt;
      ++vo.count;
    }
    s.origin.push_back(vo);
    vf.emplace_back();
    return id;
  }

  void setFace(int f, const Vec3i& nf) {
    for (int k = 0; k < 3; ++k) {
      auto& l = vf[s.F[f][k]];
      l.erase(std::remove(l.begin(), l.end(), f), l.end());
    }
    s.F[f] = nf;
    for (int k = 0; k < 3; ++k) vf[nf[k]].push_back(f);
  }
  int addFace(const Vec3i& nf, int parent) {
    const int f = static_cast<int>(s.F.size());
    s.F.push_back(nf);
    s.parentFace.push_back(parent);
    for (int k = 0; k < 3; ++k) vf[nf[k]].push_back(f);
    return f;
  }

  int splitEdge(int u, int v, Real t) {
    const int src[2] = {u, v};
    const Real w[2] = {1 - t, t};
    const int m = addVertex(src, w, 2);
    const std::vector<int> around = vf[u];
    for (int f : around) {
      const Vec3i tri = s.F[f];
      for (int k = 0; k < 3; ++k) {
        const int a = tri[k], b = tri[(k + 1) % 3], c = tri[(k + 2) % 3];
        if (!((a == u && b == v) || (a == v && b == u))) continue;
        setFace(f, Vec3i(a, m, c));
        addFace(Vec3i(m, b, c), s.parentFace[f]);
        break;
      }
    }
    return m;
  }

  int splitFace(int f, const Vec3& bary) {
    const Vec3i tri = s.F[f];
    const int src[3] = {tri[0], tri[1], tri[2]};
    const Real w[3] = {bary[0], bary[1], bary[2]};
    const int m = addVertex(src, w, 3);
    setFace(f, Vec3i(tri[0], tri[1], m));
    addFace(Vec3i(tri[1], tri[2], m), s.parentFace[f]);
    addFace(Vec3i(tri[2], tri[0], m), s.parentFace[f]);
    return m;
  }

  // Closest point on face f to p.
  Vec3 closest(int f, const Vec3& p, Vec3& bary) const {
    return closestPointOnTriangle(p, pos(s.F[f][0]), pos(s.F[f][1]), pos(s.F[f][2]), bary);
  }

  // Nearest face to p (ties to the lower index), its closest point, distance and barycentrics.
  int locate(const Vec3& p, Vec3& q, Vec3& bary, Real& dist) const {
    int best = kNone;
    dist = std::numeric_limits<Real>::infinity();
    for (size_t f = 0; f < s.F.size(); ++f) {
      Vec3 b;
      const Vec3 c = closest(static_cast<int>(f), p, b);
      const Real d = (c - p).norm();
      if (d < dist) {
        dist = d;
        best = static_cast<int>(f);
        q = c;
        bary = b;
      }
    }
    return best;
  }

  // Inserts the point with barycentric coordinates b in face f, snapping to a vertex or edge
  // within `snap`. Counts the kind of point in the report.
  int insertPoint(int f, const Vec3& b, Real snap, CutReport& rep) {
    const Vec3i tri = s.F[f];
    for (int k = 0; k < 3; ++k) {
      if (b[k] >= 1 - snap) {
        ++rep.vertexPoints;
        return tri[k];
      }
    }
    for (int k = 0; k < 3; ++k) {
      if (b[k] >= snap) continue;
      const int i = tri[(k + 1) % 3], j = tri[(k + 2) % 3];
      const Real bi = b[(k + 1) % 3], bj = b[(k + 2) % 3];
      const Real t = bj / std::max(bi + bj, std::numeric_limits<Real>::min());
      if (t <= snap) {
        ++rep.vertexPoints;
        return i;
      }
      if (t >= 1 - snap) {
        ++rep.vertexPoints;
        return j;
      }
      ++rep.edgePoints;
      return splitEdge(i, j, t);
    }
    ++rep.facetPoints;
    return splitFace(f, b);
  }

  // The triangle fan of v from the triangle holding v -> b round to the one holding a -> v
  // (the left side of the path a -> v -> b). Empty when v's fan is not a closed disc.
  std::vector<int> leftFan(int v, int a, int b) const {
    auto nextPrev = [&](int f, int& next, int& prev) {
      const Vec3i& t = s.F[f];
      for (int k = 0; k < 3; ++k)
        if (t[k] == v) {
          next = t[(k + 1) % 3];
          prev = t[(k + 2) % 3];
        }
    };
    int f = kNone;
    for (int g : vf[v]) {
      int n = -1, p = -1;
      nextPrev(g, n, p);
      if (n == b) f = g;
    }
    std::vector<int> fan;
    for (size_t guard = 0; f != kNone && guard <= vf[v].size(); ++guard) {
      fan.push_back(f);
      int n = -1, p = -1;
      nextPrev(f, n, p);
      if (p == a) return fan;
      int g2 = kNone;
      for (int g : vf[v]) {
        int n2 = -1, p2 = -1;
        nextPrev(g, n2, p2);
        if (n2 == p) g2 = g;
      }
      f = g2;
    }
    return {};
  }
};

// The triangle around vertex c whose wedge at c holds the direction to `target` (projected
// into the triangle's plane, as dir): the one maximising the smaller of the two sines between
// dir and the triangle's edges from c (face kNone when no triangle qualifies).
struct Wedge {
  int face = kNone, u = kNone, v = kNone;
  Vec3 dir = Vec3::Zero();
};
Wedge exitWedge(const Editor& ed, int c, const Vec3& target) {
  const Vec3 xc = ed.pos(c);
  Wedge w;
  Real bestScore = -std::numeric_limits<Real>::infinity();
  for (int g : ed.vf[c]) {
    const Vec3i& t = ed.s.F[g];
    int kc = 0;
    while (t[kc] != c) ++kc;
    const int u = t[(kc + 1) % 3], v = t[(kc + 2) % 3];
    const Vec3 eu = ed.pos(u) - xc, ev = ed.pos(v) - xc;
    const Vec3 n = eu.cross(ev).normalized();
    Vec3 d = target - xc;
    d -= d.dot(n) * n;
    const Real dn = d.norm(), un = eu.norm(), vn = ev.norm();
    if (!(dn > 0) || !(un > 0) || !(vn > 0)) continue;
    const Real s1 = eu.cross(d).dot(n) / (un * dn), s2 = d.cross(ev).dot(n) / (dn * vn);
    const Real score = std::min(s1, s2);
    if (score > bestScore) {
      bestScore = score;
      w = {g, u, v, d};
    }
  }
  return w;
}

}  // namespace

CutReport cutSurface(CuttableSurface& surface, const CutPath& path, const CutOptions& options) {
  CutReport rep;
  if (path.points.size() < 2) {
    rep.reason = "a cut path needs at least two points";
    return rep;
  }
  CuttableSurface s = surface;  // transactional: commit only on success
  Editor ed(s);
  const int v0 = s.numVertices(), f0 = static_cast<int>(s.F.size());
  const Real snap = std::clamp<Real>(options.snapFraction, 0, 0.3);
  const Box box = boundingBox(s.x);
  const Real tiny = 1e-9 * std::max<Real>(box.diagonal(), 1e-12);

  Vec3 q, b;
  Real dist;
  int f = ed.locate(path.points[0], q, b, dist);
  if (f == kNone) {
    rep.reason = "empty surface";
    return rep;
  }
  std::vector<int> cutPath = {ed.insertPoint(f, b, snap, rep)};
  const size_t maxSteps = 8 * s.F.size() + 16;
  size_t steps = 0;
  for (size_t k = 1; k < path.points.size(); ++k) {
    Vec3 target, tb;
    Real tdist;
    if (ed.locate(path.points[k], target, tb, tdist) == kNone) break;
    while (true) {
      if (++steps > maxSteps) {
        rep.reason = "the cut walk did not converge";
        return rep;
      }
      const int c = cutPath.back();
      const Vec3 xc = ed.pos(c);
      if ((target - xc).norm() <= tiny) break;
      // Target inside a triangle around c: insert it there (it then shares an edge with c).
      int inFace = kNone;
      Vec3 inBary;
      Real inDist = std::numeric_limits<Real>::infinity();
      for (int g : ed.vf[c]) {
        Vec3 bb;
        const Real d = (ed.closest(g, target, bb) - target).norm();
        if (d < inDist) {
          inDist = d;
          inFace = g;
          inBary = bb;
        }
      }
      if (inFace != kNone && inDist <= tiny) {
        const int m = ed.insertPoint(inFace, inBary, snap, rep);
        if (m != c) cutPath.push_back(m);
        break;
      }
      // Otherwise leave c through the triangle whose wedge contains the direction to the target.
      const Wedge w = exitWedge(ed, c, target);
      const int best = w.face, bu = w.u, bv = w.v;
      const Vec3 bestDir = w.dir;
      if (best == kNone) {
        rep.reason = "the cut reached a degenerate neighbourhood";
        return rep;
      }
      // Solve xc + a dir = xu + t (xv - xu) in the triangle's plane (least squares).
      const Vec3 xu = ed.pos(bu), e = ed.pos(bv) - xu;
      Eigen::Matrix<Real, 3, 2> A;
      A.col(0) = bestDir;
      A.col(1) = -e;
      const Eigen::Matrix<Real, 2, 1> sol =
          (A.transpose() * A).ldlt().solve(A.transpose() * (xu - xc));
      const Real t = std::clamp<Real>(sol[1], 0, 1);
      int next;
      if (t <= snap) {
        next = bu;
        ++rep.vertexPoints;
      } else if (t >= 1 - snap) {
        next = bv;
        ++rep.vertexPoints;
      } else {
        next = ed.splitEdge(bu, bv, t);
        ++rep.edgePoints;
      }
      if ((ed.pos(next) - target).norm() >= (xc - target).norm() - tiny) {
        rep.reason = "the cut walk made no progress (path leaves the surface?)";
        return rep;
      }
      cutPath.push_back(next);
    }
  }
  // The path must be simple.
  std::vector<int> sorted = cutPath;
  std::sort(sorted.begin(), sorted.end());
  if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) {
    rep.reason = "the cut path crosses itself";
    return rep;
  }
  if (cutPath.size() < 2) {
    rep.reason = "the cut is shorter than the snapping distance";
    return rep;
  }
  if (cutPath.size() == 2) {  // both ends are tips: a midpoint lets the cut open
    const int m = ed.splitEdge(cutPath[0], cutPath[1], 0.5);
    ++rep.edgePoints;
    cutPath.insert(cutPath.begin() + 1, m);
  }
  // Left fans of the interior path vertices, all computed before any vertex is duplicated.
  std::vector<std::vector<int>> fans;
  for (size_t i = 1; i + 1 < cutPath.size(); ++i) {
    std::vector<int> fan = ed.leftFan(cutPath[i], cutPath[i - 1], cutPath[i + 1]);
    if (fan.empty() || fan.size() == ed.vf[cutPath[i]].size()) {
      rep.reason = "the cut runs through a vertex on an open boundary";
      return rep;
    }
    fans.push_back(std::move(fan));
  }
  for (size_t i = 1; i + 1 < cutPath.size(); ++i) {
    const int v = cutPath[i];
    const Real one = 1;
    const int copy = ed.addVertex(&v, &one, 1);
    for (int g : fans[i - 1]) {
      Vec3i t = s.F[g];
      for (int k = 0; k < 3; ++k)
        if (t[k] == v) t[k] = copy;
      ed.setFace(g, t);
    }
    rep.duplicates.emplace_back(v, copy);
  }
  rep.path = cutPath;
  rep.newVertices = s.numVertices() - v0;
  rep.newFaces = static_cast<int>(s.F.size()) - f0;
  rep.applied = true;
  surface = std::move(s);
  return rep;
}

SurfaceConstraints constraintsAfterCut(const CuttableSurface& s,
                                       const SurfaceConstraints& original) {
  auto key = [](int a, int b) { return std::make_pair(std::min(a, b), std::max(a, b)); };
  std::map<std::pair<int, int>, Real> restLength, restAngle;
  for (const auto& d : original.stretch) restLength[key(d.a, d.b)] = d.rest;
  for (const auto& h : original.bending) restAngle[key(h.p[2], h.p[3])] = h.restAngle;
  auto origLength = [&](int a, int b) {
    const auto it = restLength.find(key(a, b));
    return it != restLength.end() ? it->second : (s.rest.row(a) - s.rest.row(b)).norm();
  };

  SurfaceConstraints out;
  const MatX3i F = s.faces();
  const MatX2i E = uniqueEdges(F);
  const MatX2i EF = edgeFaces(F, E);
  for (Eigen::Index e = 0; e < E.rows(); ++e) {
    pbd::DistanceConstraint d;
    d.a = E(e, 0);
    d.b = E(e, 1);
    const int fa = EF(e, 0), fb = EF(e, 1);
    const int pa = s.parentFace[fa];
    const int A = s.originalF(pa, 0), B = s.originalF(pa, 1), C = s.originalF(pa, 2);
    const bool originalEdge =
        d.a < s.originalVertices && d.b < s.originalVertices && restLength.count(key(d.a, d.b));
    if (originalEdge) {
      d.rest = restLength[key(d.a, d.b)];
    } else {
      d.rest = restDistanceInTriangle(origLength(A, B), origLength(B, C), origLength(C, A),
                                      s.baryInOriginalFace(d.a, pa), s.baryInOriginalFace(d.b, pa));
    }
    out.stretch.push_back(d);
    if (fb < 0) continue;
    pbd::DihedralConstraint h;
    if (!orderHinge(F, fa, fb, d.a, d.b, h)) continue;
    const int pb = s.parentFace[fb];
    if (pa == pb) {
      h.restAngle = 0;  // both pieces lie in one flat original triangle
    } else {
      // The original edge the two parents share.
      std::vector<int> shared;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          if (s.originalF(pa, i) == s.originalF(pb, j)) shared.push_back(s.originalF(pa, i));
      const auto it =
          shared.size() == 2 ? restAngle.find(key(shared[0], shared[1])) : restAngle.end();
      if (it != restAngle.end()) {
        h.restAngle = it->second;
      } else {
        Vec3 g[4];
        Real theta = 0;
        if (!pbd::dihedralAngle(s.rest.row(h.p[0]).transpose(), s.rest.row(h.p[1]).transpose(),
                                s.rest.row(h.p[2]).transpose(), s.rest.row(h.p[3]).transpose(),
                                theta, g))
          continue;
        h.restAngle = theta;
      }
    }
    out.bending.push_back(h);
  }
  return out;
}

}  // namespace deform::hybrid_fem_pbd
