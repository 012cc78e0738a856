// particle_bem: the coarse BEM surface. Quadric edge collapse (Garland & Heckbert 1997,
// "Surface simplification using quadric error metrics"): every vertex carries the area-weighted
// sum of the quadrics K_p = p p^T of its faces' planes p = (n, -n.x0); the edge (a, b) with the
// least cost v^T (Q_a + Q_b) v is collapsed to the v that minimises it.
//
// Two changes for a BEM surface, whose elements should be even-sized and well shaped:
//  - a regulariser eps * Abar * |v - m|^2 (m the edge midpoint, Abar the mean face area) is added
//    to every edge's quadric, so flat regions are simplified evenly (shortest edges first) and
//    the 3x3 system for v is always positive definite;
//  - a collapse is refused when it would break the closed 2-manifold (link condition: a and b
//    share exactly the two opposite vertices; no vertex left with valence < 3), flip a face
//    (normal turns by more than ~80 degrees) or create a triangle whose quality
//    4 sqrt(3) area / sum(edge^2) is below 0.1 (unless it was already that bad).
//
// With fixed regions (boxes; the input cut along their faces by conformToBoxes) the partition
// of the triangles into "in the fixed region" and "outside" is kept: every face keeps its tag
// and must stay on its side after a collapse (triangleConforms), so a vertex on the region's
// boundary curve can only slide along the box face (the optimum moved onto the plane, or an
// end point), an interior vertex merges into a boundary vertex at the boundary vertex's place,
// and two boundary vertices joined by an edge that is not part of the curve are never merged.
// The boundary curve stays a closed polyline on the box faces, coarser but exact to round-off.
#pragma once

#include <deform/sdk/mesh.h>

#include <vector>

namespace deform::particle_bem {

struct DecimationStats {
  int collapses = 0;
  int refusedTopology = 0;  ///< link condition / valence
  int refusedGeometry = 0;  ///< flip or quality
};

/// Decimates a closed, manifold, outward surface to at most targetVertices vertices (stops
/// earlier, with fewer collapses, when no legal collapse is left). Returns the surface unchanged
/// when it already has <= targetVertices. Deterministic.
SurfaceMesh decimateQuadric(const SurfaceMesh& in, int targetVertices,
                            DecimationStats* stats = nullptr, Real regulariser = 0.05);

/// The same, keeping the partition of the surface by the fixed regions (header comment); the
/// input should conform to them (conformToBoxes). Collapses with no position that keeps every
/// face on its side are refused (counted in refusedGeometry).
SurfaceMesh decimateQuadric(const SurfaceMesh& in, int targetVertices,
                            const std::vector<Box>& fixedRegions, DecimationStats* stats = nullptr,
                            Real regulariser = 0.05);

}  // namespace deform::particle_bem
