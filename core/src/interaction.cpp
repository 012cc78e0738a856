// Interaction resolved identically for every model: keyframed tools, grasp attachment and
// release, point forces and pin-head springs, and the fixed region in terms of a model's nodes.
#include <deform/interaction.h>

#include <algorithm>
#include <cmath>

namespace deform {

namespace {

/// Keyframe times are compared with times computed as k * dt; this slack (relative to dt) makes
/// a keyframe at t = 0.1 count as reached at step 100 even when 100 * 0.001 rounds below 0.1.
constexpr Real kTimeSlack = 1e-6;

}  // namespace

Vec3 toolPosition(const std::vector<KeyFrame>& trajectory, Real t) {
  if (trajectory.empty()) return Vec3::Zero();
  if (t <= trajectory.front().t) return trajectory.front().pos;
  if (t >= trajectory.back().t) return trajectory.back().pos;
  const auto next = std::upper_bound(trajectory.begin(), trajectory.end(), t,
                                     [](Real x, const KeyFrame& k) { return x < k.t; });
  const KeyFrame& b = *next;
  const KeyFrame& a = *(next - 1);
  const Real s = (t - a.t) / (b.t - a.t);
  return (1 - s) * a.pos + s * b.pos;
}

bool jawClosed(const std::vector<KeyFrame>& trajectory, Real t) {
  bool closed = false;
  for (const KeyFrame& k : trajectory) {
    if (k.t > t) break;
    closed = k.jawClosed;
  }
  return closed;
}

Interaction::Interaction(const Scene& scene, const SurfaceMesh& restSurface)
    : m_scene(scene), m_rest(restSurface), m_attach(scene.tools.size()) {
  for (const LoadSpec& load : scene.loads)
    m_loadVertices.push_back(nearestVertex(m_rest.V, load.at));
}

void Interaction::reset() {
  m_attach.assign(m_scene.tools.size(), Attachment{});
  m_emptyGrasps.clear();
}

StepInput Interaction::prepare(Real t, Real dt, const Model& model) {
  StepInput in;
  in.time = t;
  in.dt = dt;
  in.gravity = m_scene.gravity;
  const Real slack = kTimeSlack * dt;
  const MatX3& nodes = model.nodes();

  for (size_t i = 0; i < m_scene.tools.size(); ++i) {
    const ToolSpec& tool = m_scene.tools[i];
    const Real r2 = tool.radius * tool.radius;
    if (tool.type == ToolType::Grasper) {
      Attachment& a = m_attach[i];
      const bool closed = jawClosed(tool.trajectory, t + slack);
      if (closed && !a.active) {
        a = Attachment{};
        a.active = true;
        a.toolAtClose = toolPosition(tool.trajectory, t);
        for (Eigen::Index n = 0; n < nodes.rows(); ++n) {
          if ((nodes.row(n).transpose() - a.toolAtClose).squaredNorm() <= r2)
            a.nodes.push_back(static_cast<int>(n));
        }
        a.restPositions.resize(static_cast<Eigen::Index>(a.nodes.size()), 3);
        for (size_t k = 0; k < a.nodes.size(); ++k) a.restPositions.row(k) = nodes.row(a.nodes[k]);
        if (a.nodes.empty() &&
            std::find(m_emptyGrasps.begin(), m_emptyGrasps.end(), int(i)) == m_emptyGrasps.end())
          m_emptyGrasps.push_back(static_cast<int>(i));
      } else if (!closed && a.active) {
        a = Attachment{};
      }
      if (a.active && !a.nodes.empty()) {
        GraspInput g;
        g.tool = static_cast<int>(i);
        g.nodes = a.nodes;
        const Vec3 shift = toolPosition(tool.trajectory, t + dt) - a.toolAtClose;
        g.targets = a.restPositions.rowwise() + shift.transpose();
        in.grasps.push_back(std::move(g));
      }
    } else {
      // A probe is a rigid sphere: nodes it would contain at the end of the step are pushed
      // radially onto its surface, through the same attachment input as a grasp.
      const Vec3 c = toolPosition(tool.trajectory, t + dt);
      Vec3 motion = c - toolPosition(tool.trajectory, t);
      if (motion.norm() <= 0) motion = Vec3(0, 0, -1);
      GraspInput g;
      g.tool = static_cast<int>(i);
      std::vector<Vec3> targets;
      for (Eigen::Index n = 0; n < nodes.rows(); ++n) {
        const Vec3 d = nodes.row(n).transpose() - c;
        if (d.squaredNorm() >= r2) continue;
        const Real len = d.norm();
        const Vec3 dir = len > tol::kDegenerateLength ? Vec3(d / len) : Vec3(motion.normalized());
        g.nodes.push_back(static_cast<int>(n));
        targets.push_back(c + tool.radius * dir);
      }
      if (!g.nodes.empty()) {
        g.targets.resize(static_cast<Eigen::Index>(targets.size()), 3);
        for (size_t k = 0; k < targets.size(); ++k) g.targets.row(k) = targets[k].transpose();
        in.grasps.push_back(std::move(g));
      }
    }
  }

  for (size_t l = 0; l < m_scene.loads.size(); ++l) {
    const LoadSpec& load = m_scene.loads[l];
    if (t + slack < load.start || t + slack >= load.end) continue;
    PointLoad p;
    p.surfaceVertex = m_loadVertices[l];
    if (load.type == LoadType::PointForce) {
      p.force = load.force;
    } else {
      // Pin head: a spring from the rest point to the pin, evaluated at the end of the step like
      // the grasp targets.
      p.force = load.stiffness * (toolPosition(load.path, t + dt) - load.at);
    }
    in.loads.push_back(p);
  }
  return in;
}

Vec3 Interaction::focusPoint() const {
  if (!m_loadVertices.empty() && m_loadVertices.front() >= 0)
    return m_rest.V.row(m_loadVertices.front()).transpose();
  for (const ToolSpec& tool : m_scene.tools) {
    if (tool.type != ToolType::Grasper) continue;
    for (const KeyFrame& k : tool.trajectory)
      if (k.jawClosed) return k.pos;
  }
  for (const ToolSpec& tool : m_scene.tools)
    if (tool.type == ToolType::Probe) return tool.trajectory.back().pos;
  return boundingBox(m_rest.V).center();
}

std::vector<int> fixedNodeIndices(const MatX3& nodes, const FixedRegion& region,
                                  const SurfaceMesh& restSurface) {
  std::vector<int> out;
  for (Eigen::Index n = 0; n < nodes.rows(); ++n) {
    const Vec3 p = nodes.row(n).transpose();
    for (const Box& b : region.boxes) {
      if (b.contains(p)) {
        out.push_back(static_cast<int>(n));
        break;
      }
    }
  }
  for (int v : region.surfaceVertices) {
    if (v < 0 || v >= restSurface.numVertices()) continue;
    const int n = nearestVertex(nodes, restSurface.V.row(v).transpose());
    if (n >= 0) out.push_back(n);
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

}  // namespace deform
