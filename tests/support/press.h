// A press shared by the volume-network tests of pbd and massspring (`network = volume`): the
// 0.1 m cube phantom (E = 5.5 kPa, nu = 0.3, rho = 1000), its bottom face fixed, its top face
// pushed down by a traction of total force F spread by vertex area. A solid of that material
// drops by about F L / (E A) (uniaxial stress; the fixed bottom stiffens it by a few percent);
// a shell or membrane of the surface alone does not behave like that.
#pragma once

#include <deform/geometry/phantom.h>
#include <deform/sdk/error.h>
#include <deform/sdk/mesh.h>
#include <deform/sdk/model.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <limits>
#include <string>
#include <vector>

namespace deform::testing {

struct CubePress {
  Organ organ;
  std::vector<int> top;          ///< the top face's surface vertices
  std::vector<PointLoad> loads;  ///< the traction as nodal forces, one load per top vertex
  Real expectedDrop = 0;         ///< m, F L / (E A)
};

inline CubePress cubePress(Real force, Real resolution = 0.5) {
  CubePress p;
  Organ& o = p.organ;
  o.source = "phantom:cube";
  o.surface = makePhantom("cube", resolution);
  o.material.young = 5500;
  o.material.poisson = 0.3;
  o.material.density = 1000;
  const Box b = boundingBox(o.surface.V);
  const Real side = b.size().z(), eps = 1e-6 * side;
  o.fixed.boxes.push_back(
      {b.lo - Vec3::Constant(eps), Vec3(b.hi.x(), b.hi.y(), b.lo.z()) + Vec3::Constant(eps)});
  std::vector<Real> area(o.surface.numVertices(), 0.0);
  Real total = 0;
  for (Eigen::Index f = 0; f < o.surface.F.rows(); ++f) {
    bool onTop = true;
    for (int k = 0; k < 3; ++k) onTop = onTop && o.surface.V(o.surface.F(f, k), 2) > b.hi.z() - eps;
    if (!onTop) continue;
    const Vec3 a = o.surface.V.row(o.surface.F(f, 0)), c = o.surface.V.row(o.surface.F(f, 1)),
               d = o.surface.V.row(o.surface.F(f, 2));
    const Real third = 0.5 * (c - a).cross(d - a).norm() / 3;
    for (int k = 0; k < 3; ++k) area[o.surface.F(f, k)] += third;
    total += 3 * third;
  }
  for (int v = 0; v < o.surface.numVertices(); ++v)
    if (area[v] > 0) {
      p.top.push_back(v);
      p.loads.push_back(PointLoad::onVertex(v, Vec3(0, 0, -force * area[v] / total)));
    }
  p.expectedDrop = force * side / (o.material.young * total);
  return p;
}

/// Steps `model` (initialised on p.organ) `steps` times under the press at dt = 1 ms and returns
/// the mean downward displacement of the top vertices (m); NaN when a step did not return Ok.
inline Real pressedDrop(Model& model, const CubePress& p, int steps) {
  StepInput in;
  in.dt = 1e-3;
  in.loads = p.loads;
  for (int s = 0; s < steps; ++s)
    if (model.step(in) != StepStatus::Ok) return std::numeric_limits<Real>::quiet_NaN();
  Real sum = 0;
  for (int v : p.top) sum += p.organ.surface.V(v, 2) - model.surface()(v, 2);
  return sum / static_cast<Real>(p.top.size());
}

/// The volume network's press and markers, for `model` initialised on p.organ with the network's
/// tets: its surface is the input surface at rest; markers through the tets are at rest where
/// bound; pressed, the centre drops about half as far as the top (the bottom is fixed) and the
/// lateral ones stay at their height within the drop; the top drops as a solid does (within 25%
/// of F L / (E A)) without an inverted tet.
inline void expectPressedLikeASolidWithMarkers(Model& model, const CubePress& press,
                                               const char* label) {
  const MatX3 rest = press.organ.surface.V;
  EXPECT_EQ((model.surface() - rest).cwiseAbs().maxCoeff(), 0.0);
  MatX3 markers(2, 3);
  markers << 0, 0, 0, 0.02, -0.02, 0.0;
  model.bindMarkers(markers);
  EXPECT_LT((model.markers() - markers).cwiseAbs().maxCoeff(), 1e-12);
  const Real drop = pressedDrop(model, press, 1000);
  const MatX3 moved = model.markers();
  EXPECT_NEAR(markers(0, 2) - moved(0, 2), 0.5 * drop, 0.2 * drop);
  EXPECT_NEAR(markers(1, 2) - moved(1, 2), 0.5 * drop, 0.2 * drop);
  std::printf("%s: top drops %.3f mm, F L / (E A) = %.3f mm\n", label, 1e3 * drop,
              1e3 * press.expectedDrop);
  EXPECT_NEAR(drop, press.expectedDrop, 0.25 * press.expectedDrop);
  EXPECT_EQ(model.numericCounters().at("inverted_tets"), 0);
}

/// A surface network has no interior: binding a marker is an UnsupportedError that says so.
inline void expectNoMarkersOnASurfaceNetwork(Model& model) {
  try {
    model.bindMarkers(MatX3::Zero(1, 3));
    ADD_FAILURE() << "no error";
  } catch (const UnsupportedError& e) {
    EXPECT_NE(std::string(e.what()).find("surface network"), std::string::npos) << e.what();
  }
}

}  // namespace deform::testing
