#include "surface_pbd.h"

#include <algorithm>
#include <array>
#include <bit>
#include <cstdint>

namespace deform::hybrid_fem_pbd {

bool orderHinge(const MatX3i& F, int fa, int fb, int a, int b, pbd::DihedralConstraint& h) {
  int s = -1, t = -1, wingA = -1, wingB = -1;
  for (int k = 0; k < 3; ++k) {
    const int u = F(fa, k), v = F(fa, (k + 1) % 3);
    if ((u == a && v == b) || (u == b && v == a)) {
      s = u;
      t = v;
      wingA = F(fa, (k + 2) % 3);
    }
  }
  int shared = 0;
  for (int k = 0; k < 3; ++k) {
    const int u = F(fb, k);
    if (u != a && u != b)
      wingB = u;
    else
      ++shared;
  }
  if (s < 0 || wingB < 0 || shared != 2) return false;
  h.p[0] = wingA;
  h.p[1] = wingB;
  h.p[2] = s;
  h.p[3] = t;
  return true;
}

SurfaceConstraints buildSurfaceConstraints(const MatX3& restV, const MatX3i& F,
                                           long long* skipped) {
  SurfaceConstraints c;
  const MatX2i E = uniqueEdges(F);
  const MatX2i EF = edgeFaces(F, E);
  c.stretch.reserve(E.rows());
  c.bending.reserve(E.rows());
  long long bad = 0;
  for (Eigen::Index e = 0; e < E.rows(); ++e) {
    pbd::DistanceConstraint d;
    d.a = E(e, 0);
    d.b = E(e, 1);
    d.rest = (restV.row(d.a) - restV.row(d.b)).norm();
    c.stretch.push_back(d);
    const int fa = EF(e, 0), fb = EF(e, 1);
    if (fa < 0 || fb < 0) continue;
    pbd::DihedralConstraint h;
    if (!orderHinge(F, fa, fb, d.a, d.b, h)) {
      ++bad;
      continue;
    }
    Vec3 g[4];
    Real theta = 0;
    if (!pbd::dihedralAngle(restV.row(h.p[0]).transpose(), restV.row(h.p[1]).transpose(),
                            restV.row(h.p[2]).transpose(), restV.row(h.p[3]).transpose(), theta,
                            g)) {
      ++bad;
      continue;
    }
    h.restAngle = theta;
    c.bending.push_back(h);
  }
  if (skipped) *skipped += bad;
  return c;
}

namespace {

// Greedy colouring over the movable particles: constraints of one colour share no movable
// particle, and projecting colour by colour (a fixed, deterministic Gauss-Seidel order) lets the
// CPU overlap independent projections instead of waiting on a chain through one free node.
template <class NodesOf>
std::vector<int> orderByColour(const std::vector<int>& ids, const VecX& w, NodesOf nodesOf,
                               std::vector<int>& colourStart, bool& overflow) {
  std::vector<std::uint64_t> used(w.size(), 0);
  std::vector<std::pair<int, int>> key(ids.size());
  for (size_t i = 0; i < ids.size(); ++i) {
    std::uint64_t mask = 0;
    for (int n : nodesOf(ids[i]))
      if (n >= 0 && w[n] > 0) mask |= used[n];
    const int colour = (~mask == 0) ? 63 : std::countr_zero(~mask);
    overflow |= ~mask == 0;
    for (int n : nodesOf(ids[i]))
      if (n >= 0 && w[n] > 0) used[n] |= std::uint64_t(1) << colour;
    key[i] = {colour, ids[i]};
  }
  std::sort(key.begin(), key.end());
  std::vector<int> out(ids.size());
  colourStart.clear();
  for (size_t i = 0; i < key.size(); ++i) {
    out[i] = key[i].second;
    if (i == 0 || key[i].first != key[i - 1].first) colourStart.push_back(static_cast<int>(i));
  }
  colourStart.push_back(static_cast<int>(key.size()));
  return out;
}

}  // namespace

void hingeDenominatorWeights(const Real w[4], Real wd[4]) {
  Real sum = 0;
  int movable = 0;
  for (int k = 0; k < 4; ++k)
    if (w[k] > 0) {
      sum += w[k];
      ++movable;
    }
  const Real standIn = movable > 0 ? sum / movable : 0;
  for (int k = 0; k < 4; ++k) wd[k] = w[k] > 0 ? w[k] : standIn;
}

ActiveConstraints activeConstraints(const SurfaceConstraints& c, const VecX& w) {
  ActiveConstraints a;
  for (size_t i = 0; i < c.stretch.size(); ++i)
    if (w[c.stretch[i].a] > 0 || w[c.stretch[i].b] > 0) a.stretch.push_back(static_cast<int>(i));
  for (size_t i = 0; i < c.bending.size(); ++i) {
    const auto& h = c.bending[i];
    if (w[h.p[0]] > 0 || w[h.p[1]] > 0 || w[h.p[2]] > 0 || w[h.p[3]] > 0)
      a.bending.push_back(static_cast<int>(i));
  }
  a.stretch = orderByColour(
      a.stretch, w,
      [&](int i) {
        return std::array<int, 4>{c.stretch[i].a, c.stretch[i].b, -1, -1};
      },
      a.stretchColourStart, a.stretchColourOverflow);
  a.bending = orderByColour(
      a.bending, w,
      [&](int i) {
        const auto& h = c.bending[i];
        return std::array<int, 4>{h.p[0], h.p[1], h.p[2], h.p[3]};
      },
      a.bendingColourStart, a.bendingColourOverflow);
  return a;
}

long long projectSurfaceConstraints(MatX3& p, const VecX& w, const SurfaceConstraints& c,
                                    const ActiveConstraints& active, Real kStretch, Real kBending,
                                    int iterations) {
  const Real ks = pbd::classicStiffness(std::clamp<Real>(kStretch, 0, 1), iterations);
  const Real kb = pbd::classicStiffness(std::clamp<Real>(kBending, 0, 1), iterations);
  long long degenerate = 0;
  for (int it = 0; it < iterations; ++it) {
    for (int i : active.stretch) {
      const pbd::DistanceConstraint& d = c.stretch[i];
      Real lambda = 0;  // classic PBD: no multiplier memory
      Vec3 dxa, dxb;
      if (!pbd::projectDistance(p.row(d.a).transpose(), p.row(d.b).transpose(), w[d.a], w[d.b],
                                d.rest, 0, ks, lambda, dxa, dxb)) {
        ++degenerate;
        continue;
      }
      p.row(d.a) += dxa.transpose();
      p.row(d.b) += dxb.transpose();
    }
    if (kb <= 0) continue;
    for (int i : active.bending) {
      const pbd::DihedralConstraint& h = c.bending[i];
      Vec3 x[4], dx[4];
      Real wi[4], wd[4];
      for (int k = 0; k < 4; ++k) {
        x[k] = p.row(h.p[k]).transpose();
        wi[k] = w[h.p[k]];
      }
      hingeDenominatorWeights(wi, wd);
      Real lambda = 0;
      if (!pbd::projectDihedral(x, wi, wd, h.restAngle, 0, kb, lambda, dx)) {
        ++degenerate;
        continue;
      }
      for (int k = 0; k < 4; ++k)
        if (wi[k] > 0) p.row(h.p[k]) += dx[k].transpose();
    }
  }
  return degenerate;
}

}  // namespace deform::hybrid_fem_pbd
