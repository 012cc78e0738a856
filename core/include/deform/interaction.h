// deformbench SDK: interaction resolved identically for every model. The harness owns one
// Interaction per run; before each step it turns the scene's tools and loads at that time into a
// StepInput in terms of the model's own nodes and the organ's surface vertices.
//
// Grasp: when a grasper's jaws close (keyframe jaw "closed" after "open") at tool position p, the
// model nodes within the tool radius of p are attached, with their positions at that moment;
// each later step their targets are those positions translated by tool(t+dt) - tool(t_close).
// When the jaws open they are released. A grasp that closes on no node attaches nothing (and is
// reported). Point force: applied at the surface vertex nearest to `at` on the rest surface.
#pragma once

#include <deform/model.h>
#include <deform/scene.h>

#include <string>
#include <vector>

namespace deform {

/// Tool position at time t: piecewise-linear between keyframes, held before the first and after
/// the last.
Vec3 toolPosition(const std::vector<KeyFrame>& trajectory, Real t);
/// Jaw state at time t: that of the last keyframe with t_k <= t (open before the first).
bool jawClosed(const std::vector<KeyFrame>& trajectory, Real t);

class Interaction {
 public:
  Interaction(const Scene& scene, const SurfaceMesh& restSurface);

  /// The input for the step from time t to t + dt, given the model's current nodes.
  StepInput prepare(Real t, Real dt, const Model& model);

  /// Forget attachments (for Model::reset()).
  void reset();

  /// Surface vertex each load acts on (index into the rest surface), in scene order.
  const std::vector<int>& loadVertices() const { return m_loadVertices; }
  /// Point around which rmse_k is measured: the first load's vertex, else the first grasp's
  /// closing point, else the organ's centre.
  Vec3 focusPoint() const;
  /// Grasps that closed on no node so far (tool indices), for warnings.
  const std::vector<int>& emptyGrasps() const { return m_emptyGrasps; }

 private:
  struct Attachment {
    bool active = false;
    Vec3 toolAtClose = Vec3::Zero();
    std::vector<int> nodes;
    MatX3 restPositions;
  };
  const Scene& m_scene;
  const SurfaceMesh& m_rest;
  std::vector<int> m_loadVertices;
  std::vector<Attachment> m_attach;
  std::vector<int> m_emptyGrasps;
};

}  // namespace deform
