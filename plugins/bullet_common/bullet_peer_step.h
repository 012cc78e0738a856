// What the two Bullet peer plugins (bullet_softbody: btSoftBody on the organ surface;
// bullet_deformable: btDeformableBody on a tet mesh) do around Bullet's own step, in one place.
// Not a plugin: a header both include (through the deform_bullet_double target).
//
// Before the step: grasped nodes become kinematic (Bullet inverse mass 0; the model gives them the
// velocity that lands them on their targets), released nodes get their inverse mass back. Nodes
// under a sliding plate (GraspInput::slideNormal) keep their mass: Bullet has no per-axis
// constraint on a node, so their velocity along the plate's normal is set to land them on its
// plane (aimSlidingNodes) and, after the step, their position and velocity along the normal are
// set again (the solve moved them), the tangential components left to Bullet.
//
// After the step (finishBulletStep):
//   1. grasped nodes are put exactly on their targets, sliding nodes on their plate's plane,
//      moving with it along its normal;
//   2. contact with the scene's rigid instruments (StepInput::contact) by the SDK's shared
//      response, the same for every model (deform/sdk/contact.h, respondToContact()): each node is
//      a sphere of the contact thickness; a penetrating node i with inverse mass w_i > 0 moves out,
//        x_i += d n,   v_i -= min(v_i . n, 0) n
//      (Mueller et al. 2007, "Position based dynamics", Sec. 3.5, Eq. (9)-(10), static collider,
//      plus an inelastic normal velocity), and -m_i (dx_i / dt + dv_i) / dt is reported to the
//      instrument as the tissue's reaction. Bullet's own collision pipeline stays off
//      (m_cfg.collisions = 0): the response is applied after Bullet's step, to its node positions
//      and velocities, which are written back so that Bullet's next step starts from them;
//   3. the nodes are copied out (and the organ's surface vertices, when they are a subset);
//   4. divergence: NaN/Inf, or a node outside the cube of half side boxHalf about boxCenter.
#pragma once

#include <BulletSoftBody/btSoftBody.h>
#include <deform/sdk/contact.h>
#include <deform/sdk/model.h>

#include <algorithm>
#include <chrono>
#include <vector>

namespace deform::bullet_common {

/// A node under a sliding plate in this step: n . x ends at `offset`, from `start` (n . x when
/// the step began); free along the plate.
struct SlidingNode {
  int node;
  Vec3 normal;
  Real offset, start;
};

/// Per-model state of the shared step tail. Scratch members keep their capacity across steps.
struct PeerStepState {
  Vec3 boxCenter = Vec3::Zero();  ///< m, centre of the divergence cube
  Real boxHalf = 0;               ///< m, its half side
  std::vector<int> grasped;       ///< sorted nodes kinematic in the last step
  std::vector<int> graspScratch;
  std::vector<NodeGrasp> nodeGrasps;  ///< this step's grasps on the nodes carrying the vertices
  std::vector<SlidingNode> sliding;   ///< this step's nodes under sliding plates (not bonded)
  MatX3 velocity;                     ///< #N by 3, m/s (contact only)
  VecX invMass;                       ///< #N, 1/kg (contact only)
  MatX3 before;                       ///< #N by 3, positions before the contact response
  std::chrono::steady_clock::time_point start;
};

/// Makes the nodes carrying the grasped surface vertices of bonded `grasps` kinematic (inverse
/// mass 0) and gives released nodes inverseMass back; lists the nodes under sliding plates (a node
/// a bonded grasp also holds stays bonded); records the step's start time. surfaceNode: the node
/// of each organ surface vertex (empty: the identity). Returns true when the kinematic set changed
/// (the caller refreshes whatever Bullet derives from the inverse masses).
inline bool beginBulletStep(btSoftBody& b, const std::vector<btScalar>& inverseMass,
                            const std::vector<GraspInput>& grasps,
                            const std::vector<int>& surfaceNode, PeerStepState& s) {
  s.start = std::chrono::steady_clock::now();
  graspsOnNodes(grasps, surfaceNode, s.nodeGrasps);
  s.graspScratch.clear();
  for (const NodeGrasp& g : s.nodeGrasps)
    if (!g.sliding()) s.graspScratch.insert(s.graspScratch.end(), g.nodes.begin(), g.nodes.end());
  std::sort(s.graspScratch.begin(), s.graspScratch.end());
  s.graspScratch.erase(std::unique(s.graspScratch.begin(), s.graspScratch.end()),
                       s.graspScratch.end());
  s.sliding.clear();
  for (const NodeGrasp& g : s.nodeGrasps) {
    if (!g.sliding()) continue;
    const Vec3 n = g.slideNormal.normalized();
    for (size_t k = 0; k < g.nodes.size(); ++k) {
      const int i = g.nodes[k];
      if (std::binary_search(s.graspScratch.begin(), s.graspScratch.end(), i)) continue;
      const btVector3& x = b.m_nodes[i].m_x;
      s.sliding.push_back({i, n, n.dot(g.targets.row(Eigen::Index(k)).transpose()),
                           n.x() * x.x() + n.y() * x.y() + n.z() * x.z()});
    }
  }
  if (s.graspScratch == s.grasped) return false;
  for (int i : s.grasped) b.m_nodes[i].m_im = inverseMass[size_t(i)];
  for (int i : s.graspScratch) b.m_nodes[i].m_im = 0;
  s.grasped.swap(s.graspScratch);
  return true;
}

/// Gives the nodes under sliding plates the velocity along the normal that lands them on the
/// plate's plane at the end of a step of dt (the tangential velocity kept).
inline void aimSlidingNodes(btSoftBody& b, const PeerStepState& s, Real dt) {
  for (const SlidingNode& h : s.sliding) {
    btSoftBody::Node& node = b.m_nodes[h.node];
    const btVector3 n(h.normal.x(), h.normal.y(), h.normal.z());
    node.m_v += ((h.offset - h.start) / dt - n.dot(node.m_v)) * n;
    node.m_vn = node.m_v;
  }
}

/// Node positions of b into x (#N by 3).
inline void copyNodes(const btSoftBody& b, MatX3& x) {
  x.resize(b.m_nodes.size(), 3);
  for (int i = 0; i < b.m_nodes.size(); ++i)
    for (int k = 0; k < 3; ++k) x(i, k) = b.m_nodes[i].m_x[k];
}

/// Steps 1-4 of the header comment after Bullet's stepSimulation(). x: the model's nodes (out).
/// surfaceNode / surface: when given, surface row i = x row surfaceNode[i]. phase: "step" (the
/// whole step since beginBulletStep()) and "contact" (the response alone) in ms.
inline StepStatus finishBulletStep(btSoftBody& b, const StepInput& in, Real dt, PeerStepState& s,
                                   MatX3& x, PhaseTimes& phase,
                                   const std::vector<int>* surfaceNode = nullptr,
                                   MatX3* surface = nullptr) {
  using Clock = std::chrono::steady_clock;
  for (const NodeGrasp& g : s.nodeGrasps)
    if (!g.sliding())
      for (size_t k = 0; k < g.nodes.size(); ++k)
        b.m_nodes[g.nodes[k]].m_x = btVector3(g.targets(k, 0), g.targets(k, 1), g.targets(k, 2));
  for (const SlidingNode& h : s.sliding) {
    btSoftBody::Node& node = b.m_nodes[h.node];
    const btVector3 n(h.normal.x(), h.normal.y(), h.normal.z());
    node.m_x += (h.offset - n.dot(node.m_x)) * n;
    node.m_v += ((h.offset - h.start) / dt - n.dot(node.m_v)) * n;
    node.m_vn = node.m_v;
  }
  if (!s.sliding.empty()) b.updateNormals();  // the volume force of the next step reads them
  copyNodes(b, x);

  const auto c0 = Clock::now();
  if (in.contact) {
    const int n = b.m_nodes.size();
    s.velocity.resize(n, 3);
    s.invMass.resize(n);
    for (int i = 0; i < n; ++i) {
      const btSoftBody::Node& node = b.m_nodes[i];
      for (int k = 0; k < 3; ++k) s.velocity(i, k) = node.m_v[k];
      s.invMass[i] = node.m_im;  // 0 for fixed and grasped nodes: they stay
    }
    s.before = x;
    ContactProxy proxy;
    proxy.nodes = &x;
    proxy.invMass = &s.invMass;
    proxy.velocity = s.velocity.data();
    const ContactResolution r = respondToContact(*in.contact, proxy, ContactResponse::Project, dt);
    if (r.contacts > 0) {
      // Only moved nodes are written back: Bullet's state of every other node stays bit for bit.
      for (int i = 0; i < n; ++i) {
        if (x.row(i) == s.before.row(i)) continue;
        btSoftBody::Node& node = b.m_nodes[i];
        node.m_x = btVector3(x(i, 0), x(i, 1), x(i, 2));
        node.m_v = btVector3(s.velocity(i, 0), s.velocity(i, 1), s.velocity(i, 2));
        node.m_vn = node.m_v;
      }
      b.updateNormals();  // the volume force of the next step reads the face normals
    }
  }
  const auto c1 = Clock::now();

  if (surfaceNode && surface) {
    surface->resize(Eigen::Index(surfaceNode->size()), 3);
    for (size_t i = 0; i < surfaceNode->size(); ++i)
      surface->row(Eigen::Index(i)) = x.row((*surfaceNode)[i]);
  }
  phase["step"] = std::chrono::duration<double, std::milli>(Clock::now() - s.start).count();
  if (in.contact) phase["contact"] = std::chrono::duration<double, std::milli>(c1 - c0).count();

  if (!x.allFinite()) return StepStatus::Diverged;
  if ((x.rowwise() - s.boxCenter.transpose()).cwiseAbs().maxCoeff() > s.boxHalf)
    return StepStatus::Diverged;
  return StepStatus::Ok;
}

/// After Bullet's step, before finishBulletStep() puts the sliding plates' nodes back on their
/// plates: per grasp, the force a sliding plate takes from its nodes (the normal momentum the step
/// gave them beyond the plate's own motion, per step; zero for a bonded grasp).
inline std::vector<Vec3> slidingPlateForces(const btSoftBody& b, const PeerStepState& s,
                                            std::size_t numGrasps, Real dt) {
  std::vector<Vec3> forces(numGrasps, Vec3::Zero());
  // s.sliding lists, grasp by grasp, the sliding grasps' nodes no bonded grasp holds.
  size_t next = 0;
  for (size_t g = 0; g < numGrasps && g < s.nodeGrasps.size(); ++g) {
    const NodeGrasp& gr = s.nodeGrasps[g];
    if (!gr.sliding()) continue;
    for (int node : gr.nodes) {
      if (std::binary_search(s.grasped.begin(), s.grasped.end(), node)) continue;
      const bullet_common::SlidingNode& h = s.sliding[next++];
      const btSoftBody::Node& nd = b.m_nodes[h.node];
      if (!(nd.m_im > 0)) continue;
      const btVector3 n(h.normal.x(), h.normal.y(), h.normal.z());
      // The plate takes back the normal velocity the step gave the node beyond the plate's own.
      forces[g] += h.normal * ((n.dot(nd.m_v) - (h.offset - h.start) / dt) / (nd.m_im * dt));
    }
  }
  return forces;
}

}  // namespace deform::bullet_common
