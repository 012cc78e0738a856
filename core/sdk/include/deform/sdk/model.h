// deformbench SDK: the model interface every plugin implements, and the interaction data the
// harness hands it each step. Interaction is defined on the organ's surface and resolved
// identically for every model by the harness (see interaction.h, contract v2):
//  - a grasp names the organ surface vertices it holds and their target positions each step;
//  - a point force arrives as per-surface-vertex forces (a traction over a patch, spread with
//    consistent area weights);
//  - a fixed region pins every model node inside it.
// Each model maps these through its own surface mapping (SOFA's Mapping): its surface points are
// x_s = J q (J: identity, embedding weights, skinning, ...), the grasped points follow their
// targets through J, and surface forces reach the model's degrees of freedom as J^T f.
#pragma once

#include <deform/sdk/cache.h>
#include <deform/sdk/error.h>
#include <deform/sdk/mesh.h>
#include <deform/sdk/params.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace deform {

class ContactWorld;

/// Isotropic material, SI.
struct Material {
  Real young = 5500.0;    ///< Young's modulus E, Pa
  Real poisson = 0.3;     ///< Poisson ratio nu, dimensionless, in (-1, 0.5)
  Real density = 1000.0;  ///< kg/m^3
};

/// A roller support: the model nodes inside `box` are held at rest along the axes whose bit is
/// set in `axes` (1 x, 2 y, 4 z) and free along the others: a frictionless wall, a symmetry plane,
/// a plane-strain face. Only models with the "roller_support" capability receive scenes with
/// rollers (the others are reported unsupported, never pinned fully in silence).
struct RollerBox {
  Box box;
  int axes = 7;
};

/// Region whose model nodes are pinned: nodes inside any box, and the model node nearest to each
/// listed surface vertex (identity-mapped models pin exactly those vertices); plus roller boxes,
/// which hold some axes only (rollerNodeAxes).
struct FixedRegion {
  std::vector<Box> boxes;
  std::vector<int> surfaceVertices;
  std::vector<RollerBox> rollers;
  bool empty() const { return boxes.empty() && surfaceVertices.empty() && rollers.empty(); }
};

/// The organ as the scene defines it, in metres, validated (or repaired when the scene asked).
struct Organ {
  std::string source;             ///< file path or "phantom:NAME"
  SurfaceMesh surface;            ///< rest surface; every model reports positions of these vertices
  std::optional<TetMesh> volume;  ///< when the mesh file had tetrahedra (surface = its boundary)
  Material material;
  FixedRegion fixed;
};

/// Which of a model's own nodes are pinned by the fixed region. nodes: #N by 3 rest positions.
/// restSurface: the organ's rest surface (to resolve listed surface vertices). Sorted, unique.
std::vector<int> fixedNodeIndices(const MatX3& nodes, const FixedRegion& region,
                                  const SurfaceMesh& restSurface);

/// The nodes the region's roller boxes hold and along which axes: (node, axis bits as in
/// RollerBox, the union over the boxes containing it), sorted by node. Nodes that
/// fixedNodeIndices pins fully are included too; a model skips them.
std::vector<std::pair<int, int>> rollerNodeAxes(const MatX3& nodes, const FixedRegion& region);

/// What init() receives. References stay valid for the model's lifetime.
struct ModelSetup {
  const Organ& organ;
  const ParamValues& params;
  Cache& cache;
  Real dt;       ///< s, the scene's time step (constant for a run)
  Vec3 gravity;  ///< m/s^2
};

/// A grasp in force during a step: the organ surface vertices the harness picked when the jaws
/// closed (every rest-surface vertex within the jaw radius of the closing point, at least the
/// nearest one), and the positions (#vertices by 3, m) they must reach at the end of the step:
/// their positions at the closing, translated with the tool. They stay held until the jaws open.
/// The model makes its surface points follow these targets through its own surface mapping; the
/// harness reports how well it did (grasp_residual_m).
/// A sliding plate (scene "plates" with "contact": "sliding") arrives as a grasp with a non-zero
/// `slideNormal`: only the held vertices' displacement along that unit normal is prescribed
/// (n . x = n . target), the tangential components are free (a frictionless platen). Only models
/// with the "sliding" capability receive such grasps; the others are reported unsupported, so a
/// model without it may treat every grasp as bonded.
struct GraspInput {
  int tool = 0;               ///< index of the tool in the scene
  std::vector<int> vertices;  ///< organ surface vertex indices, sorted, unique
  MatX3 targets;              ///< #vertices by 3
  /// Zero for an ordinary (bonded) grasp; a unit vector for a sliding plate: the plate's normal.
  /// The scene restricts it to a coordinate axis for now (models may rely on that and say so).
  Vec3 slideNormal = Vec3::Zero();
  bool sliding() const { return slideNormal.squaredNorm() > 0; }
};

/// The coordinate axis (0 x, 1 y, 2 z) a sliding grasp's normal lies along, or -1 when it is not
/// axis-aligned (or the grasp is bonded): for models that hold single coordinates.
inline int slideAxis(const GraspInput& g) {
  if (!g.sliding()) return -1;
  for (int a = 0; a < 3; ++a)
    if (std::abs(g.slideNormal[a]) == 1 && g.slideNormal.squaredNorm() == 1) return a;
  return -1;
}

/// The surface vertices held by any of the grasps, sorted and without repeats, written to out
/// (its capacity is kept, so a model can call this every step without allocating).
inline void graspedVertexSet(const std::vector<GraspInput>& grasps, std::vector<int>& out) {
  out.clear();
  for (const GraspInput& g : grasps) out.insert(out.end(), g.vertices.begin(), g.vertices.end());
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
}

/// A force on the organ surface, as the harness spreads it: the traction of a pressure patch
/// around `surfaceVertex` (the vertex nearest the load point) turned into consistent nodal
/// forces on the organ's surface vertices: vertex vertices[k] receives weights[k] * force. The
/// weights sum to 1 and are the same for every model; a model applies them through J^T.
struct PointLoad {
  int surfaceVertex = -1;     ///< centre of the patch
  Vec3 force = Vec3::Zero();  ///< total force, N
  std::vector<int> vertices;  ///< organ surface vertices of the patch, the centre first
  std::vector<Real> weights;  ///< share of `force` per vertex; sums to 1

  /// The whole force on one surface vertex (a patch of one vertex): for tests and benchmarks
  /// that drive a model without the harness.
  static PointLoad onVertex(int vertex, const Vec3& force) {
    return PointLoad{vertex, force, {vertex}, {1.0}};
  }
};

/// A grasp in terms of a model's own nodes, for models whose organ surface vertices are among
/// their nodes (J a selection): node nodes[k] must reach targets.row(k).
struct NodeGrasp {
  int tool = 0;
  std::vector<int> nodes;
  MatX3 targets;                    ///< #nodes by 3
  Vec3 slideNormal = Vec3::Zero();  ///< as GraspInput::slideNormal (zero: bonded)
  bool sliding() const { return slideNormal.squaredNorm() > 0; }
};

/// The grasps on the nodes that carry the grasped surface vertices. vertexNode: the node of each
/// organ surface vertex (empty: vertex i is node i). out keeps its capacity between calls.
inline void graspsOnNodes(const std::vector<GraspInput>& grasps, const std::vector<int>& vertexNode,
                          std::vector<NodeGrasp>& out) {
  out.resize(grasps.size());
  for (size_t g = 0; g < grasps.size(); ++g) {
    NodeGrasp& n = out[g];
    n.tool = grasps[g].tool;
    n.nodes.resize(grasps[g].vertices.size());
    for (size_t k = 0; k < n.nodes.size(); ++k) {
      const int v = grasps[g].vertices[k];
      n.nodes[k] = vertexNode.empty() ? v : vertexNode[size_t(v)];
    }
    n.targets = grasps[g].targets;
    n.slideNormal = grasps[g].slideNormal;
  }
}

/// The organ surface's triangles F in terms of the nodes that carry their vertices: the
/// collision proxy of a model whose nodes include the surface vertices. vertexNode as in
/// graspsOnNodes (empty: vertex i is node i); a vertex outside it throws std::out_of_range.
inline MatX3i facesOnNodes(const MatX3i& F, const std::vector<int>& vertexNode) {
  MatX3i out = F;
  if (!vertexNode.empty())
    for (Eigen::Index f = 0; f < out.rows(); ++f)
      for (int k = 0; k < 3; ++k) out(f, k) = vertexNode.at(size_t(out(f, k)));
  return out;
}

/// The inverse masses of a model's nodes: 1 / mass, 0 for a node without mass and for the fixed
/// nodes (immovable). fixed: node indices, as fixedNodeIndices gives them.
inline VecX inverseMasses(const VecX& mass, const std::vector<int>& fixed) {
  VecX w(mass.size());
  for (Eigen::Index i = 0; i < mass.size(); ++i) w[i] = mass[i] > 0 ? 1.0 / mass[i] : 0.0;
  for (int i : fixed) w[i] = 0.0;
  return w;
}

/// The organ surface vertices a grasp closing at p with jaw radius r holds: every rest-surface
/// vertex (rest: #V by 3) within r of p (sorted), or the nearest vertex alone when none is. The
/// one definition of the grasped set (the harness's interaction, rmse_k's exclusion and
/// conformance use it; models and their tests may too).
std::vector<int> graspedSurfaceVertices(const MatX3& rest, const Vec3& p, Real r);
inline std::vector<int> graspedSurfaceVertices(const SurfaceMesh& rest, const Vec3& p, Real r) {
  return graspedSurfaceVertices(rest.V, p, r);
}

/// The grasps' vertices and targets as one list, for models that hold every grasped vertex the
/// same way: grasp by grasp, each vertex once (its first grasp's target wins), skipping vertices
/// outside [0, numVertices) and those without a target row. targets is sized for all the grasps'
/// vertices; its first verts.size() rows are the targets of verts (capacity of verts kept).
inline void flattenGrasps(const std::vector<GraspInput>& grasps, Eigen::Index numVertices,
                          std::vector<int>& verts, MatX3& targets) {
  verts.clear();
  Eigen::Index rows = 0;
  for (const GraspInput& g : grasps) rows += Eigen::Index(g.vertices.size());
  targets.resize(rows, 3);
  for (const GraspInput& g : grasps)
    for (size_t k = 0; k < g.vertices.size(); ++k) {
      const int v = g.vertices[k];
      if (v < 0 || v >= numVertices || Eigen::Index(k) >= g.targets.rows() ||
          std::find(verts.begin(), verts.end(), v) != verts.end())
        continue;
      targets.row(Eigen::Index(verts.size())) = g.targets.row(Eigen::Index(k));
      verts.push_back(v);
    }
}

/// The nodes held by any of the grasps, sorted and without repeats (capacity of out kept).
inline void graspedNodeSet(const std::vector<NodeGrasp>& grasps, std::vector<int>& out) {
  out.clear();
  for (const NodeGrasp& g : grasps) out.insert(out.end(), g.nodes.begin(), g.nodes.end());
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
}

/// The loads' per-vertex forces on the nodes that carry those vertices (J^T of a selection):
/// (node, force) pairs appended to out after clearing it. vertexNode as in graspsOnNodes.
inline void loadsOnNodes(const std::vector<PointLoad>& loads, const std::vector<int>& vertexNode,
                         std::vector<std::pair<int, Vec3>>& out) {
  out.clear();
  for (const PointLoad& l : loads)
    for (size_t k = 0; k < l.vertices.size(); ++k) {
      const int v = l.vertices[k];
      out.emplace_back(vertexNode.empty() ? v : vertexNode[size_t(v)], l.weights[k] * l.force);
    }
}

/// Everything that drives one step from time `time` to `time + dt`.
struct StepInput {
  Real time = 0;  ///< s, time at the start of the step
  Real dt = 0;    ///< s
  Vec3 gravity = Vec3::Zero();
  std::vector<GraspInput> grasps;
  std::vector<PointLoad> loads;
  /// Rigid instruments to keep the model's collision proxy out of (deform/sdk/contact.h), at their
  /// poses for the end of the step; nullptr when the scene has none (no Bullet world exists).
  /// Models with the "contact" capability describe their proxy and call respondToContact() (or
  /// solveWithContactConstraints()) with it, so that no node ends the step inside an instrument.
  ContactWorld* contact = nullptr;
  /// Prescribed positions of the model's own nodes, on top of the grasps: what the contact
  /// drivers of deform/sdk/contact.h add when a model solves contact as constraints. graspForces()
  /// then reports the grasps' forces followed by these, in order. Always empty from the harness.
  std::vector<NodeGrasp> nodeConstraints;
};

enum class StepStatus { Ok, Diverged };

/// Counts as the papers count them: "nodes", "elements", "constraints", "spheres", "links",
/// "particles", ... whichever apply.
using Counts = std::map<std::string, long long>;
/// Milliseconds spent in each phase of the last step ("assembly", "solve", "skinning", ...).
using PhaseTimes = std::map<std::string, double>;
/// Degeneracies skipped and counted inside kernels ("inverted_elements", "degenerate_constraints").
using NumericCounters = std::map<std::string, long long>;

/// A cut along a polyline on (or just under) the surface.
struct CutPath {
  std::vector<Vec3> points;  ///< m, at least two
  Real depth = 0.0;          ///< m
};

class DEFORM_VISIBLE Model {
 public:
  virtual ~Model() = default;

  /// Builds the model's own representation. Expensive precomputation goes through setup.cache.
  /// Throws InputError for inputs the model cannot handle (say why), never crashes.
  virtual void init(const ModelSetup& setup) = 0;

  /// Advances by in.dt. Returns Diverged when the model detects its own divergence (NaN, runaway
  /// energy); it must not throw for numerical trouble.
  virtual StepStatus step(const StepInput& in) = 0;

  /// Current positions of the model's own simulation nodes (#N by 3, m): what grasps attach and
  /// what the fixed region pins. Rest positions right after init() and reset().
  virtual const MatX3& nodes() const = 0;

  /// Current positions of the organ's input surface vertices, in input order (#V by 3, m), plus
  /// any vertices appended by cuts.
  virtual const MatX3& surface() const = 0;

  /// Back to the state right after init(); a rerun must reproduce the results bit for bit.
  virtual void reset() = 0;

  virtual Counts counts() const = 0;
  virtual PhaseTimes phaseTimes() const { return {}; }
  virtual NumericCounters numericCounters() const { return {}; }

  /// Force (N) the tissue exerts on each grasp of the last step, in the order of
  /// StepInput::grasps; empty when the model cannot tell (no reaction_force capability).
  virtual std::vector<Vec3> graspForces() const { return {}; }

  /// Interior markers (capability "markers"): binds points given at rest (#M by 3, m, inside the
  /// organ) to the model's own interior mapping (the containing tet's barycentric coordinates,
  /// a hex cell's trilinear ones, ...); markers() then returns their current positions (#M by
  /// 3, m), also after reset(). A point outside the model's interior is bound to the nearest
  /// element (extrapolated). The default, for a model with no interior, throws UnsupportedError
  /// with the reason; a model with the capability may still throw it for a configuration
  /// without one (e.g. a surface-only network), saying why.
  virtual void bindMarkers(const MatX3& /*rest*/) {
    throw UnsupportedError("this model has no interior mapping for markers");
  }
  virtual MatX3 markers() const { return {}; }

  /// Cuts the surface (capability "cut"). New surface vertices are appended; original indices
  /// stay valid. Triangles of the current surface after cuts are given by surfaceFaces().
  virtual void cut(const CutPath& /*path*/) { throw UnsupportedError("this model cannot cut"); }
  /// Current surface triangles when cuts changed them; empty means "the organ's input faces".
  virtual MatX3i surfaceFaces() const { return {}; }
};

}  // namespace deform
