// Metaballs plugin: the 3-D Delaunay tetrahedralisation of a point set by Qhull (reentrant C API,
// libqhull_r; options "d Qt Qbb Qz"): the dual of the Voronoi diagram whose vertices (tetrahedra
// circumcentres) approximate the medial axis (paper Sect. 4.1). Kept in its own translation unit
// so that Qhull's macros stay out of the rest of the plugin.
#pragma once

#include <deform/sdk/types.h>

#include <array>
#include <vector>

namespace deform::metaballs {

/// Tetrahedra as indices into the rows of points (#P by 3); facets touching Qz's point at
/// infinity and upper-Delaunay facets are dropped. Throws std::runtime_error when Qhull fails.
std::vector<std::array<int, 4>> delaunayTetrahedra(const MatX3& points);

}  // namespace deform::metaballs
