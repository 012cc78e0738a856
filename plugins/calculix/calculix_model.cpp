#include "calculix_model.h"

#include "ccx_process.h"

#include <deform/geometry/organ_tets.h>
#include <deform/geometry/tet_embedding.h>
#include <deform/sdk/error.h>
#include <deform/sdk/mesh.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <memory>
#include <set>

namespace deform::calculix {

namespace {

class CalculixModel final : public Model {
 public:
  void init(const ModelSetup& setup) override {
    const ParamValues& p = setup.params;
    // First, before any meshing: a machine without CalculiX cannot run this model at all.
    m_ccx = findCcx();
    if (m_ccx.empty())
      throw UnsupportedError(
          "ccx not found (install CalculiX, e.g. Debian's calculix-ccx, or set DEFORM_CCX to "
          "the program)");
    m_timeout = p.real("timeout");
    m_maxMemory = p.real("max_memory") > 0 ? p.real("max_memory") : halfPhysicalMemory();
    m_increments.initial = p.real("initial_increment");
    m_increments.maximum = std::max(m_increments.initial, p.real("max_increment"));
    m_increments.minimum = std::min(m_increments.initial, p.real("min_increment"));
    m_increments.maxIncrements = int(p.integer("max_increments"));
    m_increments.residualTolerance = p.real("residual_tolerance");
    const Organ& organ = setup.organ;

    // The mesh reference_fem builds with the same parameters.
    OrganTets tets = organTets(organ, organTetOptions(p), setup.cache);
    m_surfaceNode = std::move(tets.surfaceNode);
    m_numElements = tets.mesh.numTets();
    m_cornerTets = tets.mesh.T;
    std::shared_ptr<QuadraticTetNodes> q;
    if (p.integer("element_order") == 2) {
      q = std::make_shared<QuadraticTetNodes>(addMidsideNodes(tets.mesh));
      m_surfaceLoad = std::make_unique<QuadraticSurfaceLoad>(
          tets.mesh, [q](int a, int b) { return q->edgeNode(a, b); });
      m_model.nodes = q->V;
      m_model.elements = q->elements.cast<int>();
    } else {
      m_model.nodes = tets.mesh.V;
      m_model.elements = tets.mesh.T;
    }
    // The nodes a grasp holds between its vertices, as reference_fem
    // (deform/geometry/organ_tets.h).
    std::function<int(int, int)> edgeNode;
    if (q) edgeNode = [q](int a, int b) { return q->edgeNode(a, b); };
    m_graspPatch = std::make_unique<GraspedPatchNodes>(organ.surface, m_surfaceNode, m_model.nodes,
                                                       tetBoundaryNodes(tets.mesh, edgeNode));
    m_model.material = p.choiceAs<CcxMaterial>(
        "material", {{"linear", CcxMaterial::Linear}, {"neo_hookean", CcxMaterial::NeoHookean}});
    m_model.young = organ.material.young;
    m_model.poisson = organ.material.poisson;
    m_model.density = organ.material.density;
    m_fixed = fixedNodeIndices(m_model.nodes, organ.fixed, organ.surface);
    m_model.fixedDofs.assign(size_t(m_model.nodes.rows()), {false, false, false});
    for (int n : m_fixed) m_model.fixedDofs[size_t(n)] = {true, true, true};
    // Roller boxes hold single axes (frictionless faces, plane strain); organTets never clips them.
    for (const auto& [node, axes] : rollerNodeAxes(m_model.nodes, organ.fixed))
      for (int k = 0; k < 3; ++k)
        if (axes & (1 << k)) m_model.fixedDofs[size_t(node)][size_t(k)] = true;
    m_modelDeck = ccxModelDeck(m_model);
    // rho * integral of each node's shape function: its share of a body force (straight-sided
    // tets: a P1 corner V/4; a P2 corner -V/20 and a midside node V/5).
    m_bodyShare.assign(size_t(m_model.nodes.rows()), 0.0);
    for (Eigen::Index t = 0; t < m_model.elements.rows(); ++t) {
      const auto x = [&](int a) { return m_model.nodes.row(m_model.elements(t, a)).transpose(); };
      const Real mass = m_model.density * std::abs(tetVolume(x(0), x(1), x(2), x(3)));
      for (int a = 0; a < m_model.elements.cols(); ++a)
        m_bodyShare[size_t(m_model.elements(t, a))] +=
            m_model.elements.cols() == 10 ? mass * (a < 4 ? -0.05 : 0.2) : 0.25 * mass;
    }
    m_restSurface = organ.surface.V;
    m_pinnedOutside = 0;
    for (int n : m_surfaceNode) m_pinnedOutside += n < 0;
    reset();
  }

  StepStatus step(const StepInput& in) override {
    const auto start = std::chrono::steady_clock::now();
    CcxLoads loads;
    loads.gravity = in.gravity;
    // Grasped surface vertices: prescribed displacements (a vertex with no node, or on a node of
    // the fixed region, stays where the support holds it, as in reference_fem).
    // A sliding plate (axis-aligned normal) prescribes the normal dof only.
    std::map<int, Vec3> held;
    std::map<std::pair<int, int>, Real> heldDof;
    // Per grasp (then per node constraint), the nodes it holds: its force is the sum of their
    // reactions.
    std::vector<std::set<int>> holds;
    for (const GraspInput& g : in.grasps) {
      std::set<int>& mine = holds.emplace_back();
      const int axis = slideAxis(g);
      if (g.sliding() && axis < 0)
        throw InputError("calculix", "grasp of tool " + std::to_string(g.tool),
                         "a sliding plate's normal must lie along x, y or z");
      const auto hold = [&](int node, const Vec3& target) {
        mine.insert(node);
        const Vec3 u = target - m_model.nodes.row(node).transpose();
        if (axis >= 0)
          heldDof[{node, axis}] = u(axis);
        else
          held[node] = u;
      };
      std::map<int, Eigen::Index> row;
      for (size_t k = 0; k < g.vertices.size(); ++k) {
        row[g.vertices[k]] = Eigen::Index(k);
        const int node = m_surfaceNode[size_t(g.vertices[k])];
        if (node < 0 || isFixed(node)) continue;
        hold(node, g.targets.row(Eigen::Index(k)).transpose());
      }
      // The nodes on the triangles between the grasped vertices, at interpolated targets.
      for (const GraspedPatchNodes::Held& h : m_graspPatch->held(g.vertices)) {
        if (isFixed(h.node)) continue;
        Vec3 target = Vec3::Zero();
        for (int k = 0; k < 3; ++k)
          target += h.weights(k) * g.targets.row(row.at(h.vertices[size_t(k)])).transpose();
        hold(h.node, target);
      }
    }
    for (const NodeGrasp& g : in.nodeConstraints) {
      std::set<int>& mine = holds.emplace_back();
      for (size_t k = 0; k < g.nodes.size(); ++k)
        if (!isFixed(g.nodes[k])) {
          mine.insert(g.nodes[k]);
          held[g.nodes[k]] = g.targets.row(Eigen::Index(k)).transpose() -
                             m_model.nodes.row(g.nodes[k]).transpose();
        }
    }
    loads.displacements.assign(held.begin(), held.end());
    loads.dofDisplacements.assign(heldDof.begin(), heldDof.end());
    for (const PointLoad& l : in.loads) {
      std::vector<std::pair<int, Vec3>> shares;
      for (size_t k = 0; k < l.vertices.size(); ++k) {
        const int node = m_surfaceNode[size_t(l.vertices[k])];
        if (node >= 0) shares.emplace_back(node, l.weights[k] * l.force);
      }
      // C3D10: onto the quadratic faces, as reference_fem does (deform/geometry/organ_tets.h).
      if (m_surfaceLoad) shares = m_surfaceLoad->spread(shares);
      loads.forces.insert(loads.forces.end(), shares.begin(), shares.end());
    }

    const CcxRun run = runCcx(m_ccx, m_modelDeck + ccxStepDeck(m_model, loads, m_increments),
                              m_timeout, 1, m_maxMemory);
    ++m_runs;
    m_wallMs += 1e3 * run.wallSeconds;
    m_cpuMs += 1e3 * run.cpuSeconds;
    if (!run.ok) throw std::runtime_error("ccx: " + run.message);
    double time = 0;
    const MatX3 u = ccxLastDisplacements(run.dat, int(m_model.nodes.rows()), time);
    if (std::abs(time - 1.0) > 1e-6)
      throw std::runtime_error("ccx: the step stopped at " + std::to_string(time) + " of its load");
    // The force on each grasp's tool: minus the reactions at the nodes it holds, as
    // reference_fem's minus the energy gradient there. ccx's RF at a prescribed dof is the
    // internal force alone (loads and body forces there are not in it), so the node's external
    // force is added back on its prescribed dofs: -(RF - f_ext). A sliding plate's free dofs
    // carry no reaction (to ccx's tolerance).
    double forceTime = 0;
    const MatX3 rf = ccxLastReactionForces(run.dat, int(m_model.nodes.rows()), forceTime);
    std::map<int, Vec3> external;
    for (const auto& [node, f] : loads.forces) {
      auto it = external.emplace(node, Vec3::Zero()).first;
      it->second += f;
    }
    m_graspForces.clear();
    for (const std::set<int>& nodes : holds) {
      Vec3 f = Vec3::Zero();
      for (int n : nodes) {
        Vec3 fn = m_bodyShare[size_t(n)] * in.gravity;
        if (const auto it = external.find(n); it != external.end()) fn += it->second;
        if (!held.count(n))  // a sliding plate's node: its normal dof alone is prescribed
          for (int k = 0; k < 3; ++k)
            if (!heldDof.count({n, k})) fn(k) = 0;
        f += fn - rf.row(n).transpose();
      }
      m_graspForces.push_back(f);
    }
    m_nodes = m_model.nodes + u;
    updateSurface();
    m_phase["solve"] =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    m_phase["ccx_wall"] = 1e3 * run.wallSeconds;
    m_phase["ccx_cpu"] = 1e3 * run.cpuSeconds;
    return m_nodes.allFinite() ? StepStatus::Ok : StepStatus::Diverged;
  }

  const MatX3& nodes() const override { return m_nodes; }
  std::vector<Vec3> graspForces() const override { return m_graspForces; }
  const MatX3& surface() const override { return m_surface; }

  void reset() override {
    m_nodes = m_model.nodes;
    m_runs = 0;
    m_graspForces.clear();
    m_wallMs = m_cpuMs = 0;
    m_phase.clear();
    updateSurface();
  }

  Counts counts() const override {
    // Counted as reference_fem counts them: a surface vertex that the conforming clip removed is
    // an isolated clamped node (no element, at rest), among the nodes and the fixed nodes.
    return {{"nodes", (long long)m_model.nodes.rows() + m_pinnedOutside},
            {"elements", m_numElements},
            {"fixed_nodes", (long long)m_fixed.size() + m_pinnedOutside},
            {"isolated_clamped_nodes", m_pinnedOutside}};
  }
  PhaseTimes phaseTimes() const override { return m_phase; }

  /// 10-node tets: the midside node of every edge whose two corners are held follows them (the
  /// mean of their displacements: straight sides), as reference_fem does, so that a held patch
  /// (a bonded plate) moves as a whole.

  // Markers: barycentric coordinates in the containing corner tet
  // (deform/geometry/tet_embedding.h), through the quadratic shape functions when the elements have
  // 10 nodes.
  void bindMarkers(const MatX3& rest) override {
    m_markerEmbedding = embedInTets(m_model.nodes, m_cornerTets, rest);
  }
  MatX3 markers() const override {
    if (m_model.elements.cols() == 10)
      return embeddedPositionsQuadratic(m_markerEmbedding, m_nodes,
                                        [this](int t, int a) { return m_model.elements(t, a); });
    return embeddedPositions(m_markerEmbedding, m_nodes, m_cornerTets);
  }

  NumericCounters numericCounters() const override {
    // Totals over the run; CPU time is the ccx child processes' (user + system, their rusage).
    return {{"ccx_runs", m_runs},
            {"ccx_wall_ms", std::llround(m_wallMs)},
            {"ccx_cpu_ms", std::llround(m_cpuMs)}};
  }

 private:
  bool isFixed(int node) const {
    const auto& d = m_model.fixedDofs[size_t(node)];
    return d[0] && d[1] && d[2];
  }

  void updateSurface() {
    m_surface.resize(Eigen::Index(m_surfaceNode.size()), 3);
    for (size_t i = 0; i < m_surfaceNode.size(); ++i) {
      const int n = m_surfaceNode[i];
      if (n < 0 || isFixed(n))
        m_surface.row(Eigen::Index(i)) = m_restSurface.row(Eigen::Index(i));
      else
        m_surface.row(Eigen::Index(i)) = m_nodes.row(n);
    }
  }

  std::string m_ccx;
  double m_timeout = 3600;
  double m_maxMemory = 0;  ///< bytes, the ccx child's RLIMIT_AS
  CcxIncrements m_increments;
  CcxModel m_model;
  std::string m_modelDeck;
  long long m_numElements = 0;
  std::unique_ptr<QuadraticSurfaceLoad> m_surfaceLoad;  ///< C3D10: loads onto the quadratic faces
  std::unique_ptr<GraspedPatchNodes> m_graspPatch;      ///< nodes between a grasp's vertices
  MatX4i m_cornerTets;                                  ///< the corner tets (marker embedding)
  TetEmbedding m_markerEmbedding;
  std::vector<int> m_fixed;
  std::vector<int> m_surfaceNode;  ///< surface vertex -> node; -1: inside a fixed box, no node
  MatX3 m_restSurface;
  long long m_pinnedOutside = 0;
  MatX3 m_nodes, m_surface;
  std::vector<Vec3> m_graspForces;  ///< N, per grasp then node constraint, of the last step
  std::vector<Real> m_bodyShare;    ///< kg: rho times the integral of each node's shape function
  long long m_runs = 0;
  double m_wallMs = 0, m_cpuMs = 0;
  PhaseTimes m_phase;
};

}  // namespace

std::unique_ptr<Model> makeCalculixModel() {
  return std::make_unique<CalculixModel>();
}

}  // namespace deform::calculix
