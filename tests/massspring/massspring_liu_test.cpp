// The local/global integrator (Liu et al. 2013, massspring_liu.cpp): its iterations converge to
// the implicit Euler step (the residual of M (x - x_n - h v_n) / h^2 = f(x) + f_ext vanishes),
// with and without the Chebyshev acceleration; the default 5 accelerated, warm-started
// iterations land at least as close to that step as 10 plain ones; and it is stable at
// dt = 1 ms on the default liver phantom under a grasp-and-lift.
#include "../support/meshes.h"
#include "massspring_model.h"

#include <deform/geometry/phantom.h>

#include <gtest/gtest.h>

#include <cstdio>

namespace deform::massspring {
namespace {

// Max over free nodes of |M (x - x_n - h v_n) / h^2 - f_spring(x) - f_ext| (N).
Real implicitEulerResidual(MassSpringModel& m, const MatX3& xn, const MatX3& vn, Real h,
                           const PointLoad& load) {
  MatX3 f;
  const MatX3 x = m.nodes();
  m.springForces(x, MatX3::Zero(x.rows(), 3), f);  // no dashpots in this test (damping 0)
  f.row(load.surfaceVertex) += load.force.transpose();
  Real worst = 0;
  for (Eigen::Index i = 0; i < x.rows(); ++i) {
    if (m.velocities().row(i).isZero() && (x.row(i) - xn.row(i)).isZero()) continue;  // fixed
    const Vec3 r =
        (m.masses()[i] * (x.row(i) - xn.row(i) - h * vn.row(i)) / (h * h) - f.row(i)).transpose();
    worst = std::max(worst, r.norm());
  }
  return worst;
}

// The small ellipsoid held at its base, a 2 N load on vertex 0, two local/global steps of h
// (5 ms: large enough for the springs' nonlinearity to matter), no damping: the implicit Euler
// residual of the second step (from a moving state) and how far it moved the nodes.
struct SecondStep {
  Real residual = 0, moved = 0, force = 0;
};
SecondStep secondLocalGlobalStep(MassSpringConfig cfg) {
  Organ o;
  o.source = "test:ellipsoid";
  o.surface = testing::uvEllipsoid(5, 8, 0.04, 0.03, 0.02);
  o.fixed.boxes.push_back({Vec3(-1, -1, -1), Vec3(1, 1, -0.015)});
  cfg.integrator = Integrator::LocalGlobal;
  cfg.dampingRatio = 0.0;
  cfg.massDamping = 0.0;
  const Real h = 5e-3;
  const PointLoad load = PointLoad::onVertex(0, Vec3(0.3, 0.1, -2.0));
  StepInput in;
  in.dt = h;
  in.loads.push_back(load);
  MassSpringModel m;
  m.init(o, cfg);
  SecondStep out;
  out.force = load.force.norm();
  EXPECT_EQ(m.step(in), StepStatus::Ok);  // first step from rest
  const MatX3 xn = m.nodes(), vn = m.velocities();
  EXPECT_EQ(m.step(in), StepStatus::Ok);  // the step checked: from a moving state
  out.moved = (m.nodes() - xn).norm();
  out.residual = implicitEulerResidual(m, xn, vn, h, load);
  return out;
}

TEST(MassSpringLocalGlobal, ConvergesToTheImplicitEulerStep) {
  MassSpringConfig cfg;
  Real residual[2] = {0, 0};
  int k = 0;
  for (int iterations : {2, 400}) {
    cfg.localGlobalIterations = iterations;
    const SecondStep s = secondLocalGlobalStep(cfg);
    EXPECT_GT(s.moved, 1e-4);
    residual[k++] = s.residual / s.force;
  }
  EXPECT_GT(residual[0], 1e-4);  // two iterations are not the implicit Euler step ...
  EXPECT_LT(residual[1], 1e-9);  // ... many converge to it
}

TEST(MassSpringLocalGlobal, PlainIterationsConvergeToTheImplicitEulerStepToo) {
  MassSpringConfig cfg;
  cfg.localGlobalAcceleration = LocalGlobalAcceleration::None;
  cfg.localGlobalWarmStart = false;
  cfg.localGlobalIterations = 2000;
  const SecondStep s = secondLocalGlobalStep(cfg);
  EXPECT_LT(s.residual, 1e-9 * s.force);
}

// One step from a state of a grasp-and-lift (a 2.6k-spring ellipsoid held at its base, 8 nodes
// lifted at 50 mm/s, dt = 1 ms): distance of the result to the converged implicit Euler step
// (300 plain iterations) after the default 5 Chebyshev iterations with warm start, and after 10
// and 5 plain ones.
TEST(MassSpringLocalGlobal, FiveAcceleratedIterationsAreCloserThanTenPlainOnes) {
  Organ o;
  o.source = "test:ellipsoid";
  o.surface = testing::uvEllipsoid(16, 24, 0.05, 0.04, 0.03);
  o.fixed.boxes.push_back({Vec3(-1, -1, -1), Vec3(1, 1, -0.02)});
  GraspInput g;
  g.vertices = nearestVertices(o.surface.V, Vec3(0.0, 0.0, 0.03), 8);
  g.targets.resize(static_cast<Eigen::Index>(g.vertices.size()), 3);
  StepInput in;
  in.dt = 1e-3;
  const auto lift = [&](int step) {
    for (size_t k = 0; k < g.vertices.size(); ++k)
      g.targets.row(k) = o.surface.V.row(g.vertices[k]) + Vec3(0, 0, 5e-5 * (step + 1)).transpose();
    in.grasps = {g};
  };
  const auto config = [](int iterations, LocalGlobalAcceleration acceleration, bool warm) {
    MassSpringConfig c;
    c.integrator = Integrator::LocalGlobal;
    c.localGlobalIterations = iterations;
    c.localGlobalAcceleration = acceleration;
    c.localGlobalWarmStart = warm;
    return c;
  };
  const auto None = LocalGlobalAcceleration::None;
  // The converged trajectory, to the step checked (n) and the one before it.
  MassSpringModel ref;
  ref.init(o, config(300, None, false));
  const int n = 20;
  MatX3 xPrev, vPrev;
  for (int s = 0; s < n; ++s) {
    if (s == n - 1) xPrev = ref.nodes(), vPrev = ref.velocities();
    lift(s);
    ASSERT_EQ(ref.step(in), StepStatus::Ok);
  }
  const MatX3 xn = ref.nodes(), vn = ref.velocities();
  lift(n);
  ASSERT_EQ(ref.step(in), StepStatus::Ok);
  const auto distance = [&](MassSpringConfig c) {
    MassSpringModel m;
    m.init(o, c);
    lift(n - 1);
    m.setState(xPrev, vPrev);
    EXPECT_EQ(m.step(in), StepStatus::Ok);  // the warm start's previous step
    lift(n);
    m.setState(xn, vn);
    EXPECT_EQ(m.step(in), StepStatus::Ok);
    if (c.localGlobalAcceleration == LocalGlobalAcceleration::Chebyshev) {
      EXPECT_GT(m.localGlobalRho(), 0.1);
      EXPECT_LT(m.localGlobalRho(), 1.0);
    }
    return (m.nodes() - ref.nodes()).rowwise().norm().maxCoeff();
  };
  const Real stepSize = (ref.nodes() - xn).rowwise().norm().maxCoeff();
  const Real plain10 = distance(config(10, None, false));
  const Real plain5 = distance(config(5, None, false));
  const Real accelerated = distance(MassSpringConfig{.integrator = Integrator::LocalGlobal});
  std::printf(
      "step %.3e m; distance to implicit Euler: 5 accelerated %.3e m, 10 plain %.3e m, "
      "5 plain %.3e m\n",
      stepSize, accelerated, plain10, plain5);
  EXPECT_GT(plain10, 1e-4 * stepSize);  // 10 plain iterations are not converged here ...
  EXPECT_GT(plain5, plain10);
  EXPECT_LE(accelerated, plain10);  // ... and 5 accelerated ones are at least as close
}

TEST(MassSpringLocalGlobal, StableAtOneMillisecondOnTheLiverPhantom) {
  Organ o;
  o.source = "phantom:liver";
  o.surface = makePhantom("liver");
  // The default scene's support (scenes/liver_grasp_lift.json).
  o.fixed.boxes.push_back({Vec3(-0.11, -0.08, -0.05), Vec3(0.11, -0.035, 0.05)});
  o.fixed.boxes.push_back({Vec3(-0.11, -0.08, -0.05), Vec3(0.11, 0.03, -0.032)});
  MassSpringConfig cfg;
  cfg.integrator = Integrator::LocalGlobal;
  MassSpringModel m;
  m.init(o, cfg);
  GraspInput g;
  g.vertices = nearestVertices(o.surface.V, Vec3(-0.0235, 0.0744, -0.0232), 8);
  g.targets.resize(static_cast<Eigen::Index>(g.vertices.size()), 3);
  StepInput in;
  in.dt = 1e-3;
  const int steps = 80;
  for (int s = 0; s < steps; ++s) {
    const Real lift = 0.01 * std::min(1.0, (s + 1) / 50.0);  // 10 mm in 50 ms, then hold
    for (size_t k = 0; k < g.vertices.size(); ++k)
      g.targets.row(k) = o.surface.V.row(g.vertices[k]) + Vec3(0, 0, lift).transpose();
    in.grasps = {g};
    ASSERT_EQ(m.step(in), StepStatus::Ok) << "step " << s;
  }
  const Real maxDisp = (m.nodes() - o.surface.V).rowwise().norm().maxCoeff();
  // The grasp moved 10 mm; the lobe follows with some inertia, nothing runs away.
  EXPECT_GT(maxDisp, 0.0099);
  EXPECT_LT(maxDisp, 0.02);
  EXPECT_EQ(m.numericCounters().at("factorisations"), 1);  // one grasp set: one factorisation
}

}  // namespace
}  // namespace deform::massspring
