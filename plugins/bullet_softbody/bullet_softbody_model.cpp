#include "bullet_softbody_model.h"

#include <BulletSoftBody/btSoftBody.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <BulletSoftBody/btSoftRigidDynamicsWorld.h>
#include <btBulletDynamicsCommon.h>

#include <algorithm>
#include <cmath>

namespace deform::bullet_softbody {

static_assert(sizeof(btScalar) == sizeof(double), "the Bullet peers use double-precision Bullet");

Real xpbdLinkStiffness(Real young, Real thickness, Real restLength, Real adjacentArea, Real wa,
                       Real wb, Real dt) {
  const Real w = wa + wb;
  const Real stiffness = young * thickness * adjacentArea;  // alpha = L0^2 / stiffness
  if (w <= 0 || !(stiffness > 0)) return 1.0;
  const Real alphaTilde = restLength * restLength / stiffness / (dt * dt);
  // Bullet divides by kLST: keep it away from 0 for absurdly soft links.
  return std::clamp(w / (w + alphaTilde), 1e-12, 1.0);
}

Real volumeCoefficient(const Material& m, Real restVolume) {
  const Real bulk = m.young / (3.0 * (1.0 - 2.0 * m.poisson));
  return restVolume > 0 ? bulk / restVolume : 0.0;
}

Real dampingCoefficient(Real rate, Real dt) {
  return 1.0 - std::exp(-rate * dt);
}

// The Bullet objects of one run. Members are declared in construction order; the soft body is
// not owned by the world, so it is removed and deleted first.
struct BulletSoftBodyModel::World {
  btSoftBodyRigidBodyCollisionConfiguration collision;
  btCollisionDispatcher dispatcher{&collision};
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btSoftRigidDynamicsWorld world{&dispatcher, &broadphase, &solver, &collision};
  btSoftBody* body = nullptr;
  std::vector<btScalar> inverseMass;  // per node, 0 for fixed nodes

  ~World() {
    if (body) {
      world.removeSoftBody(body);
      delete body;
    }
  }
};

BulletSoftBodyModel::BulletSoftBodyModel() = default;
BulletSoftBodyModel::~BulletSoftBodyModel() = default;

void BulletSoftBodyModel::init(const ModelSetup& setup) {
  const SoftBodyConfig config = configFromParams(setup.params);
  const std::vector<int> fixed =
      fixedNodeIndices(setup.organ.surface.V, setup.organ.fixed, setup.organ.surface);
  init(setup.organ, config, setup.dt, fixed);
}

void BulletSoftBodyModel::init(const Organ& organ, const SoftBodyConfig& config, Real dt,
                               const std::vector<int>& fixedNodes) {
  const SurfaceMesh& s = organ.surface;
  if (s.numVertices() < 4 || s.numFaces() < 4)
    throw InputError(organ.source, "", "bullet_softbody needs a closed surface mesh");
  if (!(dt > 0)) throw InputError(organ.source, "dt", "bullet_softbody needs a positive time step");
  // generateBendingConstraints(2) allocates a dense #V x #V distance table.
  if (config.bending && s.numVertices() > 12000)
    throw InputError(organ.source, "params.bending",
                     "Bullet's bending links need a dense #V^2 table; at most 12000 vertices");
  m_config = config;
  m_dt = dt;
  m_material = organ.material;
  m_rest = s.V;
  m_faces = s.F;
  m_edges = uniqueEdges(s.F);
  m_fixed = fixedNodes;
  m_restVolume = signedVolume(s.V, s.F);
  if (!(m_restVolume > 0))
    throw InputError(organ.source, "", "bullet_softbody needs an outward-oriented closed surface");

  // Area of the faces adjacent to each edge, and node masses by adjacent area.
  const MatX2i ef = edgeFaces(s.F, m_edges);
  VecX faceArea(s.numFaces());
  VecX nodeArea = VecX::Zero(s.numVertices());
  for (int f = 0; f < s.numFaces(); ++f) {
    const Vec3 a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
    faceArea(f) = 0.5 * (b - a).cross(c - a).norm();
    for (int k = 0; k < 3; ++k) nodeArea(s.F(f, k)) += faceArea(f) / 3.0;
  }
  m_edgeArea.resize(m_edges.rows());
  for (Eigen::Index e = 0; e < m_edges.rows(); ++e) {
    m_edgeArea(e) = 0;
    for (int k = 0; k < 2; ++k)
      if (ef(e, k) >= 0) m_edgeArea(e) += faceArea(ef(e, k));
  }
  m_holder.assign(size_t(s.numVertices()), -1);
  const Real totalMass = organ.material.density * m_restVolume;
  m_mass = nodeArea * (totalMass / nodeArea.sum());

  const Box box = boundingBox(s.V);
  m_tail.boxCenter = box.center();
  m_tail.boxHalf = 0.5 * tol::kDivergenceBoxFactor * box.size().maxCoeff();

  build();
}

void BulletSoftBodyModel::build() {
  m_world = std::make_unique<World>();
  World& w = *m_world;
  const int n = static_cast<int>(m_rest.rows());

  std::vector<btVector3> x(n);
  std::vector<btScalar> mass(n);
  for (int i = 0; i < n; ++i) {
    x[i] = btVector3(m_rest(i, 0), m_rest(i, 1), m_rest(i, 2));
    mass[i] = m_mass(i);
  }
  for (int i : m_fixed) mass[i] = 0;  // Bullet: mass 0 = immovable
  w.inverseMass.resize(n);
  for (int i = 0; i < n; ++i) w.inverseMass[i] = mass[i] > 0 ? 1.0 / mass[i] : 0.0;

  btSoftBodyWorldInfo& info = w.world.getWorldInfo();
  info.m_gravity.setZero();
  w.body = new btSoftBody(&info, n, x.data(), mass.data());
  btSoftBody& b = *w.body;

  btSoftBody::Material* base = b.m_materials[0];
  base->m_kLST = m_config.mapping == StiffnessMapping::Fixed ? m_config.linkStiffness : 1.0;
  for (Eigen::Index e = 0; e < m_edges.rows(); ++e) {
    const int a = m_edges(e, 0), c = m_edges(e, 1);
    btSoftBody::Material* mat = base;
    if (m_config.mapping == StiffnessMapping::Xpbd) {
      mat = b.appendMaterial();
      const Real rest = (m_rest.row(a) - m_rest.row(c)).norm();
      mat->m_kLST = xpbdLinkStiffness(m_material.young, m_config.thickness, rest, m_edgeArea(e),
                                      w.inverseMass[a], w.inverseMass[c], m_dt);
    }
    b.appendLink(a, c, mat, false);
  }
  for (Eigen::Index f = 0; f < m_faces.rows(); ++f)
    b.appendFace(m_faces(f, 0), m_faces(f, 1), m_faces(f, 2), base);
  if (m_config.bending) {
    btSoftBody::Material* bend = b.appendMaterial();
    bend->m_kLST = m_config.bendingStiffness;
    b.generateBendingConstraints(2, bend);
  }

  b.m_cfg.piterations = m_config.iterations;
  b.m_cfg.kDP = dampingCoefficient(m_config.damping, m_dt);
  b.m_cfg.kVC =
      m_config.volume ? m_config.volumeScale * volumeCoefficient(m_material, m_restVolume) : 0.0;
  // Bullet's own collision stays off (no self collision); instruments are handled by the shared
  // contact response after the step (bullet_peer_step.h).
  b.m_cfg.collisions = 0;
  // setPose records the rest volume V0 for kVC and calls updateConstants (rest lengths, areas)
  // while the body is at rest. Afterwards m_bUpdateRtCst must stay false: Bullet's
  // updateConstants() would reset every rest length to the current (deformed) length, which is
  // why grasps write the inverse masses directly instead of calling setMass().
  b.setPose(m_config.volume, false);
  b.updateNormals();
  b.m_bUpdateRtCst = false;
  b.setActivationState(DISABLE_DEACTIVATION);
  w.world.addSoftBody(&b);

  m_tail.grasped.clear();
  m_graspForces.clear();
  m_graspForcesStale = false;
  bullet_common::copyNodes(b, m_x);
}

StepStatus BulletSoftBodyModel::step(const StepInput& in) {
  World& w = *m_world;
  btSoftBody& b = *w.body;
  const Real dt = in.dt > 0 ? in.dt : m_dt;
  w.world.getWorldInfo().m_gravity = btVector3(in.gravity.x(), in.gravity.y(), in.gravity.z());

  // Kinematic grasped nodes (the surface vertices are the body's nodes): inverse mass 0 and
  // the velocity that lands them on the target.
  if (bullet_common::beginBulletStep(b, w.inverseMass, in.grasps, {}, m_tail))
    b.updateLinkConstants();  // link c0 = (w_a + w_b) / kLST
  for (const NodeGrasp& g : m_tail.nodeGrasps)
    for (size_t k = 0; k < g.nodes.size() && !g.sliding(); ++k) {
      btSoftBody::Node& node = b.m_nodes[g.nodes[k]];
      const btVector3 target(g.targets(k, 0), g.targets(k, 1), g.targets(k, 2));
      node.m_v = (target - node.m_x) / dt;
    }
  bullet_common::aimSlidingNodes(b, m_tail, dt);  // free along their plate (bullet_peer_step.h)
  for (const PointLoad& l : in.loads)
    for (size_t k = 0; k < l.vertices.size(); ++k) {
      const Vec3 f = l.weights[k] * l.force;
      b.addForce(btVector3(f.x(), f.y(), f.z()), l.vertices[k]);
    }

  w.world.stepSimulation(dt, 0, dt);  // exactly one internal step of length dt
  // Before finishBulletStep puts them back on the plate.
  m_slidingForces = bullet_common::slidingPlateForces(b, m_tail, in.grasps.size(), dt);
  m_stepGrasps = in.grasps.size();
  m_stepDt = dt;
  m_graspForcesStale = true;
  return bullet_common::finishBulletStep(b, in, dt, m_tail, m_x, m_phase);
}

std::vector<Vec3> BulletSoftBodyModel::graspForces() const {
  if (m_graspForcesStale) {
    computeGraspForces(m_stepGrasps, m_stepDt);
    m_graspForcesStale = false;
  }
  return m_graspForces;
}

void BulletSoftBodyModel::computeGraspForces(std::size_t numGrasps, Real dt) const {
  m_graspForces.clear();
  if (m_config.mapping != StiffnessMapping::Xpbd) return;  // no physical stiffness to report
  m_graspForces.assign(numGrasps, Vec3::Zero());
  if (numGrasps == 0) return;
  const btSoftBody& b = *m_world->body;
  const size_t ng = std::min(numGrasps, m_tail.nodeGrasps.size());
  for (size_t g = 0; g < ng; ++g)
    for (int node : m_tail.nodeGrasps[g].nodes)
      if (m_holder[size_t(node)] < 0 && b.m_nodes[node].m_im == 0) m_holder[size_t(node)] = int(g);
  // Links: one projection of link (a, c) moves c by w_c kappa d and a by -w_a kappa d,
  // kappa = kLST (L0^2 - |d|^2) / ((w_a + w_c) (L0^2 + |d|^2)), d = x_c - x_a: the momentum it
  // gives a is -kappa d whatever w_a (0 for a kinematic node: then that is what the node, held by
  // the tool, gives c back). Near a steady state the constraint error hardly changes over the
  // sweeps of a step, so the `iterations` sweeps give a -N kappa d per step: a force -N kappa d /
  // dt^2 on the held end.
  const Real sweeps = Real(b.m_cfg.piterations) / (dt * dt);
  const btSoftBody::Node* first = &b.m_nodes[0];
  for (int e = 0; e < b.m_links.size(); ++e) {  // structural, then bending links
    const btSoftBody::Link& l = b.m_links[e];
    const int a = int(l.m_n[0] - first), c = int(l.m_n[1] - first);
    const int ga = m_holder[size_t(a)], gc = m_holder[size_t(c)];
    if (ga < 0 && gc < 0) continue;
    const Real w = l.m_n[0]->m_im + l.m_n[1]->m_im;
    if (!(w > 0)) continue;  // both ends immovable: Bullet skips the link
    const Vec3 d = m_x.row(c) - m_x.row(a);
    const Real l2 = d.squaredNorm(), r2 = l.m_rl * l.m_rl;
    const Real kappa = l.m_material->m_kLST * (r2 - l2) / (w * (r2 + l2));
    const Vec3 f = (-sweeps * kappa) * d;  // on a
    if (ga >= 0) m_graspForces[size_t(ga)] += f;
    if (gc >= 0) m_graspForces[size_t(gc)] -= f;
  }
  for (size_t g = 0; g < ng; ++g) {
    const NodeGrasp& gr = m_tail.nodeGrasps[g];
    if (!gr.sliding()) continue;
    const Vec3 n = gr.slideNormal.normalized();
    m_graspForces[g] = n * n.dot(m_graspForces[g]) + m_slidingForces[g];
  }
  for (size_t g = 0; g < ng; ++g)
    for (int node : m_tail.nodeGrasps[g].nodes) m_holder[size_t(node)] = -1;
}

void BulletSoftBodyModel::reset() {
  build();
}

Counts BulletSoftBodyModel::counts() const {
  const btSoftBody& b = *m_world->body;
  long long bending = 0;
  for (int i = 0; i < b.m_links.size(); ++i) bending += b.m_links[i].m_bbending ? 1 : 0;
  return {{"nodes", b.m_nodes.size()},
          {"links", b.m_links.size()},
          {"bending_links", bending},
          {"faces", b.m_faces.size()}};
}

std::vector<Real> BulletSoftBodyModel::linkStiffnesses() const {
  const btSoftBody& b = *m_world->body;
  std::vector<Real> k(b.m_links.size());
  for (int i = 0; i < b.m_links.size(); ++i) k[i] = b.m_links[i].m_material->m_kLST;
  return k;
}

Real BulletSoftBodyModel::volumeCoefficientUsed() const {
  return m_world->body->m_cfg.kVC;
}
Real BulletSoftBodyModel::dampingCoefficientUsed() const {
  return m_world->body->m_cfg.kDP;
}

}  // namespace deform::bullet_softbody
