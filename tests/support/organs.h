// Organs and inputs shared by tests and benchmarks (benchmarks include the tests folder):
// phantoms with a fixed bottom slab, the liver-sized surface held at its top. Include as
// "../support/organs.h" from tests, "support/organs.h" from benchmarks.
#pragma once

#include "meshes.h"

#include <deform/geometry/phantom.h>
#include <deform/sdk/mesh.h>
#include <deform/sdk/model.h>

#include <string>

namespace deform::testing {

/// The phantom `name` at `resolution` (E = 5.5 kPa, nu = 0.3, rho = 1000) with the nodes in the
/// bottom `slab` fraction of its height fixed (the box reaches 1 cm beyond the organ sideways and
/// below).
inline Organ phantomWithFixedBottom(const std::string& name, double resolution, double slab) {
  Organ o;
  o.source = "phantom:" + name;
  o.surface = makePhantom(name, resolution);
  o.material = Material{5500, 0.3, 1000};
  const Box b = boundingBox(o.surface.V);
  Box fixed;
  fixed.lo = b.lo - Vec3::Constant(0.01);
  fixed.hi = Vec3(b.hi.x() + 0.01, b.hi.y() + 0.01, b.lo.z() + slab * b.size().z());
  o.fixed.boxes.push_back(fixed);
  return o;
}

/// The liver-sized ellipsoid surface (meshes.h) as an organ of the default material.
inline Organ liverSizedOrgan() {
  Organ o;
  o.source = "bench:liver-sized ellipsoid";
  o.surface = liverSizedSurface();
  return o;
}

/// One step of dt under gravity with a grasp holding the 5 vertices of `o` nearest (0, 0, 4 cm)
/// where they are at rest.
inline StepInput heldTopInput(const Organ& o, Real dt) {
  StepInput in;
  in.dt = dt;
  in.gravity = Vec3(0, 0, -9.81);
  GraspInput g;
  g.vertices = nearestVertices(o.surface.V, Vec3(0, 0, 0.04), 5);
  g.targets.resize(static_cast<Eigen::Index>(g.vertices.size()), 3);
  for (size_t k = 0; k < g.vertices.size(); ++k) g.targets.row(k) = o.surface.V.row(g.vertices[k]);
  in.grasps.push_back(g);
  return in;
}

}  // namespace deform::testing
