// Fixtures and checks shared by the tests of the models whose nodes are the organ's surface
// vertices or tet nodes (pbd, massspring): the test organs, a step input, and the checks both
// models pass (a scripted run, grasped nodes on their targets, the grasp reaction of a hanging
// organ, no markers on a surface network). Include as "../support/network_model.h".
#pragma once

#include "grasp.h"
#include "meshes.h"
#include "press.h"

#include <deform/sdk/cache.h>
#include <deform/sdk/mesh.h>
#include <deform/sdk/model.h>
#include <deform/sdk/params.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <vector>

namespace deform::testing {

/// A closed ellipsoid surface (semi-axes 5, 4, 3 cm) of the given Young's modulus, nu = 0.3,
/// rho = 1000.
inline Organ ellipsoidOrgan(Real young = 5500.0) {
  Organ o;
  o.source = "test:ellipsoid";
  o.surface = uvEllipsoid(10, 16, 0.05, 0.04, 0.03);
  o.material.young = young;
  o.material.poisson = 0.3;
  o.material.density = 1000.0;
  return o;
}

/// A 4 x 3 x 2 cm tet box (4 x 3 x 2 cells) and its boundary, with the default material.
inline Organ tetBoxOrgan() {
  Organ o;
  o.source = "test:tetbox";
  o.volume = tetBox(4, 3, 2, 0.04, 0.03, 0.02);
  o.surface = tetBoundary(*o.volume);
  return o;
}

inline StepInput stepInput(Real dt, Vec3 gravity = Vec3::Zero()) {
  StepInput in;
  in.dt = dt;
  in.gravity = gravity;
  return in;
}

inline Real maxDistance(const MatX3& a, const MatX3& b) {
  return (a - b).rowwise().norm().maxCoeff();
}

/// A scripted run of `steps` steps of dt with gravity, a grasp lifting the top vertex by `rise`
/// per step and a 0.5 N point load on the side; the surface after each step.
inline std::vector<MatX3> scriptedRun(Model& m, const Organ& o, int steps, Real dt, Real rise) {
  std::vector<MatX3> out;
  const int top = nearestVertex(o.surface.V, Vec3(0, 0, 0.03));
  const int side = nearestVertex(o.surface.V, Vec3(0.05, 0, 0));
  for (int s = 0; s < steps; ++s) {
    StepInput in = stepInput(dt, Vec3(0, 0, -9.81));
    GraspInput g;
    g.vertices = {top};
    g.targets = o.surface.V.row(top) + Eigen::RowVector3d(0, 0, rise * (s + 1));
    in.grasps.push_back(g);
    in.loads.push_back(PointLoad::onVertex(side, Vec3(0.5, 0, 0)));
    EXPECT_EQ(m.step(in), StepStatus::Ok);
    out.push_back(m.surface());
  }
  return out;
}

/// Grasps `nodes` with targets moving by step s * (vx, 0, vz) from rest for `steps` steps of dt
/// under gravity; every grasped node is exactly on its target after every step.
inline void expectGraspedNodesFollow(Model& m, const Organ& o, const std::vector<int>& nodes,
                                     int steps, Real dt, Real vx, Real vz) {
  const Eigen::Index n = Eigen::Index(nodes.size());
  for (int s = 0; s < steps; ++s) {
    StepInput in = stepInput(dt, Vec3(0, 0, -9.81));
    GraspInput g;
    g.vertices = nodes;
    g.targets.resize(n, 3);
    for (Eigen::Index k = 0; k < n; ++k)
      g.targets.row(k) = o.surface.V.row(nodes[k]) + Eigen::RowVector3d(vx * s, 0, vz * s);
    in.grasps.push_back(g);
    ASSERT_EQ(m.step(in), StepStatus::Ok);
    for (Eigen::Index k = 0; k < n; ++k) EXPECT_TRUE(m.nodes().row(nodes[k]) == g.targets.row(k));
  }
}

/// An organ hanging from a grasp on the 7 vertices nearest its top, `steps` steps of dt: once
/// still, the tissue pulls the grasp down with the weight of every node the grasp does not hold
/// (momentum balance of the free nodes), within `tolerance` of it. ModelT has masses().
template <class ModelT>
void expectGraspReactionBalancesTheWeight(ModelT& m, const Organ& o, int steps, Real dt,
                                          Real tolerance) {
  const std::vector<int> held = nearestVertices(o.surface.V, Vec3(0, 0, 0.03), 7);
  Real heldMass = 0;
  for (int i : held) heldMass += m.masses()[i];
  const Vec3 g(0, 0, -9.81);
  for (int s = 0; s < steps; ++s) {
    StepInput in = stepInput(dt, g);
    in.grasps.push_back(graspOf(held, o.surface.V));
    ASSERT_EQ(m.step(in), StepStatus::Ok);
  }
  const std::vector<Vec3> f = m.graspForces();
  ASSERT_EQ(f.size(), 1u);
  const Vec3 weight = (m.masses().sum() - heldMass) * g;
  EXPECT_LT((f[0] - weight).norm(), tolerance * weight.norm()) << f[0].transpose();
}

/// init() through the parameter layer, as the runner calls it (dt 1 ms, no gravity, no cache).
inline void initWithParams(Model& m, const Organ& o, const ParamValues& p) {
  Cache cache{std::filesystem::path()};
  m.init(ModelSetup{o, p, cache, 1e-3, Vec3::Zero()});
}

/// A surface network (the model at its default parameters, specs) has no interior: it refuses
/// markers, naming why (on the pressed cube).
inline void expectNoMarkersAtDefaults(Model& m, const std::vector<ParamSpec>& specs) {
  initWithParams(m, cubePress(0.5).organ, ParamValues::defaults(specs));
  expectNoMarkersOnASurfaceNetwork(m);
}

}  // namespace deform::testing
