#include "topology.h"

#include <deform/geometry/kdtree.h>

#include <algorithm>
#include <limits>
#include <numeric>
#include <tuple>
#include <utility>

namespace deform::metaballs {

namespace {
struct UnionFind {
  std::vector<int> p;
  explicit UnionFind(int n) : p(size_t(n)) { std::iota(p.begin(), p.end(), 0); }
  int find(int x) {
    while (p[size_t(x)] != x) x = p[size_t(x)] = p[size_t(p[size_t(x)])];
    return x;
  }
  bool unite(int a, int b) {
    a = find(a);
    b = find(b);
    if (a == b) return false;
    p[size_t(std::max(a, b))] = std::min(a, b);
    return true;
  }
};
}  // namespace

int countComponents(int n, const MatX2i& links) {
  UnionFind uf(n);
  int comps = n;
  for (Eigen::Index l = 0; l < links.rows(); ++l)
    comps -= uf.unite(links(l, 0), links(l, 1)) ? 1 : 0;
  return comps;
}

Topology buildTopology(const SphereSet& spheres, int maxNeighbours) {
  Topology topo;
  const int n = spheres.size();
  topo.selected.resize(size_t(n));
  if (n == 0) return topo;
  const KdTree3 tree(spheres.centers);
  const Real rmax = spheres.radii.maxCoeff();
  std::vector<int> hits;
  std::vector<std::pair<int, int>> pairs;
  for (int i = 0; i < n; ++i) {
    tree.radius(spheres.center(i), spheres.radii(i) + rmax, hits);  // nearest first
    auto& sel = topo.selected[size_t(i)];
    for (int j : hits) {
      if (j == i) continue;
      const Real d = (spheres.center(i) - spheres.center(j)).norm();
      if (d < spheres.radii(i) + spheres.radii(j)) sel.push_back(j);
      if (int(sel.size()) == maxNeighbours) break;
    }
    for (int j : sel) pairs.emplace_back(std::min(i, j), std::max(i, j));
  }
  // Bridges: join components through their closest pair of spheres (Kruskal on gaps).
  UnionFind uf(n);
  for (const auto& [a, b] : pairs) uf.unite(a, b);
  int comps = 0;
  for (int i = 0; i < n; ++i) comps += uf.find(i) == i ? 1 : 0;
  if (comps > 1) {
    std::vector<std::tuple<Real, int, int>> cand;
    for (int i = 0; i < n; ++i)
      for (int j = i + 1; j < n; ++j) {
        if (uf.find(i) == uf.find(j)) continue;
        const Real gap =
            (spheres.center(i) - spheres.center(j)).norm() - spheres.radii(i) - spheres.radii(j);
        cand.emplace_back(gap, i, j);
      }
    std::sort(cand.begin(), cand.end());
    for (const auto& [gap, i, j] : cand) {
      if (uf.unite(i, j)) {
        pairs.emplace_back(i, j);
        ++topo.bridges;
      }
    }
  }
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  topo.links.resize(Eigen::Index(pairs.size()), 2);
  for (size_t l = 0; l < pairs.size(); ++l) {
    topo.links(Eigen::Index(l), 0) = pairs[l].first;
    topo.links(Eigen::Index(l), 1) = pairs[l].second;
  }
  return topo;
}

}  // namespace deform::metaballs
