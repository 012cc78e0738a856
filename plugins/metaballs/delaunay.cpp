#include "delaunay.h"

#include <stdexcept>
#include <string>

extern "C" {
#include <libqhull_r/qhull_ra.h>
}

namespace deform::metaballs {

std::vector<std::array<int, 4>> delaunayTetrahedra(const MatX3& points) {
  const int n = int(points.rows());
  std::vector<coordT> coords(size_t(n) * 3);
  for (int i = 0; i < n; ++i)
    for (int d = 0; d < 3; ++d) coords[size_t(3 * i + d)] = points(i, d);
  std::vector<std::array<int, 4>> tets;
  qhT qhStorage;
  qhT* qh = &qhStorage;
  QHULL_LIB_CHECK
  qh_zero(qh, stderr);
  // d: Delaunay; Qt: triangulated (simplicial) output; Qbb: scale the paraboloid coordinate;
  // Qz: add a point at infinity (phantoms are often sampled on cospherical points).
  char flags[] = "qhull d Qt Qbb Qz";
  const int code = qh_new_qhull(qh, 3, n, coords.data(), False, flags, nullptr, stderr);
  if (code == 0) {
    facetT* facet;
    vertexT *vertex, **vertexp;
    FORALLfacets {
      if (facet->upperdelaunay) continue;
      std::array<int, 4> t{-1, -1, -1, -1};
      int k = 0;
      bool ok = true;
      FOREACHvertex_(facet->vertices) {
        const int id = qh_pointid(qh, vertex->point);
        if (k >= 4 || id < 0 || id >= n) {
          ok = false;
          break;
        }
        t[size_t(k++)] = id;
      }
      if (ok && k == 4) tets.push_back(t);
    }
  }
  qh_freeqhull(qh, !qh_ALL);
  int curlong = 0, totlong = 0;
  qh_memfreeshort(qh, &curlong, &totlong);
  if (code != 0)
    throw std::runtime_error("Qhull Delaunay failed with exit code " + std::to_string(code));
  return tets;
}

}  // namespace deform::metaballs
