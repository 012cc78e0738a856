// Interaction resolved identically for every model: keyframed tools, grasp attachment and
// release, point forces and pin-head springs, and the fixed region in terms of a model's nodes.
#include <deform/engine/interaction.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <map>

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
  for (const LoadSpec& load : scene.loads) {
    if (load.type == LoadType::Traction) {
      m_loadPatches.push_back(regionPatch(m_rest, load.region));
      m_loadVertices.push_back(m_loadPatches.back().vertices.empty()
                                   ? nearestVertex(m_rest.V, load.at)
                                   : m_loadPatches.back().vertices.front());
      continue;
    }
    m_loadVertices.push_back(nearestVertex(m_rest.V, load.at));
    m_loadPatches.push_back(pressurePatch(m_rest, m_loadVertices.back(), load.radius));
  }
  for (const PlateSpec& plate : scene.plates)
    m_plateVertices.push_back(plateSurfaceVertices(m_rest.V, plate.region));
  buildWorlds();
}

Interaction::~Interaction() = default;

void Interaction::reset() {
  m_attach.assign(m_scene.tools.size(), Attachment{});
  m_emptyGrasps.clear();
  m_forcelessGraspSteps = 0;
  buildWorlds();
}

namespace {

Mat3 sphereInertia(Real m, Real r) {
  return Mat3::Identity() * (0.4 * m * r * r);
}

Mat3 boxInertia(Real m, const Vec3& half) {
  const Vec3 s = 2.0 * half;
  return Vec3(m / 12.0 * (s.y() * s.y() + s.z() * s.z()),
              m / 12.0 * (s.x() * s.x() + s.z() * s.z()),
              m / 12.0 * (s.x() * s.x() + s.y() * s.y()))
      .asDiagonal();
}

/// A grasper's ODE body is its shaft, whose centre of mass is half a shaft above the jaws' hinge
/// (the tool position).
Vec3 grasperOffset(const ToolSpec& t) {
  return Vec3(0, 0, 0.5 * t.dynamics->shaftLength);
}

}  // namespace

void Interaction::buildWorlds() {
  m_contact.reset();
  m_dynamics.reset();
  const size_t nt = m_scene.tools.size(), no = m_scene.objects.size();
  m_toolContactBody.assign(nt, -1);
  m_toolDynBody.assign(nt, -1);
  m_objectContactBody.assign(no, -1);
  m_objectDynBody.assign(no, -1);
  m_toolPosBefore.assign(nt, Vec3::Zero());
  m_handForces.clear();
  if (m_scene.needsContact()) {
    m_contact = std::make_unique<ContactWorld>(m_scene.contact);
    for (size_t i = 0; i < nt; ++i) {
      const ToolSpec& t = m_scene.tools[i];
      if (t.type != ToolType::Probe) continue;
      m_toolContactBody[i] = m_contact->addBody(probeShape(
          t.radius, t.shaftLength, t.shaftRadius > 0 ? t.shaftRadius : t.radius, t.shaftAxis));
      m_contact->setPose(m_toolContactBody[i], toolPosition(t.trajectory, 0.0));
    }
    for (size_t j = 0; j < no; ++j) {
      m_objectContactBody[j] = m_contact->addBody(m_scene.objects[j].shape);
      m_contact->setPose(m_objectContactBody[j], m_scene.objects[j].pos);
    }
  }
  if (m_scene.needsDynamics()) {
    m_dynamics = std::make_unique<InstrumentWorld>(m_scene.gravity);
    for (size_t i = 0; i < nt; ++i) {
      const ToolSpec& t = m_scene.tools[i];
      if (!t.dynamics) continue;
      const Vec3 p0 = toolPosition(t.trajectory, 0.0);
      if (t.type == ToolType::Grasper) {
        m_toolDynBody[i] = m_dynamics->addGrasper(t.dynamics->mass, t.dynamics->shaftLength,
                                                  t.dynamics->jawLength, p0, t.dynamics->coupling);
      } else {
        m_toolDynBody[i] =
            m_dynamics->addBody(t.dynamics->mass, sphereInertia(t.dynamics->mass, t.radius), p0,
                                false, true, t.dynamics->coupling, true);
      }
      m_toolPosBefore[i] = p0;
    }
    for (size_t j = 0; j < no; ++j) {
      const ObjectSpec& o = m_scene.objects[j];
      const ShapePrimitive& p = o.shape.parts.front();
      const Mat3 I = p.kind == ShapePrimitive::Kind::Box ? boxInertia(o.mass, p.halfExtents)
                                                         : sphereInertia(o.mass, p.radius);
      m_objectDynBody[j] =
          m_dynamics->addBody(o.mass, I, o.pos, true, !o.trajectory.empty(), o.coupling);
      // Objects collide with each other and with the grasper's jaws in ODE.
      m_dynamics->setShape(m_objectDynBody[j], o.shape);
    }
    m_dynamics->setFriction(m_scene.contact.friction);
    // Bodies with dynamics take their share of each contact correction (ContactWorld's
    // two-body exchange); kinematic tools stay immovable for the tissue.
    if (m_contact) {
      for (size_t i = 0; i < nt; ++i)
        if (m_toolContactBody[i] >= 0 && m_scene.tools[i].dynamics)
          m_contact->setInverseMass(m_toolContactBody[i], 1.0 / m_scene.tools[i].dynamics->mass);
      for (size_t j = 0; j < no; ++j)
        m_contact->setInverseMass(m_objectContactBody[j], 1.0 / m_scene.objects[j].mass);
    }
  }
  const int nb = m_dynamics ? m_dynamics->numBodies() : 0;
  m_reactionForce.assign(nb, Vec3::Zero());
  m_reactionTorque.assign(nb, Vec3::Zero());
}

Vec3 Interaction::toolAt(size_t i, Real t) const {
  const ToolSpec& tool = m_scene.tools[i];
  if (m_toolDynBody[i] < 0) return toolPosition(tool.trajectory, t);
  Vec3 p = m_dynamics->position(m_toolDynBody[i]);
  if (tool.type == ToolType::Grasper)
    p -= m_dynamics->rotation(m_toolDynBody[i]) * grasperOffset(tool);
  return p;
}

std::vector<Vec3> Interaction::objectPositions() const {
  std::vector<Vec3> out;
  for (int b : m_objectDynBody) out.push_back(m_dynamics ? m_dynamics->position(b) : Vec3::Zero());
  return out;
}

std::vector<std::string> Interaction::describeWorlds() const {
  std::vector<std::string> out;
  if (m_contact) {
    int probes = 0;
    for (int b : m_toolContactBody) probes += b >= 0;
    out.push_back("bullet: btCollisionWorld (btDbvtBroadphase + Bullet narrowphase) with " +
                  std::to_string(probes) + " probe(s) and " +
                  std::to_string(m_scene.objects.size()) + " object(s); contact thickness " +
                  std::to_string(m_scene.contact.thickness) + " m, " +
                  std::to_string(m_scene.contact.passes) + " pass(es), method " +
                  contactMethodName(m_scene.contact.method) + ", friction " +
                  std::to_string(m_scene.contact.friction));
  }
  if (m_dynamics) {
    int tools = 0;
    for (int b : m_toolDynBody) tools += b >= 0;
    out.push_back("ode: dWorld with " + std::to_string(tools) + " virtually coupled tool(s) and " +
                  std::to_string(m_scene.objects.size()) + " rigid object(s) (" +
                  std::to_string(m_dynamics->numBodies()) + " bodies)");
  }
  return out;
}

void Interaction::finishStep(const StepInput& in, const Model& model) {
  if (!m_dynamics) return;
  std::fill(m_reactionForce.begin(), m_reactionForce.end(), Vec3::Zero());
  std::fill(m_reactionTorque.begin(), m_reactionTorque.end(), Vec3::Zero());
  if (m_contact) {
    for (size_t i = 0; i < m_scene.tools.size(); ++i) {
      if (m_toolContactBody[i] < 0 || m_toolDynBody[i] < 0) continue;
      m_reactionForce[m_toolDynBody[i]] += m_contact->reactionForce(m_toolContactBody[i]);
      m_reactionTorque[m_toolDynBody[i]] += m_contact->reactionTorque(m_toolContactBody[i]);
    }
    for (size_t j = 0; j < m_scene.objects.size(); ++j) {
      m_reactionForce[m_objectDynBody[j]] += m_contact->reactionForce(m_objectContactBody[j]);
      m_reactionTorque[m_objectDynBody[j]] += m_contact->reactionTorque(m_objectContactBody[j]);
    }
  }
  // The model's grasp forces only where a dynamic instrument holds one (a model may compute
  // them when asked).
  std::vector<Vec3> grasp;
  bool asked = false, forceless = false;
  for (size_t g = 0; g < in.grasps.size(); ++g) {
    const int tool = in.grasps[g].tool;
    if (tool < 0 || tool >= int(m_toolDynBody.size()) || m_toolDynBody[tool] < 0) continue;
    if (!asked) grasp = model.graspForces();
    asked = true;
    if (g < grasp.size())
      m_reactionForce[m_toolDynBody[tool]] += grasp[g];
    else
      forceless = true;
  }
  m_forcelessGraspSteps += forceless;
}

StepInput Interaction::prepare(Real t, Real dt, const Model& model) {
  StepInput in;
  in.time = t;
  in.dt = dt;
  in.gravity = m_scene.gravity;
  const Real slack = kTimeSlack * dt;

  if (m_dynamics) {
    const auto hand = [&](const std::vector<KeyFrame>& traj, const Vec3& offset, int body) {
      const Vec3 a = toolPosition(traj, t), b = toolPosition(traj, t + dt);
      m_dynamics->setHand(body, b + offset, (b - a) / dt);
    };
    for (size_t i = 0; i < m_scene.tools.size(); ++i) {
      const int b = m_toolDynBody[i];
      if (b < 0) continue;
      const ToolSpec& tool = m_scene.tools[i];
      m_toolPosBefore[i] = toolAt(i, t);
      const bool grasper = tool.type == ToolType::Grasper;
      hand(tool.trajectory, grasper ? grasperOffset(tool) : Vec3::Zero(), b);
      if (grasper) m_dynamics->setJaws(b, jawClosed(tool.trajectory, t + slack));
    }
    for (size_t j = 0; j < m_scene.objects.size(); ++j) {
      if (!m_scene.objects[j].trajectory.empty())
        hand(m_scene.objects[j].trajectory, Vec3::Zero(), m_objectDynBody[j]);
    }
    for (int b = 0; b < static_cast<int>(m_reactionForce.size()); ++b) {
      m_dynamics->addForce(b, m_reactionForce[b], m_dynamics->position(b));
      m_dynamics->addTorque(b, m_reactionTorque[b]);
    }
    m_dynamics->step(dt);
    m_handForces.clear();
    for (size_t i = 0; i < m_scene.tools.size(); ++i) {
      if (m_toolDynBody[i] >= 0)
        m_handForces.push_back({"tools/" + std::to_string(i),
                                m_dynamics->couplingForce(m_toolDynBody[i]), toolAt(i, t + dt)});
    }
    for (size_t j = 0; j < m_scene.objects.size(); ++j) {
      if (!m_scene.objects[j].trajectory.empty())
        m_handForces.push_back({"objects/" + std::to_string(j),
                                m_dynamics->couplingForce(m_objectDynBody[j]),
                                m_dynamics->position(m_objectDynBody[j])});
    }
  }
  if (m_contact) {
    m_contact->clearReactions();
    for (size_t i = 0; i < m_scene.tools.size(); ++i) {
      const int b = m_toolContactBody[i];
      if (b < 0) continue;
      if (m_toolDynBody[i] >= 0) {
        m_contact->setPose(b, toolAt(i, t + dt), m_dynamics->rotation(m_toolDynBody[i]));
      } else {
        m_contact->setPose(b, toolPosition(m_scene.tools[i].trajectory, t + dt));
      }
    }
    for (size_t j = 0; j < m_scene.objects.size(); ++j) {
      m_contact->setPose(m_objectContactBody[j], m_dynamics->position(m_objectDynBody[j]),
                         m_dynamics->rotation(m_objectDynBody[j]));
    }
    in.contact = m_contact.get();
  }

  for (size_t i = 0; i < m_scene.tools.size(); ++i) {
    const ToolSpec& tool = m_scene.tools[i];
    if (tool.type == ToolType::Grasper) {
      Attachment& a = m_attach[i];
      const bool closed = jawClosed(tool.trajectory, t + slack);
      if (closed && !a.active) {
        a = Attachment{};
        a.active = true;
        a.toolAtClose = m_toolDynBody[i] >= 0 ? m_toolPosBefore[i] : toolAt(i, t);
        a.vertices = graspedSurfaceVertices(m_rest.V, a.toolAtClose, tool.radius);
        const MatX3& surface = model.surface();
        a.closePositions.resize(static_cast<Eigen::Index>(a.vertices.size()), 3);
        for (size_t k = 0; k < a.vertices.size(); ++k)
          a.closePositions.row(Eigen::Index(k)) = surface.row(a.vertices[k]);
        if (a.vertices.empty() &&
            std::find(m_emptyGrasps.begin(), m_emptyGrasps.end(), int(i)) == m_emptyGrasps.end())
          m_emptyGrasps.push_back(static_cast<int>(i));
      } else if (!closed && a.active) {
        a = Attachment{};
      }
      if (a.active && !a.vertices.empty()) {
        GraspInput g;
        g.tool = static_cast<int>(i);
        g.vertices = a.vertices;
        const Vec3 shift = toolAt(i, t + dt) - a.toolAtClose;
        g.targets = a.closePositions.rowwise() + shift.transpose();
        in.grasps.push_back(std::move(g));
      }
    }
    // Probes act through the contact world (set above), not through the grasp input.
  }
  // Plates: grasps of the surface vertices in their boxes, from the start, to rest +
  // offset(t + dt): bonded, or along the plate's normal only (sliding).
  for (size_t p = 0; p < m_scene.plates.size(); ++p) {
    const std::vector<int>& held = m_plateVertices[p];
    if (held.empty()) continue;
    GraspInput g;
    g.tool = static_cast<int>(m_scene.tools.size() + p);
    g.vertices = held;
    if (m_scene.plates[p].contact == PlateContact::Sliding)
      g.slideNormal = m_scene.plates[p].normal;
    const Vec3 offset = toolPosition(m_scene.plates[p].trajectory, t + dt);
    g.targets.resize(Eigen::Index(held.size()), 3);
    for (size_t k = 0; k < held.size(); ++k)
      g.targets.row(Eigen::Index(k)) = m_rest.V.row(held[k]) + offset.transpose();
    in.grasps.push_back(std::move(g));
  }

  for (size_t l = 0; l < m_scene.loads.size(); ++l) {
    const LoadSpec& load = m_scene.loads[l];
    if (t + slack < load.start || t + slack >= load.end) continue;
    PointLoad p;
    p.surfaceVertex = m_loadVertices[l];
    p.vertices = m_loadPatches[l].vertices;
    p.weights = m_loadPatches[l].weights;
    if (load.type == LoadType::PointForce || load.type == LoadType::Traction) {
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

std::vector<Real> Interaction::graspTravel() const {
  std::vector<Real> out(m_scene.tools.size(), 0.0);
  for (size_t i = 0; i < m_scene.tools.size(); ++i) {
    const ToolSpec& tool = m_scene.tools[i];
    if (tool.type != ToolType::Grasper) continue;
    const auto& traj = tool.trajectory;
    Vec3 close = Vec3::Zero();
    bool was = false;
    for (const KeyFrame& k : traj) {
      if (k.jawClosed && !was) close = k.pos;
      if (k.jawClosed) out[i] = std::max(out[i], (k.pos - close).norm());
      was = k.jawClosed;
    }
  }
  for (const PlateSpec& plate : m_scene.plates) {
    Real travel = 0;
    for (const KeyFrame& k : plate.trajectory) travel = std::max(travel, k.pos.norm());
    out.push_back(travel);
  }
  return out;
}

std::vector<int> plateSurfaceVertices(const MatX3& rest, const Box& region) {
  return rowsInBox(rest, region);
}

SurfacePatch regionPatch(const SurfaceMesh& rest, const Box& box) {
  SurfacePatch patch;
  std::map<int, Real> area;
  Real total = 0;
  for (int f = 0; f < rest.numFaces(); ++f) {
    bool inside = true;
    for (int k = 0; k < 3; ++k)
      inside = inside && box.contains(rest.V.row(rest.F(f, k)).transpose());
    if (!inside) continue;
    const Vec3 X0 = rest.V.row(rest.F(f, 0)), X1 = rest.V.row(rest.F(f, 1)),
               X2 = rest.V.row(rest.F(f, 2));
    const Real a = 0.5 * (X1 - X0).cross(X2 - X0).norm();
    for (int k = 0; k < 3; ++k) area[rest.F(f, k)] += a / 3;
    total += a;
  }
  if (!(total > 0)) return patch;
  for (const auto& [v, a] : area) {
    patch.vertices.push_back(v);
    patch.weights.push_back(a / total);
  }
  return patch;
}

}  // namespace deform
