#include "bullet_deformable_model.h"

#include <BulletSoftBody/btDeformableBodySolver.h>
#include <BulletSoftBody/btDeformableGravityForce.h>
#include <BulletSoftBody/btDeformableLinearElasticityForce.h>
#include <BulletSoftBody/btDeformableMultiBodyConstraintSolver.h>
#include <BulletSoftBody/btDeformableMultiBodyDynamicsWorld.h>
#include <BulletSoftBody/btDeformableNeoHookeanForce.h>
#include <BulletSoftBody/btSoftBody.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <btBulletDynamicsCommon.h>
#include <deform/geometry/tet_mesher.h>
#include <deform/geometry/tet_nodes.h>
#include <deform/kernels/cholesky_solver.h>
#include <deform/kernels/fem_tet.h>
#include <deform/sdk/cache.h>

#include <algorithm>
#include <array>
#include <cmath>

namespace deform::bullet_deformable {

static_assert(sizeof(btScalar) == sizeof(double), "the Bullet peers use double-precision Bullet");

std::pair<Real, Real> lameParameters(const Material& m) {
  const Real mu = m.young / (2.0 * (1.0 + m.poisson));
  const Real lambda = m.young * m.poisson / ((1.0 + m.poisson) * (1.0 - 2.0 * m.poisson));
  return {mu, lambda};
}

VecX lumpedMasses(const TetMesh& mesh, Real density) {
  VecX m = VecX::Zero(mesh.numVertices());
  for (int t = 0; t < mesh.numTets(); ++t) {
    const auto r = mesh.T.row(t);
    const Real v =
        std::abs(tetVolume(mesh.V.row(r(0)), mesh.V.row(r(1)), mesh.V.row(r(2)), mesh.V.row(r(3))));
    for (int k = 0; k < 4; ++k) m(r(k)) += density * v / 4.0;
  }
  return m;
}

namespace {

// The preconditioner of Bullet's CG (parameter "preconditioner"), z = P^-1 r:
//   rest_factor: P = M + dt D + dt^2 K of the body at rest (header comment), factorised by
//                CHOLMOD at the scene's dt, the held nodes (inverse mass 0) pinned by a penalty
//                on their diagonal; refactorised when the held set changes;
//   none:        P = I, what Bullet 3.24 applies in its implicit projection form (the world hands
//                the solver its mass preconditioner, which is filled only in the explicit
//                Lagrange-multiplier branch and is otherwise the identity).
// It also counts Bullet's CG iterations, which Bullet's solver discards: btConjugateGradient
// applies the preconditioner first to its search direction p, then to its residual r once
// before the loop and once per iteration, all three vectors members at fixed addresses. A call
// on any vector but r therefore starts a solve, and a solve's iterations are its r calls less 1.
class CgPreconditioner : public Preconditioner {
 public:
  btDeformableBackwardEulerObjective* objective = nullptr;  // for its projection
  int cap = 0;                                              // CG iteration cap
  long long solves = 0, iterations = 0, cappedSolves = 0;
  long long cappedSteps = 0;  // steps with a solve that reached the cap

  // Assembles P at rest: lumped masses plus each tet's linear-elastic stiffness (fem_tet.h) with
  // the Lame parameters (cMu, cLambda).
  void build(const TetMesh& mesh, const VecX& mass, Real cMu, Real cLambda) {
    const int n = mesh.numVertices();
    std::vector<Triplet> t;
    t.reserve(size_t(mesh.numTets()) * 144 + size_t(n) * 3);
    for (int i = 0; i < n; ++i)
      for (int d = 0; d < 3; ++d) t.emplace_back(3 * i + d, 3 * i + d, mass(i));
    const LinearMaterial material{{cMu, cLambda}};
    for (int e = 0; e < mesh.numTets(); ++e) {
      std::array<Vec3, 4> X;
      for (int k = 0; k < 4; ++k) X[size_t(k)] = mesh.V.row(mesh.T(e, k)).transpose();
      TetRest rest;
      if (!makeTetRest(X[0], X[1], X[2], X[3], rest)) continue;
      TetEvaluation k;
      evaluateTet(material, rest, X, TetEvalMode::Stiffness, k);
      for (int i = 0; i < 12; ++i)
        for (int j = 0; j < 12; ++j)
          t.emplace_back(3 * mesh.T(e, i / 3) + i % 3, 3 * mesh.T(e, j / 3) + j % 3,
                         k.stiffness(i, j));
    }
    m_rest.resize(3 * n, 3 * n);
    m_rest.setFromTriplets(t.begin(), t.end());
    m_rest.makeCompressed();
    m_diagonal.resize(size_t(3 * n));
    for (int c = 0; c < 3 * n; ++c)
      m_diagonal[size_t(c)] = int(&m_rest.coeffRef(c, c) - m_rest.valuePtr());
    m_matrix = m_rest;
    installCholmodAllocator();
    m_chol.analyzePattern(m_matrix);
    m_ok = false;
    m_held.assign(size_t(n), -1);  // no held set factorised yet
    m_r.resize(3 * n);
    m_z.resize(3 * n);
  }

  // Before each step: refactorises when the held nodes (inverse mass 0) changed. A failed
  // factorisation leaves the identity for the steps until the next change.
  void update(const btSoftBody& body) {
    if (m_rest.rows() == 0) return;
    bool changed = false;
    for (int i = 0; i < body.m_nodes.size(); ++i) {
      const char held = body.m_nodes[i].m_im == 0;
      changed |= held != m_held[size_t(i)];
      m_held[size_t(i)] = held;
    }
    if (!changed) return;
    std::copy_n(m_rest.valuePtr(), m_rest.nonZeros(), m_matrix.valuePtr());
    for (size_t i = 0; i < m_held.size(); ++i)
      if (m_held[i])
        for (int d = 0; d < 3; ++d) m_matrix.valuePtr()[m_diagonal[3 * i + size_t(d)]] *= 1e8;
    {
      const SerialOpenMpScope serial;
      m_chol.factorize(m_matrix);
    }
    m_ok = m_chol.info() == Eigen::Success;
  }

  void operator()(const TVStack& x, TVStack& b) override {
    count(&x);
    const int n = int(m_r.size()) / 3;
    if (m_ok && x.size() >= n) {
      for (int i = 0; i < n; ++i)
        for (int d = 0; d < 3; ++d) m_r(3 * i + d) = x[i][d];
      if (m_chol.solveInto(m_r, m_z)) {
        for (int i = 0; i < n; ++i) b[i].setValue(m_z(3 * i), m_z(3 * i + 1), m_z(3 * i + 2));
        for (int i = n; i < x.size(); ++i) b[i] = x[i];
        if (objective) objective->project(b);
        return;
      }
    }
    for (int i = 0; i < x.size(); ++i) b[i] = x[i];
  }
  void reinitialize(bool) override {}

  // Closes the step's last solve (call after each step).
  void finishStep() {
    finishSolve();
    if (m_stepCapped) ++cappedSteps;
    m_stepCapped = false;
  }

 private:
  void finishSolve() {
    if (m_inSolve && m_residualCalls > 0) {
      const long long k = m_residualCalls - 1;
      iterations += k;
      if (k >= cap) {
        ++cappedSolves;
        m_stepCapped = true;
      }
    }
    m_inSolve = false;
  }
  void count(const void* x) {
    if (m_learnResidual) {  // the second call ever: the residual's address
      m_residual = x;
      m_learnResidual = false;
    }
    if (x == m_residual) {
      ++m_residualCalls;
      return;
    }
    finishSolve();
    ++solves;
    m_inSolve = true;
    m_residualCalls = 0;
    if (!m_residual) m_learnResidual = true;
  }

  SparseMatrix m_rest, m_matrix;
  std::vector<int> m_diagonal;  // value index of each diagonal entry
  CholeskySolver m_chol;
  std::vector<char> m_held;  // per node: held at the last factorisation (-1: none yet)
  bool m_ok = false;         // a factor of P for m_held is ready
  VecX m_r, m_z;
  const void* m_residual = nullptr;
  bool m_learnResidual = false, m_inSolve = false, m_stepCapped = false;
  long long m_residualCalls = 0;
};

// btDeformableBodySolver keeps its Newton and Krylov iteration caps protected. The world hands it
// Bullet's mass preconditioner before every step (setPreconditioner); it keeps ours.
class ConfigurableDeformableSolver : public btDeformableBodySolver {
 public:
  CgPreconditioner preconditioner;

  void setLimits(int newton, int krylov, Real krylovTolerance) {
    m_maxNewtonIterations = newton;
    m_cg.m_maxIterations = krylov;
    m_cr.m_maxIterations = krylov;
    m_cg.m_tolerance = krylovTolerance;
    preconditioner.cap = krylov;
    preconditioner.objective = m_objective;
  }
  void setPreconditioner(int /*bullet's choice*/) override {
    m_objective->m_preconditioner = &preconditioner;
  }
};

}  // namespace

// The Bullet objects of one run, in construction order. The soft body and the forces are not
// owned by the world: the world goes first (it only refers to them), then they are deleted.
struct BulletDeformableModel::World {
  btSoftBodyRigidBodyCollisionConfiguration collision;
  btCollisionDispatcher dispatcher{&collision};
  btDbvtBroadphase broadphase;
  ConfigurableDeformableSolver deformableSolver;
  btDeformableMultiBodyConstraintSolver constraintSolver;
  std::unique_ptr<btDeformableMultiBodyDynamicsWorld> world;
  std::unique_ptr<btSoftBody> body;
  std::unique_ptr<btDeformableLagrangianForce> elastic;
  std::unique_ptr<btDeformableGravityForce> gravity;
  std::vector<btScalar> inverseMass;

  ~World() {
    if (world && body) world->removeSoftBody(body.get());
    world.reset();
  }
};

BulletDeformableModel::BulletDeformableModel() = default;
BulletDeformableModel::~BulletDeformableModel() = default;

void BulletDeformableModel::init(const ModelSetup& setup) {
  const DeformableConfig config = configFromParams(setup.params);
  const Organ& organ = setup.organ;
  TetMesh mesh;
  std::vector<int> surfaceNode(size_t(organ.surface.numVertices()));
  if (organ.volume) {
    mesh = *organ.volume;
    orientTetsPositive(mesh);
    // The loader's surface of a tet file is the boundary over the same nodes: match by position.
    surfaceNode = surfaceVertexNodes(organ, mesh.V);
  } else {
    mesh = surfaceVolumeCached(organ.surface, config.targetTets, organ.source, setup.cache);
    for (int i = 0; i < organ.surface.numVertices(); ++i) surfaceNode[size_t(i)] = i;
  }
  const std::vector<int> fixed = fixedNodeIndices(mesh.V, organ.fixed, organ.surface);
  init(mesh, std::move(surfaceNode), organ.material, config, setup.dt, fixed);
}

void BulletDeformableModel::init(const TetMesh& mesh, std::vector<int> surfaceNode,
                                 const Material& material, const DeformableConfig& config, Real dt,
                                 const std::vector<int>& fixedNodes) {
  if (mesh.numTets() < 1) throw InputError("", "", "bullet_deformable needs tetrahedra");
  if (!(dt > 0)) throw InputError("", "dt", "bullet_deformable needs a positive time step");
  m_config = config;
  m_dt = dt;
  m_material = material;
  m_mesh = mesh;
  m_surfaceNode = std::move(surfaceNode);
  m_fixed = fixedNodes;
  m_mass = lumpedMasses(mesh, material.density);
  m_boundary = tetBoundary(mesh).F;

  std::vector<std::array<int, 2>> edges;
  edges.reserve(size_t(mesh.numTets()) * 6);
  for (int t = 0; t < mesh.numTets(); ++t)
    for (int a = 0; a < 4; ++a)
      for (int b = a + 1; b < 4; ++b) {
        const int i = mesh.T(t, a), j = mesh.T(t, b);
        edges.push_back({std::min(i, j), std::max(i, j)});
      }
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  m_edges.resize(Eigen::Index(edges.size()), 2);
  for (size_t e = 0; e < edges.size(); ++e)
    m_edges.row(Eigen::Index(e)) << edges[e][0], edges[e][1];

  const Box box = boundingBox(mesh.V);
  m_tail.boxCenter = box.center();
  m_tail.boxHalf = 0.5 * tol::kDivergenceBoxFactor * box.size().maxCoeff();
  build();
}

void BulletDeformableModel::build() {
  m_world.reset();
  m_world = std::make_unique<World>();
  World& w = *m_world;
  w.constraintSolver.setDeformableSolver(&w.deformableSolver);
  w.world = std::make_unique<btDeformableMultiBodyDynamicsWorld>(
      &w.dispatcher, &w.broadphase, &w.constraintSolver, &w.collision, &w.deformableSolver);
  btDeformableMultiBodyDynamicsWorld& world = *w.world;
  world.setGravity(btVector3(0, 0, 0));
  world.getWorldInfo().m_gravity.setZero();

  const int n = m_mesh.numVertices();
  std::vector<btVector3> x(n);
  std::vector<btScalar> mass(n);
  for (int i = 0; i < n; ++i) {
    x[i] = btVector3(m_mesh.V(i, 0), m_mesh.V(i, 1), m_mesh.V(i, 2));
    mass[i] = m_mass(i);
  }
  for (int i : m_fixed) mass[i] = 0;  // Bullet: mass 0 = immovable
  w.inverseMass.resize(n);
  for (int i = 0; i < n; ++i) w.inverseMass[i] = mass[i] > 0 ? 1.0 / mass[i] : 0.0;

  w.body = std::make_unique<btSoftBody>(&world.getWorldInfo(), n, x.data(), mass.data());
  btSoftBody& b = *w.body;
  for (int t = 0; t < m_mesh.numTets(); ++t)
    b.appendTetra(m_mesh.T(t, 0), m_mesh.T(t, 1), m_mesh.T(t, 2), m_mesh.T(t, 3));
  for (Eigen::Index e = 0; e < m_edges.rows(); ++e)
    b.appendLink(m_edges(e, 0), m_edges(e, 1), nullptr, false);
  for (Eigen::Index f = 0; f < m_boundary.rows(); ++f)
    b.appendFace(m_boundary(f, 0), m_boundary(f, 1), m_boundary(f, 2));
  b.initializeDmInverse();
  btSoftBody::TetraScratch scratch;
  scratch.m_F.setIdentity();
  scratch.m_cofF.setIdentity();
  scratch.m_corotation.setIdentity();
  scratch.m_trace = 3;
  scratch.m_J = 1;
  b.m_tetraScratches.resize(b.m_tetras.size(), scratch);
  b.m_tetraScratchesTn.resize(b.m_tetras.size(), scratch);
  // Bullet's own collision stays off (no self collision); instruments are handled by the shared
  // contact response after the step (bullet_peer_step.h).
  b.m_cfg.collisions = 0;
  b.m_cfg.drag = 0;
  b.m_sleepingThreshold = 0;
  b.setActivationState(DISABLE_DEACTIVATION);
  world.addSoftBody(&b);

  const auto [mu, lambda] = lameParameters(m_material);
  if (m_config.force == ElasticForce::LinearElasticity) {
    w.elastic = std::make_unique<btDeformableLinearElasticityForce>(
        mu, lambda, m_config.dampingAlpha, m_config.dampingBeta);
  } else {
    // Smith, de Goes, Kim 2018, Sec. 3.4: mu' = 4/3 mu, lambda' = lambda + 5/6 mu make the stable
    // Neo-Hookean energy agree with linear elasticity (E, nu) at small strain.
    w.elastic = std::make_unique<btDeformableNeoHookeanForce>(
        4.0 / 3.0 * mu, lambda + 5.0 / 6.0 * mu, m_config.dampingBeta);
  }
  w.gravity = std::make_unique<btDeformableGravityForce>(btVector3(0, 0, 0));
  world.addForce(&b, w.elastic.get());
  world.addForce(&b, w.gravity.get());
  world.setImplicit(true);
  world.setLineSearch(false);
  // Bullet 3.24's implicit branch only solves correctly with the projection formulation (the
  // Lagrange-multiplier default leaves dv = 0: nothing moves); measured, see README.
  world.setUseProjection(true);
  w.deformableSolver.setLimits(m_config.newtonIterations, m_config.krylovIterations,
                               m_config.krylovTolerance);
  if (m_config.preconditioner == CgPreconditioning::RestFactor) {
    // Bullet's damping differentials: beta times its own elastic parameters (the Neo-Hookean's
    // mu', lambda'; the linear force's mu, lambda; its alpha M enters no differential).
    const bool neo = m_config.force == ElasticForce::NeoHookean;
    const Real muDamp = m_config.dampingBeta * (neo ? 4.0 / 3.0 * mu : mu);
    const Real lambdaDamp = m_config.dampingBeta * (neo ? lambda + 5.0 / 6.0 * mu : lambda);
    w.deformableSolver.preconditioner.build(m_mesh, m_mass, m_dt * m_dt * mu + m_dt * muDamp,
                                            m_dt * m_dt * lambda + m_dt * lambdaDamp);
  }

  m_tail.grasped.clear();
  m_graspForces.clear();
  m_graspForcesStale = false;
  bullet_common::copyNodes(b, m_x);
  m_surface.resize(Eigen::Index(m_surfaceNode.size()), 3);
  for (size_t i = 0; i < m_surfaceNode.size(); ++i)
    m_surface.row(Eigen::Index(i)) = m_x.row(m_surfaceNode[i]);
}

StepStatus BulletDeformableModel::step(const StepInput& in) {
  World& w = *m_world;
  btSoftBody& b = *w.body;
  const Real dt = in.dt > 0 ? in.dt : m_dt;
  const btVector3 g(in.gravity.x(), in.gravity.y(), in.gravity.z());
  w.gravity->m_gravity = g;
  w.world->getWorldInfo().m_gravity = g;

  bullet_common::beginBulletStep(b, w.inverseMass, in.grasps, m_surfaceNode, m_tail);
  for (const PointLoad& l : in.loads)
    for (size_t k = 0; k < l.vertices.size(); ++k) {
      btSoftBody::Node& node = b.m_nodes[m_surfaceNode[size_t(l.vertices[k])]];
      const Vec3 f = l.weights[k] * l.force;
      node.m_v += btVector3(f.x(), f.y(), f.z()) * (node.m_im * dt);
      node.m_vn = node.m_v;
    }
  for (const NodeGrasp& gr : m_tail.nodeGrasps)
    for (size_t k = 0; k < gr.nodes.size() && !gr.sliding(); ++k) {
      btSoftBody::Node& node = b.m_nodes[gr.nodes[k]];
      node.m_v = (btVector3(gr.targets(k, 0), gr.targets(k, 1), gr.targets(k, 2)) - node.m_x) / dt;
      node.m_vn = node.m_v;
    }
  bullet_common::aimSlidingNodes(b, m_tail, dt);  // free along their plate (bullet_peer_step.h)

  w.deformableSolver.preconditioner.update(b);  // the held set is final here
  w.world->stepSimulation(dt, 0, dt);           // exactly one internal step of length dt
  w.deformableSolver.preconditioner.finishStep();
  // Before finishBulletStep puts them back on the plate.
  m_slidingForces = bullet_common::slidingPlateForces(b, m_tail, in.grasps.size(), dt);
  m_stepGrasps = in.grasps.size();
  m_graspForcesStale = true;
  return bullet_common::finishBulletStep(b, in, dt, m_tail, m_x, m_phase, &m_surfaceNode,
                                         &m_surface);
}

std::vector<Vec3> BulletDeformableModel::graspForces() const {
  if (m_graspForcesStale) {
    computeGraspForces(m_stepGrasps);
    m_graspForcesStale = false;
  }
  return m_graspForces;
}

void BulletDeformableModel::computeGraspForces(std::size_t numGrasps) const {
  m_graspForces.assign(numGrasps, Vec3::Zero());
  if (numGrasps == 0) return;
  World& w = *m_world;
  btSoftBody& b = *w.body;
  // F of every tet at the final positions (grasped nodes on their targets); Bullet's scratches
  // are restored afterwards so that its next step starts from exactly what it left.
  const btAlignedObjectArray<btSoftBody::TetraScratch> saved = b.m_tetraScratches;
  b.updateDeformation();
  btAlignedObjectArray<btVector3> f;
  f.resize(b.m_nodes.size(), btVector3(0, 0, 0));
  w.elastic->addScaledForces(1.0, f);  // elastic + damping: f_i = -dPsi/dx_i - D v_i
  b.m_tetraScratches = saved;
  for (size_t g = 0; g < numGrasps && g < m_tail.nodeGrasps.size(); ++g) {
    const NodeGrasp& gr = m_tail.nodeGrasps[g];
    Vec3& sum = m_graspForces[g];
    if (gr.sliding()) {
      sum = m_slidingForces[g];
      // Nodes a bonded grasp also holds are kinematic: their elastic force, along the normal.
      const Vec3 n = gr.slideNormal.normalized();
      for (int node : gr.nodes)
        if (std::binary_search(m_tail.grasped.begin(), m_tail.grasped.end(), node)) {
          const btVector3& fi = f[b.m_nodes[node].index];
          sum += n * n.dot(Vec3(fi.x(), fi.y(), fi.z()));
        }
      continue;
    }
    for (int node : gr.nodes) {
      const btVector3& fi = f[b.m_nodes[node].index];
      sum += Vec3(fi.x(), fi.y(), fi.z());
    }
  }
}

void BulletDeformableModel::reset() {
  build();
}

NumericCounters BulletDeformableModel::numericCounters() const {
  const CgPreconditioner& p = m_world->deformableSolver.preconditioner;
  // A step whose CG stopped at its cap is not the backward Euler step: the harness makes the run
  // invalid on unconverged_steps.
  return {{"cg_solves", p.solves},
          {"cg_iterations", p.iterations},
          {"cg_capped_solves", p.cappedSolves},
          {"unconverged_steps", p.cappedSteps}};
}

Counts BulletDeformableModel::counts() const {
  const btSoftBody& b = *m_world->body;
  return {{"nodes", b.m_nodes.size()},
          {"tets", b.m_tetras.size()},
          {"links", b.m_links.size()},
          {"faces", b.m_faces.size()}};
}

}  // namespace deform::bullet_deformable
