// Test meshes of the metaballs tests: a non-convex "banana" on the shared icosphere
// (tests/support/meshes.h), so the tests need not wait for the phantoms.
#pragma once

#include "../support/meshes.h"

namespace deform::metaballs::test {

/// A banana: an elongated ellipsoid bent along a circular arc in the x-z plane (non-convex).
inline SurfaceMesh banana(Real length, Real radius, Real bend, int level) {
  SurfaceMesh m = testing::ellipsoid(level, Vec3(0.5 * length, radius, radius));
  for (Eigen::Index i = 0; i < m.V.rows(); ++i) m.V(i, 2) += bend * m.V(i, 0) * m.V(i, 0) / length;
  return m;
}

}  // namespace deform::metaballs::test
