// The reference_fem model: the thin model class around the kernels in fem_solver.h (its
// parameters and their config are in plugin.cpp; README.md gives the method and the reasons
// behind each choice).
#include "reference_fem_model.h"

#include <deform/geometry/mesh_check.h>
#include <deform/geometry/organ_tets.h>
#include <deform/geometry/tet_embedding.h>
#include <deform/kernels/cholesky_solver.h>
#include <deform/sdk/contact.h>

#include <algorithm>
#include <chrono>
#include <map>
#include <memory>

namespace deform::reference_fem {

namespace {

class ReferenceFemModel final : public Model {
 public:
  void init(const ModelSetup& setup) override {
    const ReferenceFemConfig config = configFromParams(setup.params);
    m_solveKind = config.solve;
    const MaterialModel model = config.material;
    const ElementOrder order = config.order;
    const VolumetricFormulation volumetric =
        resolveVolumetricFormulation(config.volumetric, model, order, setup.organ.material.poisson);
    m_options = config.options;
    // Measured (docs/notes/reference_fem-history.md): the float copy takes 8-13% off the P2 liver
    // solves at nu 0.3, the half copy another 10-30% (where the CPU converts halves in hardware);
    // under mean dilatation (nu >= 0.45) the CG paths the float copy changes cost as many
    // factorisations as it saves.
    using Precision = CholeskySolver::Precision;
    if (config.preconditioner == "float16") {
      m_options.preconditionerCopy = Precision::Float16;
    } else if (config.preconditioner == "float32") {
      m_options.preconditionerCopy = Precision::Float32;
    } else if (config.preconditioner == "auto" &&
               volumetric != VolumetricFormulation::MeanDilatation) {
      m_options.preconditionerCopy =
          CholeskySolver::halfIsFast() ? Precision::Float16 : Precision::Float32;
    } else {
      m_options.preconditionerCopy.reset();  // float64, or auto under mean dilatation
    }
    m_alpha = config.rayleighAlpha;
    m_beta = config.rayleighBeta;
    m_dt = setup.dt;
    const Organ& organ = setup.organ;
    m_surfaceF = organ.surface.F;
    // A rest surface that already passes through itself is not judged (as the harness does).
    m_stopAtFold = config.stopAtFold && m_solveKind == SolveKind::QuasiStatic &&
                   findSelfIntersections(organ.surface, 1).ok();
    OrganTets tets = organTets(organ, config.mesh, setup.cache);
    TetMesh mesh = std::move(tets.mesh);
    m_surfaceNode = std::move(tets.surfaceNode);
    m_restSurface = organ.surface.V;
    m_meshedNodes = mesh.numVertices();
    const std::vector<int> isolated = addClampedSurfaceNodes(organ, m_surfaceNode, mesh);
    m_isolatedNodes = (long long)isolated.size();
    // The organ's triangles as node rows: the contact proxy besides the nodes themselves (the
    // surface the harness draws and checks against instruments). With a conforming mesh the
    // triangles with a vertex inside a fixed box (an isolated node) are left out: they are
    // clamped there.
    m_contactF.resize(organ.surface.F.rows(), 3);
    Eigen::Index rows = 0;
    for (Eigen::Index f = 0; f < organ.surface.F.rows(); ++f) {
      bool meshed = true;
      for (int k = 0; k < 3; ++k) {
        m_contactF(rows, k) = m_surfaceNode.at(size_t(organ.surface.F(f, k)));
        meshed = meshed && m_contactF(rows, k) < m_meshedNodes;
      }
      rows += meshed;
    }
    m_contactF.conservativeResize(rows, 3);
    m_system =
        std::make_unique<FemSystem>(std::move(mesh), organ.material, model, order, volumetric);
    m_surfaceLoad.reset();
    if (m_system->order() == ElementOrder::Quadratic) {
      const FemSystem* system = m_system.get();
      m_surfaceLoad = std::make_unique<QuadraticSurfaceLoad>(
          system->rest(), [system](int a, int b) { return system->edgeNode(a, b); });
    }
    {  // the nodes a grasp holds on the triangles and edges between its vertices (organ_tets.h)
      const FemSystem* system = m_system.get();
      m_graspPatch = std::make_unique<GraspedPatchNodes>(
          organ.surface, m_surfaceNode, system->rest().V,
          tetBoundaryNodes(system->rest(),
                           [system](int a, int b) { return system->edgeNode(a, b); }));
    }
    m_fixed = fixedNodeIndices(m_system->rest().V, organ.fixed, organ.surface);
    m_fixed.insert(m_fixed.end(), isolated.begin(), isolated.end());
    std::sort(m_fixed.begin(), m_fixed.end());
    m_fixed.erase(std::unique(m_fixed.begin(), m_fixed.end()), m_fixed.end());
    // A pinned vertex reports its rest position exactly (a vertex snapped onto a box face by
    // clipSurfaceByBoxes is a node a hair's breadth from it).
    m_isFixed.assign(size_t(m_system->numNodes()), 0);
    for (int n : m_fixed) m_isFixed[size_t(n)] = 1;
    // Roller supports: single dofs held at rest (the boxes are never clipped away: their nodes
    // stay free along the other axes).
    m_rollerDofs.clear();
    for (const auto& [node, axes] : rollerNodeAxes(m_system->rest().V, organ.fixed)) {
      if (m_isFixed[size_t(node)]) continue;
      for (int k = 0; k < 3; ++k)
        if (axes & (1 << k)) m_rollerDofs.push_back(3 * node + k);
    }
    reset();
  }

  StepStatus step(const StepInput& in) override {
    if (!in.contact) return solveOnce(in);
    // Contact as prescribed positions (Dirichlet) on the penetrating nodes. Quasi-static: along
    // the instruments' path since the last solve in sub-steps of half their thinnest radius, the
    // active set grown over up to 4 solves each; a dynamic step cannot be re-solved: 1 solve.
    ContactProxy proxy;
    proxy.nodes = &m_nodes;
    proxy.faces = &m_contactF;
    ContactConstraintSolver solver;
    solver.solve = [this](const StepInput& x) { return solveOnce(x); };
    solver.graspForces = [this] { return m_graspForces; };
    // A contact node's force on the instrument: minus the gradient there, as graspForces'.
    solver.nodeReaction = [this](int n) -> Vec3 {
      return -m_solver->lastGradient().segment<3>(3 * n);
    };
    solver.immovable = m_fixed;
    const bool quasiStatic = m_solveKind == SolveKind::QuasiStatic;
    solver.maxRounds = quasiStatic ? 4 : 1;
    solver.followInstrumentPath = quasiStatic;
    solver.maxStepFraction = 0.2;
    return solveWithContactConstraints(*in.contact, proxy, in, solver);
  }

  StepStatus solveOnce(const StepInput& in) {
    const auto start = std::chrono::steady_clock::now();
    LoadCase lc;
    lc.fixedNodes = m_fixed;
    lc.fixedDofs = m_rollerDofs;
    lc.gravity = in.gravity;
    std::vector<char> fixed(size_t(m_system->numNodes()), 0);
    for (int n : m_fixed) fixed[size_t(n)] = 1;
    // Every organ surface vertex is a node of the tet mesh (J a selection); those inside a
    // fixed box are pinned (fixed wins over a grasp; the support takes their load share).
    // With them, the nodes on the triangles and edges between the grasped vertices, at the
    // interpolated targets (the same held surface as every model's).
    // A sliding plate holds the same nodes along its normal axis only (the dof at the target's
    // coordinate), the tangential dofs free.
    std::vector<std::vector<int>> patchNodes(in.grasps.size());
    for (size_t gi = 0; gi < in.grasps.size(); ++gi) {
      const GraspInput& g = in.grasps[gi];
      const int axis = slideAxis(g);
      if (g.sliding() && axis < 0)
        throw InputError("reference_fem", "grasp of tool " + std::to_string(g.tool),
                         "a sliding plate's normal must lie along x, y or z");
      const auto hold = [&](int node, const Vec3& target) {
        if (axis >= 0) {
          lc.prescribedDofs.emplace_back(3 * node + axis, target[axis]);
          return;
        }
        lc.prescribedNodes.push_back(node);
        lc.targets.conservativeResize(Eigen::Index(lc.prescribedNodes.size()), 3);
        lc.targets.bottomRows(1) = target.transpose();
      };
      std::map<int, Eigen::Index> row;
      for (size_t k = 0; k < g.vertices.size(); ++k) {
        row[g.vertices[k]] = Eigen::Index(k);
        const int node = m_surfaceNode[size_t(g.vertices[k])];
        if (fixed[size_t(node)]) continue;
        hold(node, g.targets.row(Eigen::Index(k)).transpose());
      }
      for (const GraspedPatchNodes::Held& h : m_graspPatch->held(g.vertices)) {
        if (fixed[size_t(h.node)]) continue;
        Vec3 target = Vec3::Zero();
        for (int k = 0; k < 3; ++k)
          target += h.weights(k) * g.targets.row(row.at(h.vertices[size_t(k)])).transpose();
        hold(h.node, target);
        patchNodes[gi].push_back(h.node);
      }
    }
    for (const NodeGrasp& g : in.nodeConstraints)  // contact, on nodes
      for (size_t k = 0; k < g.nodes.size(); ++k) {
        lc.prescribedNodes.push_back(g.nodes[k]);
        lc.targets.conservativeResize(Eigen::Index(lc.prescribedNodes.size()), 3);
        lc.targets.bottomRows(1) = g.targets.row(Eigen::Index(k));
      }
    for (const PointLoad& l : in.loads) {
      std::vector<std::pair<int, Vec3>> shares;
      for (size_t k = 0; k < l.vertices.size(); ++k) {
        // A load share on an isolated clamped node goes to the support (it is dropped).
        const int node = m_surfaceNode[size_t(l.vertices[k])];
        if (node < m_meshedNodes) shares.emplace_back(node, l.weights[k] * l.force);
      }
      if (m_surfaceLoad) shares = m_surfaceLoad->spread(shares);  // P2: onto the quadratic faces
      lc.nodeForces.insert(lc.nodeForces.end(), shares.begin(), shares.end());
    }

    SolveReport rep;
    if (m_solveKind == SolveKind::QuasiStatic) {
      SolveOptions options = m_options;
      if (m_stopAtFold) {
        // The surface vertices whose node is held: fixed, grasped, in contact.
        std::vector<char> heldNode(m_isFixed), held(m_surfaceNode.size());
        for (int n : lc.prescribedNodes) heldNode[size_t(n)] = 1;
        for (const auto& dof : lc.prescribedDofs) heldNode[size_t(dof.first / 3)] = 1;
        for (size_t v = 0; v < held.size(); ++v) held[v] = heldNode[size_t(m_surfaceNode[v])];
        options.admissible = [this, nearHeld = heldRegionAndEdge(m_surfaceF, held)](const VecX& x) {
          return freeSelfIntersections(x, nearHeld) == 0;
        };
      }
      rep = m_solver->solveStatic(lc, m_x, m_fPrev, options);
      m_stoppedAtFold += rep.stoppedEarly;
      // The next step starts from this state: in equilibrium with the forces it reached.
      m_fPrev = m_system->externalForce(lc);
    } else {
      rep =
          m_solver->stepDynamic(lc, in.dt > 0 ? in.dt : m_dt, m_alpha, m_beta, m_x, m_v, m_options);
    }
    m_lastIterations = rep.newtonIterations;
    m_lastLoadSteps = rep.loadSteps;
    m_spdFallbacks += rep.spdFallbacks;
    m_projectedSteps += rep.projectedSteps;
    m_newtonIterations += rep.newtonIterations;
    m_factorizations += rep.factorizations;
    m_pcgIterations += rep.pcgIterations;
    m_failedLoadSteps += rep.failedLoadSteps;
    m_outOfBudget += rep.outOfBudget;
    if (!rep.converged) ++m_unconverged;

    m_graspForces.clear();
    for (size_t gi = 0; gi < in.grasps.size(); ++gi) {
      Vec3 f = Vec3::Zero();
      for (int v : in.grasps[gi].vertices) {
        const int n = m_surfaceNode[size_t(v)];
        if (!fixed[size_t(n)]) f -= m_solver->lastGradient().segment<3>(3 * n);
      }
      for (int n : patchNodes[gi]) f -= m_solver->lastGradient().segment<3>(3 * n);
      m_graspForces.push_back(f);
    }
    for (const NodeGrasp& g : in.nodeConstraints) {
      Vec3 f = Vec3::Zero();
      for (int n : g.nodes)
        if (!fixed[size_t(n)]) f -= m_solver->lastGradient().segment<3>(3 * n);
      m_graspForces.push_back(f);
    }
    updatePositions();
    m_phase["solve"] =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    // Where the solve's time went (SolveReport's wall-time breakdown), ms.
    m_phase["solve_analyze"] = 1e3 * rep.analyzeSeconds;
    m_phase["solve_assembly"] = 1e3 * rep.assemblySeconds;
    m_phase["solve_factor"] = 1e3 * rep.factorSeconds;
    m_phase["solve_triangular"] = 1e3 * rep.solveSeconds;
    m_phase["solve_objective"] = 1e3 * rep.objectiveSeconds;
    return m_x.allFinite() ? StepStatus::Ok : StepStatus::Diverged;
  }

  const MatX3& nodes() const override { return m_nodes; }
  const MatX3& surface() const override { return m_surface; }

  void reset() override {
    m_x = m_system->restPositions();
    m_v = VecX::Zero(m_x.size());
    m_fPrev = VecX::Zero(m_x.size());
    m_solver = std::make_unique<EquilibriumSolver>(*m_system);
    m_graspForces.clear();
    m_unconverged = m_spdFallbacks = m_projectedSteps = 0;
    m_newtonIterations = m_factorizations = m_pcgIterations = m_failedLoadSteps = 0;
    m_stoppedAtFold = m_outOfBudget = 0;
    m_lastIterations = m_lastLoadSteps = 0;
    m_phase.clear();
    updatePositions();
  }

  Counts counts() const override {
    Counts c = {{"nodes", m_system->numNodes()},
                {"elements", m_system->rest().numTets()},
                {"fixed_nodes", (long long)m_fixed.size()},
                {"isolated_clamped_nodes", m_isolatedNodes}};
    if (!m_rollerDofs.empty()) c["roller_dofs"] = (long long)m_rollerDofs.size();
    return c;
  }
  PhaseTimes phaseTimes() const override { return m_phase; }
  NumericCounters numericCounters() const override {
    const bool md = m_system->volumetric() == VolumetricFormulation::MeanDilatation;
    return {{"degenerate_elements", m_system->degenerateElements()},
            {"mean_dilatation_elements", md ? m_system->rest().numTets() : 0},
            {"unconverged_steps", m_unconverged},
            {"spd_fallbacks", m_spdFallbacks},
            {"projected_steps", m_projectedSteps},
            {"newton_iterations_last_step", m_lastIterations},
            {"load_steps_last_step", m_lastLoadSteps},
            {"newton_iterations", m_newtonIterations},
            {"factorizations", m_factorizations},
            {"pcg_iterations", m_pcgIterations},
            {"failed_load_steps", m_failedLoadSteps},
            {"solves_stopped_at_fold", m_stoppedAtFold},
            {"solves_out_of_budget", m_outOfBudget}};
  }
  std::vector<Vec3> graspForces() const override { return m_graspForces; }

  // Markers: barycentric coordinates in the containing corner tet
  // (deform/geometry/tet_embedding.h), through the quadratic shape functions for P2 elements.
  void bindMarkers(const MatX3& rest) override {
    m_markerEmbedding = embedInTets(m_system->rest().V, m_system->rest().T, rest);
  }
  MatX3 markers() const override {
    if (m_system->order() == ElementOrder::Quadratic)
      return embeddedPositionsQuadratic(
          m_markerEmbedding, m_nodes, [this](int t, int a) { return m_system->elementNode(t, a); });
    return embeddedPositions(m_markerEmbedding, m_nodes, m_system->rest().T);
  }

 private:
  /// Every surface vertex becomes a node: the vertices the conforming clip left without one
  /// (-1 in surfaceNode: inside a fixed box, or snapped onto its face, outside the meshed solid)
  /// are appended to `mesh` as nodes of no tet. Returns them; the caller pins them (they stay at
  /// rest with the clamped material around them).
  static std::vector<int> addClampedSurfaceNodes(const Organ& organ, std::vector<int>& surfaceNode,
                                                 TetMesh& mesh) {
    std::vector<int> added;
    for (int n : surfaceNode) added.resize(added.size() + (n < 0));
    if (added.empty()) return added;
    Eigen::Index next = mesh.V.rows();
    mesh.V.conservativeResize(next + Eigen::Index(added.size()), 3);
    added.clear();
    for (size_t v = 0; v < surfaceNode.size(); ++v) {
      if (surfaceNode[v] >= 0) continue;
      mesh.V.row(next) = organ.surface.V.row(Eigen::Index(v));
      added.push_back(int(next));
      surfaceNode[v] = int(next++);
    }
    return added;
  }

  /// Pairs of the organ's triangles at state x that intersect away from the held nodes and
  /// their neighbours (nearHeld: heldRegionAndEdge of the surface vertices whose node is held).
  long long freeSelfIntersections(const VecX& x, const std::vector<char>& nearHeld) const {
    SurfaceMesh surface;
    surface.F = m_surfaceF;
    surface.V.resize(Eigen::Index(m_surfaceNode.size()), 3);
    for (size_t i = 0; i < m_surfaceNode.size(); ++i)
      surface.V.row(Eigen::Index(i)) = x.segment<3>(3 * m_surfaceNode[i]).transpose();
    return countSelfIntersections(surface, nearHeld).free;
  }

  void updatePositions() {
    const int n = m_system->numNodes();
    m_nodes = Eigen::Map<const MatX3>(m_x.data(), n, 3);
    m_surface.resize(Eigen::Index(m_surfaceNode.size()), 3);
    for (size_t i = 0; i < m_surfaceNode.size(); ++i)
      if (m_isFixed[size_t(m_surfaceNode[i])])
        m_surface.row(Eigen::Index(i)) = m_restSurface.row(Eigen::Index(i));
      else
        m_surface.row(Eigen::Index(i)) = m_x.segment<3>(3 * m_surfaceNode[i]).transpose();
  }

  SolveKind m_solveKind = SolveKind::QuasiStatic;
  SolveOptions m_options;
  Real m_alpha = 0, m_beta = 0, m_dt = 1e-3;
  std::unique_ptr<FemSystem> m_system;
  std::unique_ptr<EquilibriumSolver> m_solver;
  std::vector<int> m_fixed;
  std::vector<int> m_rollerDofs;   ///< 3 node + axis held at rest by roller boxes
  std::vector<int> m_surfaceNode;  ///< surface vertex -> node
  MatX3 m_restSurface;             ///< reported for the pinned vertices
  std::vector<char> m_isFixed;     ///< per node: pinned by the fixed region
  std::unique_ptr<QuadraticSurfaceLoad> m_surfaceLoad;  ///< P2: loads onto the quadratic faces
  std::unique_ptr<GraspedPatchNodes> m_graspPatch;      ///< nodes between a grasp's vertices
  int m_meshedNodes = 0;          ///< corner nodes of the tets; isolated clamped ones follow
  long long m_isolatedNodes = 0;  ///< surface vertices inside a clipped-off fixed box
  MatX3i m_contactF;              ///< organ triangles as node rows (contact proxy)
  MatX3i m_surfaceF;              ///< the organ's triangles (surface vertex rows)
  bool m_stopAtFold = false;      ///< SolveOptions::admissible checks the surface
  VecX m_x, m_v, m_fPrev;
  MatX3 m_nodes, m_surface;
  std::vector<Vec3> m_graspForces;
  TetEmbedding m_markerEmbedding;
  long long m_unconverged = 0, m_spdFallbacks = 0, m_projectedSteps = 0, m_lastIterations = 0,
            m_lastLoadSteps = 0;
  long long m_newtonIterations = 0, m_factorizations = 0, m_pcgIterations = 0,
            m_failedLoadSteps = 0, m_stoppedAtFold = 0, m_outOfBudget = 0;  ///< totals over the run
  PhaseTimes m_phase;
};

}  // namespace

std::unique_ptr<Model> makeReferenceFemModel() {
  return std::make_unique<ReferenceFemModel>();
}

}  // namespace deform::reference_fem
