// Shared helpers of the Bullet peer tests: a small organ with its bottom slab pinned, the
// standard inputs (gravity, a grasp lifting the top), and a probe pressed into the top through
// the shared contact world.
#pragma once

#include <deform/geometry/phantom.h>
#include <deform/sdk/contact.h>
#include <deform/sdk/model.h>

#include <algorithm>
#include <cmath>
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

}  // namespace deform::testing
