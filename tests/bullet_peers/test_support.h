// Shared helpers of the Bullet peer tests: a small organ with its bottom slab pinned, the
// standard inputs (gravity, a grasp lifting the top), and a probe pressed into the top through
// the shared contact world.
#pragma once

#include <deform/geometry/phantom.h>
#include <deform/sdk/contact.h>
#include <deform/sdk/model.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

namespace deform::testing {

/// Indices of the rows of V whose z is within `fraction` of the height from the bottom.
inline std::vector<int> bottomSlab(const MatX3& V, Real fraction) {
  const Box b = boundingBox(V);
  std::vector<int> out;
  for (Eigen::Index i = 0; i < V.rows(); ++i)
    if (V(i, 2) <= b.lo.z() + fraction * b.size().z()) out.push_back(int(i));
  return out;
}

/// A grasp of the k nodes nearest to the top centre, moved by `lift` (m) along z.
inline GraspInput topGrasp(const MatX3& nodes, int k, Real lift) {
  const Box b = boundingBox(nodes);
  GraspInput g;
  g.vertices = nearestVertices(nodes, Vec3(b.center().x(), b.center().y(), b.hi.z()), k);
  std::sort(g.vertices.begin(), g.vertices.end());
  g.targets.resize(Eigen::Index(g.vertices.size()), 3);
  for (size_t i = 0; i < g.vertices.size(); ++i)
    g.targets.row(Eigen::Index(i)) = nodes.row(g.vertices[i]) + Vec3(0, 0, lift).transpose();
  return g;
}

inline Real maxDisplacement(const MatX3& x, const MatX3& rest) {
  return (x - rest).rowwise().norm().maxCoeff();
}

/// What pressProbe() saw.
struct ProbeRun {
  Real worst = 1e9;         ///< m, least |x - c| - r over the movable nodes after any step
  Real topDrop = 0;         ///< m, how far the probed (highest) node went down
  Real minReactionZ = 1e9;  ///< N, least reaction on the probe along z over contact steps
  Real lastReactionZ = 0;   ///< N, the reaction on the probe along z in the last step
  int contactSteps = 0;     ///< steps with a reaction on the probe
  int farNodesMoved = 0;    ///< nodes never within 2 r of the probe that moved > 1e-5 m
  bool allOk = true;        ///< every step returned Ok
};

/// A spherical probe of radius r comes down from just above the highest rest node and presses
/// `depth` into it over `steps` steps of dt, then holds there for `hold` more steps; no gravity.
/// fixed: the model's pinned nodes (they cannot be pushed).
inline ProbeRun pressProbe(Model& m, const MatX3& rest, const std::vector<int>& fixed, Real r,
                           Real depth, int steps, int hold, Real dt) {
  Eigen::Index top = 0;
  rest.col(2).maxCoeff(&top);
  const Vec3 p = rest.row(top).transpose();
  ContactParams cp;
  cp.thickness = 1e-4;
  ContactWorld world(cp);
  const int probe = world.addBody(probeShape(r, 0, r, Vec3::UnitZ()));
  std::vector<char> near(size_t(rest.rows()), 0);
  ProbeRun out;
  for (int k = 1; k <= steps + hold; ++k) {
    const Real s = std::min(1.0, Real(k) / steps);
    const Vec3 c = p + Vec3(0, 0, r + 1e-3 - s * (1e-3 + depth));
    world.setPose(probe, c);
    world.clearReactions();
    StepInput in;
    in.time = (k - 1) * dt;
    in.dt = dt;
    in.contact = &world;
    out.allOk = out.allOk && m.step(in) == StepStatus::Ok;
    const MatX3& x = m.nodes();
    for (Eigen::Index i = 0; i < x.rows(); ++i) {
      const Real d = (x.row(i).transpose() - c).norm();
      if (d < 2 * r) near[size_t(i)] = 1;
      if (std::binary_search(fixed.begin(), fixed.end(), int(i))) continue;
      out.worst = std::min(out.worst, d - r);
    }
    const Vec3 f = world.reactionForce(probe);
    if (f.squaredNorm() > 0) {
      ++out.contactSteps;
      out.minReactionZ = std::min(out.minReactionZ, f.z());
    }
    out.lastReactionZ = f.z();
  }
  out.topDrop = p.z() - m.nodes()(top, 2);
  for (Eigen::Index i = 0; i < rest.rows(); ++i)
    if (!near[size_t(i)] && (m.nodes().row(i) - rest.row(i)).norm() > 1e-5) ++out.farNodesMoved;
  return out;
}

/// One step of dt under gravity (-9.81 m/s^2 along z).
inline StepInput gravityInput(Real dt) {
  StepInput in;
  in.dt = dt;
  in.gravity = Vec3(0, 0, -9.81);
  return in;
}

/// The positions a check reads: Model::nodes or Model::surface.
using Positions = const MatX3& (Model::*)() const;

/// A 0.5 N upward force on the vertex of `pickFrom` nearest the top centre of `box`, 50 steps of
/// dt: the vertex rises more than 0.1 mm above its row in `rest`.
inline void expectPointForceLiftsItsVertex(Model& m, const Box& box, const MatX3& pickFrom,
                                           const MatX3& rest, Real dt) {
  StepInput in;
  in.dt = dt;
  PointLoad l;
  l.surfaceVertex = nearestVertex(pickFrom, Vec3(box.center().x(), box.center().y(), box.hi.z()));
  l.force = Vec3(0, 0, 0.5);
  in.loads.push_back(PointLoad::onVertex(l.surfaceVertex, l.force));
  for (int s = 0; s < 50; ++s) ASSERT_EQ(m.step(in), StepStatus::Ok);
  EXPECT_GT(m.surface()(l.surfaceVertex, 2) - rest(l.surfaceVertex, 2), 1e-4);
}

/// A grasp of the 6 top nodes of `rest` raised 0.2 mm a step of dt under gravity for 100 steps:
/// the grasped nodes on their targets exactly at every step, and the 20 rest vertices nearest
/// the first of them dragged up 5 mm on average (their rows of `positions`). Released, that node
/// is free again (its mass back): within releaseSteps it falls more than 0.1 mm.
inline void expectGraspFollowedThenReleased(Model& m, const MatX3& rest, Real dt,
                                            Positions positions, int releaseSteps) {
  StepInput in = gravityInput(dt);
  in.grasps.push_back(topGrasp(rest, 6, 0.0));
  const MatX3 start = in.grasps[0].targets;
  for (int s = 1; s <= 100; ++s) {
    in.grasps[0].targets = start;
    in.grasps[0].targets.col(2).array() += 2e-4 * s;  // 0.2 m/s up at 1 ms steps
    ASSERT_EQ(m.step(in), StepStatus::Ok);
    for (size_t k = 0; k < in.grasps[0].vertices.size(); ++k)
      ASSERT_EQ(m.nodes().row(in.grasps[0].vertices[k]), in.grasps[0].targets.row(Eigen::Index(k)));
  }
  const std::vector<int> near = nearestVertices(rest, rest.row(in.grasps[0].vertices[0]), 20);
  Real rise = 0;
  for (int v : near) rise += (m.*positions)()(v, 2) - rest(v, 2);
  EXPECT_GT(rise / near.size(), 0.005);
  const int held = in.grasps[0].vertices[0];
  const Real zHeld = m.nodes()(held, 2);
  in.grasps.clear();
  for (int s = 0; s < releaseSteps; ++s) ASSERT_EQ(m.step(in), StepStatus::Ok);
  EXPECT_LT(m.nodes()(held, 2), zHeld - 1e-4);
}

/// A run of `steps` steps of dt under gravity with a grasp of the 5 top nodes of `rest` sliding
/// along y until step `release`; reset() returns to `rest` and the same run again gives the same
/// positions bit for bit, more than 0.1 mm from rest.
inline void expectResetReproducesARun(Model& m, const MatX3& rest, int steps, int release, Real dt,
                                      Positions positions) {
  auto run = [&] {
    StepInput in = gravityInput(dt);
    in.grasps.push_back(topGrasp(rest, 5, 0.0));
    for (int s = 0; s < steps; ++s) {
      if (s == release) in.grasps.clear();
      if (!in.grasps.empty()) in.grasps[0].targets.col(1).array() += 1e-4;
      EXPECT_EQ(m.step(in), StepStatus::Ok);
    }
    return MatX3((m.*positions)());
  };
  const MatX3 a = run();
  m.reset();
  EXPECT_TRUE((m.*positions)() == rest);
  const MatX3 b = run();
  EXPECT_TRUE(a == b);
  EXPECT_GT(maxDisplacement(a, rest), 1e-4);
}

/// A grasp of the 8 top nodes of `rest` lifted by `lift` per step for `steps` steps of dt under
/// gravity: every step Ok, the positions finite.
inline void expectNoNanOverAGraspLift(Model& m, const MatX3& rest, int steps, Real lift, Real dt,
                                      Positions positions) {
  StepInput in = gravityInput(dt);
  in.grasps.push_back(topGrasp(rest, 8, 0.0));
  for (int s = 0; s < steps; ++s) {
    in.grasps[0].targets.col(2).array() += lift;
    ASSERT_EQ(m.step(in), StepStatus::Ok) << "step " << s;
    ASSERT_TRUE((m.*positions)().allFinite());
  }
}

/// pressProbe() with a 1 cm probe pressed 8 mm deep over 40 steps of dt and held 20, printed
/// under `label`: every step Ok, no movable node ends a step inside the probe, the top goes down
/// at least half the depth, 20 or more contact steps, the tissue pushes the probe up (with more
/// than minLastReaction N at the end) and nodes the probe never came near follow.
inline void expectAPressedProbeIsPushedBack(Model& m, const MatX3& rest,
                                            const std::vector<int>& fixed, Real dt,
                                            Real minLastReaction, const char* label) {
  const Real r = 0.01, depth = 0.008;
  const ProbeRun run = pressProbe(m, rest, fixed, r, depth, 40, 20, dt);
  std::printf(
      "%s probe: worst %.3g m, top drop %.3g m, reaction z min %.3g N, last %.3g N, %d far nodes "
      "moved, %d contact steps\n",
      label, run.worst, run.topDrop, run.minReactionZ, run.lastReactionZ, run.farNodesMoved,
      run.contactSteps);
  EXPECT_TRUE(run.allOk);
  EXPECT_GE(run.worst, -1e-9) << "a node ended a step inside the probe";
  EXPECT_GT(run.topDrop, 0.5 * depth);
  EXPECT_GE(run.contactSteps, 20);
  EXPECT_GT(run.minReactionZ, 0.0) << "the tissue must push the probe up";
  EXPECT_GT(run.lastReactionZ, minLastReaction);
  EXPECT_GT(run.farNodesMoved, 0);
}

}  // namespace deform::testing
