// deformbench SDK: interaction resolved identically for every model. The harness owns one
// Interaction per run; before each step it turns the scene's tools and loads at that time into a
// StepInput in terms of the model's own nodes and the organ's surface vertices.
//
// Grasp: when a grasper's jaws close (keyframe jaw "closed" after "open") at tool position p, the
// model nodes within the tool radius of p are attached, with their positions at that moment;
// each later step their targets are those positions translated by tool(t+dt) - tool(t_close).
// When the jaws open they are released. A grasp that closes on no node attaches nothing (and is
// reported). Point force: applied at the surface vertex nearest to `at` on the rest surface.
//
// Instruments (only when the scene asks): probes and rigid objects are bodies of a Bullet
// ContactWorld (deform/sdk/contact.h) handed to the model through StepInput::contact; tools with
// "dynamics" and objects are ODE bodies (deform/engine/instruments.h). prepare() first advances the
// ODE bodies over the step (virtual coupling to the keyframed hand, plus the tissue's reaction of
// the previous step), then places every instrument at its pose for the end of the step. After the
// model's step, finishStep() collects the tissue's reaction (contact forces, grasp forces) for the
// next ODE step. A scene with kinematic graspers and loads only creates neither world.
#pragma once

#include <deform/engine/instruments.h>
#include <deform/engine/scene.h>
#include <deform/geometry/pressure_patch.h>
#include <deform/sdk/contact.h>
#include <deform/sdk/model.h>

#include <memory>
#include <string>
#include <vector>

namespace deform {

/// Tool position at time t: piecewise-linear between keyframes, held before the first and after
/// the last.
Vec3 toolPosition(const std::vector<KeyFrame>& trajectory, Real t);
/// Jaw state at time t: that of the last keyframe with t_k <= t (open before the first).
bool jawClosed(const std::vector<KeyFrame>& trajectory, Real t);

// graspedSurfaceVertices(), the one definition of the grasped set, is in deform/sdk/model.h.

/// The organ surface vertices a plate holds: every rest-surface vertex inside its box (sorted;
/// empty when none is, which loadOrgan() refuses). The one definition of the plate's set.
std::vector<int> plateSurfaceVertices(const MatX3& rest, const Box& region);

// SurfacePatch and pressurePatch(), the point force read as a pressure patch, are in
// deform/geometry/pressure_patch.h.

/// A uniform traction over the rest surface triangles whose three vertices lie inside `box`, as
/// consistent nodal forces of linear triangles: each vertex gets a third of the area of its
/// loaded triangles, over the loaded area (the weights sum to 1). The vertices ascend (the first
/// one stands for the patch's centre); empty when no triangle lies inside the box.
SurfacePatch regionPatch(const SurfaceMesh& rest, const Box& box);

class Interaction {
 public:
  Interaction(const Scene& scene, const SurfaceMesh& restSurface);

  ~Interaction();

  /// The input for the step from time t to t + dt, given the model's current nodes.
  StepInput prepare(Real t, Real dt, const Model& model);
  /// After model.step(in): the tissue's reaction on dynamic instruments, for the next prepare().
  void finishStep(const StepInput& in, const Model& model);

  /// Force the hand exerts on each dynamic instrument over the last prepared step (the virtual
  /// coupling's F_c; the hand feels -F_c), in scene order: tools with "dynamics", then objects
  /// with a trajectory. Empty without an ODE world.
  struct HandForce {
    std::string instrument;        ///< "tools/0", "objects/1"
    Vec3 force = Vec3::Zero();     ///< N
    Vec3 position = Vec3::Zero();  ///< m, the body at the end of the step
  };
  const std::vector<HandForce>& handForces() const { return m_handForces; }
  /// Positions (m) of the objects at the end of the last prepared step, in scene order.
  std::vector<Vec3> objectPositions() const;

  /// The worlds this interaction created (nullptr when the scene did not need them).
  const ContactWorld* contactWorld() const { return m_contact.get(); }
  const InstrumentWorld* instrumentWorld() const { return m_dynamics.get(); }
  /// One line per created world, for --explain ("bullet: ...", "ode: ..."); empty if none.
  std::vector<std::string> describeWorlds() const;

  /// Forget attachments (for Model::reset()).
  void reset();  // also rebuilds the instrument worlds at their initial state

  /// Surface vertex each load acts on (index into the rest surface), in scene order.
  const std::vector<int>& loadVertices() const { return m_loadVertices; }
  /// Point around which rmse_k is measured: the first load's vertex, else the first grasp's
  /// closing point, else the organ's centre.
  Vec3 focusPoint() const;
  /// Grasps that closed on no surface vertex so far (tool indices), for warnings.
  const std::vector<int>& emptyGrasps() const { return m_emptyGrasps; }
  /// Steps at which a grasp of a dynamic instrument got no force from the model (graspForces()
  /// shorter than the grasps): that instrument felt no tissue.
  int forcelessGraspSteps() const { return m_forcelessGraspSteps; }
  /// The pressure patch of each load, in scene order.
  const std::vector<SurfacePatch>& loadPatches() const { return m_loadPatches; }
  /// Tool travel while grasping: for each grasper, the largest distance its position reaches
  /// from the closing point over its closed phases (m; 0 for other tools). The scale of the
  /// grasp-residual validity test. Plates follow the tools (index = tools + plate): the largest
  /// norm of their offset.
  std::vector<Real> graspTravel() const;
  /// The surface vertices each plate holds (plateSurfaceVertices), in scene order.
  const std::vector<std::vector<int>>& plateVertices() const { return m_plateVertices; }

 private:
  struct Attachment {
    bool active = false;
    Vec3 toolAtClose = Vec3::Zero();
    std::vector<int> vertices;  ///< organ surface vertices held
    MatX3 closePositions;       ///< the model's surface positions of those at the closing
  };
  void buildWorlds();
  /// Tool position at time t: the ODE body's when the tool has dynamics (its current position;
  /// prepare() keeps the one before the step), else the keyframed one.
  Vec3 toolAt(size_t tool, Real t) const;

  const Scene& m_scene;
  const SurfaceMesh& m_rest;
  std::vector<int> m_loadVertices;
  std::vector<SurfacePatch> m_loadPatches;
  std::vector<Attachment> m_attach;
  std::vector<int> m_emptyGrasps;
  int m_forcelessGraspSteps = 0;
  std::vector<std::vector<int>> m_plateVertices;

  std::unique_ptr<ContactWorld> m_contact;
  std::unique_ptr<InstrumentWorld> m_dynamics;
  std::vector<int> m_toolContactBody, m_toolDynBody;      // per tool, -1 when none
  std::vector<int> m_objectContactBody, m_objectDynBody;  // per object
  std::vector<Vec3> m_toolPosBefore;                      // dynamic tools, at the step's start
  std::vector<Vec3> m_reactionForce, m_reactionTorque;    // per ODE body, from the last step
  std::vector<HandForce> m_handForces;
};

}  // namespace deform
