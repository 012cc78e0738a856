#include "electrostatic_optimisation.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace deform::metaballs {

namespace {

// Calls fn(voxel index, centre) for every voxel whose centre is within `radius` of c.
template <class Fn>
void forVoxelsInBall(const VoxelGrid& g, const Vec3& c, Real radius, Fn&& fn) {
  // Position in voxel-centre coordinates (voxel i has its centre at i).
  const Vec3 rel = (c - g.origin).array() / g.cellSize - 0.5;
  const Vec3 lo = rel.array() - radius / g.cellSize;
  const Vec3 hi = rel.array() + radius / g.cellSize;
  // One voxel of margin: the exact distance test below decides, not the rounded index range.
  const int i0 = std::max(0, int(std::floor(lo.x()))),
            i1 = std::min(g.dims.x() - 1, int(std::ceil(hi.x())));
  const int j0 = std::max(0, int(std::floor(lo.y()))),
            j1 = std::min(g.dims.y() - 1, int(std::ceil(hi.y())));
  const int k0 = std::max(0, int(std::floor(lo.z()))),
            k1 = std::min(g.dims.z() - 1, int(std::ceil(hi.z())));
  const Real r2 = radius * radius;
  for (int k = k0; k <= k1; ++k)
    for (int j = j0; j <= j1; ++j)
      for (int i = i0; i <= i1; ++i) {
        const Vec3 x = g.cellCenter(Vec3i(i, j, k));
        if ((x - c).squaredNorm() <= r2) fn(int(g.linearIndex(Vec3i(i, j, k))), x);
      }
}

struct State {
  const VoxelGrid& g;
  std::vector<int> cover;  // spheres containing each voxel centre
  long long hollow = 0;

  explicit State(const VoxelGrid& grid, const SphereSet& s)
      : g(grid), cover(grid.centreInside.size(), 0) {
    for (int i = 0; i < s.size(); ++i)
      forVoxelsInBall(g, s.center(i), s.radii(i), [&](int v, const Vec3&) { ++cover[size_t(v)]; });
    for (size_t v = 0; v < cover.size(); ++v)
      hollow += (g.centreInside[v] && cover[v] == 0) ? 1 : 0;
  }
  bool isHollow(int v) const { return g.centreInside[size_t(v)] && cover[size_t(v)] == 0; }
};

Vec3 attraction(const State& st, const Vec3& c, Real r, Real range) {
  Vec3 f = Vec3::Zero();
  forVoxelsInBall(st.g, c, r + range, [&](int v, const Vec3& x) {
    if (!st.isHollow(v)) return;
    const Vec3 d = x - c;
    const Real n = d.norm();
    if (n > 0) f += d / (n * n * n);
  });
  return r * r * r * f;
}

}  // namespace

long long countHollowVoxels(const SphereSet& spheres, const VoxelGrid& grid) {
  return State(grid, spheres).hollow;
}

ElectrostaticResult optimiseElectrostatic(SphereSet& spheres, const VoxelGrid& grid,
                                          const MeshDistance& dist, const ElectrostaticParams& p) {
  ElectrostaticResult res;
  res.insideVoxels = grid.numCentresInside();
  State st(grid, spheres);
  res.hollowBefore = st.hollow;
  const int n = spheres.size();
  const Real range = p.rangeVoxels * grid.cellSize;
  std::vector<Vec3> force(static_cast<size_t>(n));
  std::vector<uint8_t> stale(size_t(n), 1);
  for (int j = 0; j < n; ++j)
    force[size_t(j)] = attraction(st, spheres.center(j), spheres.radii(j), range);
  while (res.moves < p.maxMoves) {
    // The strongest attracted sphere not known to fail.
    int best = -1;
    Real bestF = 0;
    for (int j = 0; j < n; ++j) {
      if (!stale[size_t(j)]) continue;
      const Real fn = force[size_t(j)].norm();
      if (fn > bestF) {
        bestF = fn;
        best = j;
      }
    }
    if (best < 0) break;
    const int j = best;
    stale[size_t(j)] = 0;
    ++res.trials;
    const Vec3 c = spheres.center(j);
    const Real r = spheres.radii(j);
    const Vec3 cn = c + grid.cellSize * force[size_t(j)] / bestF;
    // Stay inside: the radius is kept unless the surface is nearer than r at the new centre.
    const Real rn = std::min(r, -dist.signedDistance(cn));
    if (rn < 0.5 * grid.cellSize) continue;
    long long gained = 0, lost = 0;
    forVoxelsInBall(grid, cn, rn, [&](int v, const Vec3&) { gained += st.isHollow(v) ? 1 : 0; });
    forVoxelsInBall(grid, c, r, [&](int v, const Vec3&) {
      if (grid.centreInside[size_t(v)] && st.cover[size_t(v)] == 1 &&
          (voxelCenter(grid, v) - cn).squaredNorm() > rn * rn)
        ++lost;
    });
    if (gained - lost <= 0) continue;
    forVoxelsInBall(grid, c, r, [&](int v, const Vec3&) { --st.cover[size_t(v)]; });
    forVoxelsInBall(grid, cn, rn, [&](int v, const Vec3&) { ++st.cover[size_t(v)]; });
    st.hollow -= gained - lost;
    spheres.centers.row(j) = cn.transpose();
    spheres.radii(j) = rn;
    ++res.moves;
    // Spheres whose force or trial outcome may have changed: near the moved sphere.
    for (int k = 0; k < n; ++k) {
      const Real reach = spheres.radii(k) + r + range + 2 * grid.cellSize;
      if (k == j || (spheres.center(k) - c).squaredNorm() <= reach * reach ||
          (spheres.center(k) - cn).squaredNorm() <= reach * reach) {
        stale[size_t(k)] = 1;
        force[size_t(k)] = attraction(st, spheres.center(k), spheres.radii(k), range);
      }
    }
  }
  // Report a recount from scratch (the running count only steers the search).
  res.hollowAfter = State(grid, spheres).hollow;
  return res;
}

}  // namespace deform::metaballs
