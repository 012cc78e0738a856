// Metaballs plugin, construction stage 6 (paper Sect. 5.1, eq. 5): each sphere i selects its
// links among the spheres overlapping it (|c_i - c_j| < r_i + r_j):
//     Topo(i) = L(c_i)  (all overlapping spheres)          if num(i) <= N,
//               L'(c_i) (the N overlapping spheres nearest) if num(i) >  N,          (5)
// N = 9 by default. The links are the union of the selections (a link exists when either end
// selected it), each stored once. Eq. (5) bounds each sphere's own selection by N; a sphere may
// carry more links when other spheres selected it. When the overlap graph is not connected (it can
// be after the optimisation moved spheres), components are joined by bridge links between their
// closest spheres (smallest gap |c_i - c_j| - r_i - r_j), so the body moves as one; bridges are
// counted.
#pragma once

#include "sphere_set.h"

#include <vector>

namespace deform::metaballs {

struct Topology {
  MatX2i links;                            ///< #L by 2, i < j, sorted
  std::vector<std::vector<int>> selected;  ///< Topo(i) of eq. (5), nearest first
  int bridges = 0;                         ///< links added to connect components
};

Topology buildTopology(const SphereSet& spheres, int maxNeighbours);

/// Number of connected components of the graph (n vertices, links).
int countComponents(int n, const MatX2i& links);

}  // namespace deform::metaballs
