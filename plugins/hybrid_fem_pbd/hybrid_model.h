// Hybrid FEM+PBD model: the thin stateful layer over the kernels. The hybrid mesh is a fine
// triangle surface MS (the organ's own surface, simulated by PBD) and a coarse tetrahedral
// volume MV (linear FEM) whose boundary vertices are a subset of MS's vertices, the control
// nodes (paper Secs. 2, 5, 6). One step (paper Sec. 6.5):
//   1. load processing: each point load's fine node is attached to the coarse surface; its
//      force goes to MV as equivalent nodal forces (load_processing.h);
//   2. MV: quasi-static linear FEM, K u = f with K factorised once (coarse_fem.h); grasped
//      control nodes are prescribed displacements (Schur complement, factorisation kept);
//   3. MS prediction: v += dt (g + w f_ext), p = x + dt v for ordinary nodes;
//   4. MS projection: control nodes take MV's positions (w = 0), grasped and fixed nodes their
//      targets; stretch and bending constraints are projected Gauss-Seidel (surface_pbd.h);
//   5. v = (p - x) / dt (then damped), x = p.
// cut() implements the small incision of paper Sec. 7 (incision.h).
//
// Paper: "A Hybrid Model Method for Accurate Surface Deformation and Incision Based on FEM and
// PBD", Scientific Programming 2021, article 8343312
// See README.md.
#pragma once

#include <deform/geometry/tet_embedding.h>
#include <deform/sdk/model.h>
#include <deform/sdk/params.h>

#include <map>
#include <string>
#include <vector>

#include "batched_projection.h"
#include "coarse_fem.h"
#include "incision.h"
#include "surface_pbd.h"
#include "vertex_cover_simplification.h"

namespace deform::hybrid_fem_pbd {

/// How the surface constraints are projected (identical constraints, order and stiffness; see
/// batched_projection.h). Not a scene parameter: the reference path is kept for tests and the
/// before/after benchmark.
enum class SurfaceProjection {
  Reference,      ///< projectSurfaceConstraints(): the shared pbd_kernels.h kernels, one by one
  BatchedScalar,  ///< projectSurfaceBatches() without SIMD
  Batched,        ///< projectSurfaceBatches(), four at a time where the CPU has AVX2
};

/// The bending constraint of the fine surface: the isometric hinge of
/// deform/kernels/isometric_bending.h (default) or the paper's dihedral angle (Eqs. (10)-(11)).
enum class HybridBending { Isometric, Dihedral };

/// Number type of the two per-step kernels that dominate the step on large organs: the surface
/// projection (stretch and isometric bending; the dihedral bending and the Reference projection
/// are always double) and the grasp response Z lambda of the coarse FEM (coarse_fem.h). State
/// between steps, the FEM solve and everything else stay double.
enum class HybridPrecision { Float32, Float64 };

/// Resolved parameters (see paramSpecs()).
struct HybridConfig {
  int iterations = 10;          ///< Gauss-Seidel sweeps on MS
  Real stretchStiffness = 1.0;  ///< classic PBD, [0, 1]
  Real bendingStiffness = 0.5;  ///< classic PBD, [0, 1]
  HybridBending bending = HybridBending::Isometric;
  Real damping = 20.0;            ///< 1/s: v <- v exp(-damping dt)
  bool surfaceLoad = true;        ///< the force also acts on its fine node in the prediction
  int simplificationLevels = 1;   ///< vertex-cover passes (the paper: 1)
  Real minCollapseQuality = 0.1;  ///< see SimplificationOptions
  Real tetEdgeFactor = 1.0;       ///< interior tet edge length / mean coarse surface edge
  Real cutSnap = 0.1;             ///< CutOptions::snapFraction
  SurfaceProjection projection = SurfaceProjection::Batched;
  HybridPrecision precision = HybridPrecision::Float32;
};

std::vector<ParamSpec> paramSpecs();
HybridConfig configFromParams(const ParamValues& params);

/// The hybrid mesh: coarse surface, MV, and the map between them and MS.
struct HybridMesh {
  SurfaceMesh coarseSurface;      ///< vertices = MV nodes 0..#Vc-1
  std::vector<int> coarseToFine;  ///< #Vc
  TetMesh volume;                 ///< MV
  long long collapsed = 0, rejected = 0;
  double seconds = 0;  ///< construction wall time (simplification + meshing), s
};

/// Builds the hybrid mesh from a fine surface (cached when a cache is given).
HybridMesh buildHybridMesh(const SurfaceMesh& fine, const HybridConfig& config,
                           const std::string& source, Cache* cache);

class HybridModel final : public Model {
 public:
  void init(const ModelSetup& setup) override;
  /// init() without the parameter layer (tests and benchmarks); cache may be null.
  void init(const Organ& organ, const HybridConfig& config, Cache* cache = nullptr);

  StepStatus step(const StepInput& in) override;
  const MatX3& nodes() const override { return m_surf.x; }
  const MatX3& surface() const override { return m_surf.x; }
  void reset() override;
  Counts counts() const override;
  PhaseTimes phaseTimes() const override { return m_phase; }
  NumericCounters numericCounters() const override { return m_numeric; }
  /// Force (N) the tissue exerts on each grasp: minus the sum of the Lagrange multipliers of the
  /// grasp's prescribed displacements on MV, i.e. -(K u - f) at the grasped control nodes (see
  /// CoarseLinearFem::solve). The volume mesh carries the load in this model; the fine surface is
  /// a classic (unitless) PBD skin driven by MV, so its multipliers are not forces.
  std::vector<Vec3> graspForces() const override { return m_graspForces; }
  void cut(const CutPath& path) override;
  MatX3i surfaceFaces() const override;
  /// Markers: barycentric coordinates in the containing coarse tet (MV,
  /// deform/geometry/tet_embedding.h); binding makes the coarse FEM compute its interior nodes
  /// every step too.
  void bindMarkers(const MatX3& rest) override;
  MatX3 markers() const override;

  // Introspection for tests and benchmarks.
  const HybridMesh& hybridMesh() const { return m_mesh; }
  /// Current MV node positions (#nodes by 3): the control nodes (coarse surface, rows
  /// 0..#Vc-1); interior nodes are not computed per step and stay at rest.
  const MatX3& volumePositions() const { return m_volumeX; }
  /// Coarse vertex of each fine vertex that is (still) a control node, else -1.
  const std::vector<int>& controlOf() const { return m_controlOf; }
  const SurfaceConstraints& constraints() const { return m_constraints; }
  /// The batches projected in the last step (the constraints with a movable particle).
  const SurfaceBatches& batches() const { return m_batches; }
  const CutReport& lastCut() const { return m_lastCut; }
  const MatX3& restSurface() const { return m_surf.rest; }

 private:
  void rebuildMasses();
  const CoarseAttachment& attachment(int fineVertex);
  // The phases of step() (see the file comment).
  void gatherLoads(const std::vector<PointLoad>& loads);     ///< 1: loads onto MV and MS
  void gatherGrasps(const std::vector<GraspInput>& grasps);  ///< 1: grasp targets, prescribed
  void solveCoarse(const Vec3& gravity, size_t numGrasps);   ///< 2: MV, grasp forces
  void refreshActiveConstraints();  ///< inverse masses and batches when the immovable set changed
  void predictSurface(Real dt, const Vec3& gravity);  ///< 3: m_p
  long long projectPrediction();  ///< 4: projects m_p; returns the degenerate constraint count
  /// step() with StepInput::contact: contact as prescribed vertices (hybrid_contact.cpp).
  StepStatus stepWithContact(const StepInput& in);
  bool m_inContactStep = false;

  HybridConfig m_cfg;
  std::string m_source;
  Real m_density = 1000;  ///< kg/m^3
  HybridMesh m_mesh;
  CoarseLinearFem m_fem;
  std::vector<int> m_fixedFine;
  std::vector<char> m_isFixedFine;

  // State (restored by reset()).
  CuttableSurface m_surf, m_surf0;
  SurfaceConstraints m_constraints, m_constraints0;
  std::vector<int> m_controlOf, m_controlOf0;
  MatX3 m_v;
  VecX m_mass, m_w;
  MatX3 m_p, m_volumeU, m_volumeX;
  std::map<int, CoarseAttachment> m_attach;
  std::vector<char> m_immovable;
  ActiveConstraints m_active;
  SurfaceBatches m_batches;
  bool m_activeValid = false;
  std::vector<Vec3> m_graspForces;
  CutReport m_lastCut;
  bool m_cut = false;

  PhaseTimes m_phase;
  NumericCounters m_numeric;
  TetEmbedding m_markerEmbedding;
  bool m_markersBound = false;  ///< every MV node is solved and kept in m_volumeX

  // Per-step scratch (kept to avoid allocations in step()).
  std::vector<CoarseLinearFem::NodalForce> m_nodal;
  std::vector<std::pair<int, Vec3>> m_surfaceForces, m_graspTargets;
  std::vector<int> m_graspTargetAxis;  ///< per m_graspTargets: -1 bonded, else the sliding axis
  std::vector<CoarseLinearFem::Prescribed> m_prescribed;
  std::vector<int> m_prescribedGrasp;  ///< grasp index of each m_prescribed entry
  std::vector<Vec3> m_reactions;
  std::vector<char> m_immovableStep;
  std::vector<Real> m_x4;        ///< #V by 4 padded positions for projectSurfaceBatches
  std::vector<float> m_x4f;      ///< the same relative to m_origin, for projectSurfaceBatchesF
  Vec3 m_origin = Vec3::Zero();  ///< centre of the rest surface's bounding box, m
};

}  // namespace deform::hybrid_fem_pbd
