// Shared helpers for the particle_bem tests: an icosphere and a box mesh built here, so the
// tests do not depend on the phantoms.
#pragma once

#include <deform/mesh.h>
#include <deform/model.h>

namespace deform::particle_bem::testing {

/// Icosphere of radius r centred at c, `levels` 4-way subdivisions (12, 42, 162, 642, 2562 v).
SurfaceMesh icosphere(int levels, Real r, const Vec3& c = Vec3::Zero());

/// Ellipsoid: icosphere scaled by (a, b, c).
SurfaceMesh ellipsoid(int levels, const Vec3& radii);

/// Checks closed 2-manifold: every undirected edge in exactly two faces, used once per
/// direction. Returns the number of bad edges.
int badEdges(const SurfaceMesh& s);

}  // namespace deform::particle_bem::testing
