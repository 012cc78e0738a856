// deformbench SDK: the model interface every plugin implements, and the interaction data the
// harness hands it each step. Interaction is resolved identically for every model by the core
// (see interaction.h): a grasp attaches the model's own nodes within the grasp radius and gives
// their target positions each step; a point force names the surface vertex nearest to its point;
// a fixed region pins every model node inside it.
#pragma once

#include <deform/cache.h>
#include <deform/error.h>
#include <deform/mesh.h>
#include <deform/params.h>

#include <algorithm>
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

/// Region whose model nodes are pinned: nodes inside any box, and the model node nearest to each
/// listed surface vertex (identity-mapped models pin exactly those vertices).
struct FixedRegion {
  std::vector<Box> boxes;
  std::vector<int> surfaceVertices;
  bool empty() const { return boxes.empty() && surfaceVertices.empty(); }
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

/// What init() receives. References stay valid for the model's lifetime.
struct ModelSetup {
  const Organ& organ;
  const ParamValues& params;
  Cache& cache;
  Real dt;       ///< s, the scene's time step (constant for a run)
  Vec3 gravity;  ///< m/s^2
};

/// A grasp in force during a step: the model's own nodes attached when the jaws closed, and the
/// positions (#nodes by 3, m) they must reach at the end of the step (they follow the tool
/// rigidly). Nodes stay attached until the jaws open.
struct GraspInput {
  int tool = 0;            ///< index of the tool in the scene
  std::vector<int> nodes;  ///< model node indices
  MatX3 targets;           ///< #nodes by 3
};

/// The nodes held by any of the grasps, sorted and without repeats, written to out (its capacity
/// is kept, so a model can call this every step without allocating).
inline void graspedNodeSet(const std::vector<GraspInput>& grasps, std::vector<int>& out) {
  out.clear();
  for (const GraspInput& g : grasps) out.insert(out.end(), g.nodes.begin(), g.nodes.end());
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
}

/// A force on the organ surface: applied at one input-surface vertex, distributed by the model
/// over its own representation.
struct PointLoad {
  int surfaceVertex = -1;
  Vec3 force = Vec3::Zero();  ///< N
};

/// Everything that drives one step from time `time` to `time + dt`.
struct StepInput {
  Real time = 0;  ///< s, time at the start of the step
  Real dt = 0;    ///< s
  Vec3 gravity = Vec3::Zero();
  std::vector<GraspInput> grasps;
  std::vector<PointLoad> loads;
  /// Rigid instruments to keep the model's collision proxy out of (deform/contact.h), at their
  /// poses for the end of the step; nullptr when the scene has none (no Bullet world exists).
  /// Models with the "contact" capability call resolveContacts() (or query()) on it once their
  /// own solve is done, so that no node ends the step inside an instrument.
  ContactWorld* contact = nullptr;
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

  /// Cuts the surface (capability "cut"). New surface vertices are appended; original indices
  /// stay valid. Triangles of the current surface after cuts are given by surfaceFaces().
  virtual void cut(const CutPath& /*path*/) { throw UnsupportedError("this model cannot cut"); }
  /// Current surface triangles when cuts changed them; empty means "the organ's input faces".
  virtual MatX3i surfaceFaces() const { return {}; }
};

}  // namespace deform
