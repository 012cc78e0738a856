// fem_hex: hexahedral FEM on a voxel grid embedding the organ surface (the FEM baseline of the
// metaballs paper, /work/shared/papers/metaballs-pbd-skinning.md, Table 2: 967 hexahedra on the
// liver, 819 on the gallbladder).
//
// Implicit Euler with Rayleigh damping D = alpha M + beta K, linearised once per step (one Newton
// step, the standard real-time choice of Baraff & Witkin 1998 / Müller & Gross 2004):
//   (c1 M + c2 K) v+ = M v + h (f(x) + f_ext),   c1 = 1 + h alpha,   c2 = h beta + h^2,
//   x+ = x + h v+,
// with f(x) = -K (x - X) (linear) or sum_e -R_e K0 (R_e^T x_e - X_e) and K = sum_e R_e K0 R_e^T
// (corotational, Müller & Gross 2004; Nesme et al. 2005). All hexahedra are equal cubes, so K0
// and the element mass are computed once. M is lumped: rho h^3 / 8 per node and element.
// Fixed nodes (the grid nodes inside the fixed region) are eliminated from the unknowns.
// Surface mapping (SOFA's Mapping): the organ's surface vertices are embedded trilinearly,
// x_s = J q (J: the 8 weights of each vertex's hexahedron). A point force reaches the nodes as
// J^T f. Held surface points (the grasped vertices, with targets t moving with the tool, and the
// clamped ones, at rest) are held through the same mapping by a stiff penalty,
//     E_hold = kp/2 sum_held |J_v q - t_v|^2,
// taken implicitly in the step: h^2 kp J_H^T J_H joins the system matrix (it couples only nodes
// of one hexahedron, so the sparsity pattern is unchanged, and it is rotation invariant, so the
// rest-system preconditioner holds it exactly) and h kp J_H^T (t - J_H x) the right-hand side.
// kp = holdStiffness times the largest diagonal entry of K0: the held points miss their targets
// by their share of the reaction over kp (nm on the kidney and liver scenes). Only the grasped
// points are held, not the cells around them. The reaction of a grasp on the tool is the
// residual of the tissue's own rows at the nodes carrying its vertices, (b - A v+)_C / h (A, b
// without the penalty; equal to sum_v kp (J_v x+ - t_v) for an exact solve). (A multiplier per
// point carried across steps, lambda += kp (t - J x+), would make the hold exact in the limit but
// integrates the CG solve's residual at the held rows into lambda: the liver lift at 4000 hexahedra
// then crept near the jaws by 0.07 mm per 50 ms step instead of settling.)
#pragma once

#include <deform/kernels/cholesky_solver.h>
#include "hex_element.h"
#include "hex_grid.h"

#include <deform/sdk/contact.h>
#include <deform/sdk/model.h>

#include <functional>
#include <string>
#include <vector>

namespace deform::fem_hex {

enum class ElasticModel { Linear, Corotational };
enum class CorotationalSolver { Refactor, Pcg };
/// PCG preconditioner: Cholesky of the rest system A0 = c1 M + c2 K0, either factored once and
/// applied filtered (Rest: never refactorised, so a grasp closing costs nothing), or refactorised
/// with the grasped rows and columns eliminated whenever the grasp set changes (RestGrasped).
/// Both now include the held points' penalty and are refactorised when the grasped set changes
/// (RestGrasped is kept as a name for scenes that set it; it behaves as Rest).
enum class PcgPreconditioner { Rest, RestGrasped };
/// Number type of the PCG preconditioner's triangular solves.
enum class PreconditionerPrecision { Float64, Float32, Float16 };
/// How the fixed region holds: Points (the grid nodes inside the region are pinned and the
/// clamped surface points are held at rest by the penalty), Cells (the grid nodes inside the
/// region and every node of the cells carrying a clamped surface vertex are pinned: up to a cell
/// beyond the region) or Nodes (only the grid nodes inside the region).
enum class Clamp { Points, Cells, Nodes };

/// The element stiffness: the plain trilinear hexahedron (locks in bending) or the same nodes with
/// Wilson's condensed incompatible modes (hexStiffnessIncompatible).
enum class HexElement { Trilinear, IncompatibleModes };

/// Smallest volume fraction of a crossing cell (keeps its nodes' mass and stiffness away from 0).
constexpr Real kMinCellFill = 0.1;

/// Volume fraction inside `surface` of each hexahedron of `grid` (built from `voxels`): 1 for
/// inside cells, the fraction of the n^3 sub-cell centres inside for crossing ones (at least
/// kMinCellFill), by the same winding-number classification on a grid n times finer. n < 1: all 1.
std::vector<Real> cellFillFractions(const SurfaceMesh& surface, const VoxelGrid& voxels,
                                    const HexGrid& grid, int n);

struct HexFemConfig {
  long long elements = 967;  ///< target hexahedron count (used when cellSize == 0)
  Real cellSize = 0;         ///< m; 0 = choose from elements
  ElasticModel elastic = ElasticModel::Corotational;
  HexElement element = HexElement::IncompatibleModes;
  /// Samples per axis of the volume fraction of the cells the surface crosses: stiffness and mass
  /// of such a hexahedron are scaled by the fraction of its n^3 sub-cell centres inside the
  /// surface (at least kMinCellFill), so the grid's overhang adds neither. 0: every cell is full
  /// (the plain voxel embedding).
  int fillSamples = 4;
  CorotationalSolver solver = CorotationalSolver::Pcg;
  Real rayleighMass = 0;       ///< alpha, 1/s
  Real rayleighStiffness = 0;  ///< beta, s
  Real pcgTolerance = 1e-3;    ///< relative CG residual (see step()), D^-1 norm, D = diag(A0)
  int pcgMaxIterations = 50;
  /// CG starts from the last velocities corrected along the last step's change of velocity by
  /// the step that minimises the error's energy norm (step()); false: from the last velocities.
  bool pcgProjectedStart = true;
  /// The PCG preconditioner's triangular solves on a float or half copy of a supernodal factor
  /// (Float64: on CHOLMOD's double factor); direct solves (linear, refactor) always use the
  /// double factor.
  PreconditionerPrecision preconditionerPrecision = PreconditionerPrecision::Float32;
  PcgPreconditioner pcgPreconditioner = PcgPreconditioner::Rest;
  int rotationIterations = 8;  ///< max iterations of the warm-started rotation extraction
  Clamp clamp = Clamp::Points;
  /// Penalty stiffness of the held surface points (grasped and clamped), as a multiple of the
  /// largest diagonal entry of one hexahedron's stiffness K0 (dimensionless).
  Real holdStiffness = 1e8;
  CholeskySolver::Kind cholesky = CholeskySolver::Kind::Auto;
  bool tryAllOrderings = true;  ///< CHOLMOD nmethods = 9 (else its default AMD/METIS choice)
};

std::vector<ParamSpec> paramSpecs();  ///< plugin.cpp
HexFemConfig configFromParams(const ParamValues& params);

class HexFemModel : public Model {
 public:
  /// initialize() with the config of setup.params and the nodes inside the organ's fixed region
  /// pinned.
  void init(const ModelSetup& setup) override;
  /// Builds grid, embedding, K0, mass, sparsity pattern and factorisation. fixedNodesOf maps the
  /// rest node positions to the pinned node indices; with Clamp::Cells the nodes carrying the
  /// surface vertices of organ.fixed are pinned too, with Clamp::Points those vertices are held
  /// by the penalty. Throws InputError for unusable input.
  void initialize(const Organ& organ, const HexFemConfig& config, Real dt,
                  const std::function<std::vector<int>(const MatX3&)>& fixedNodesOf);

  StepStatus step(const StepInput& in) override;
  const MatX3& nodes() const override { return m_x; }
  const MatX3& surface() const override { return m_surface; }
  void reset() override;
  Counts counts() const override;
  PhaseTimes phaseTimes() const override;
  NumericCounters numericCounters() const override;
  std::vector<Vec3> graspForces() const override { return m_graspForces; }

  const HexGrid& grid() const { return m_grid; }
  const VoxelGrid& voxels() const { return m_voxels; }
  /// The surface mapping: each surface vertex's 8 nodes and trilinear weights.
  const Embedding& embedding() const { return m_embedding; }

  /// Markers: embedded trilinearly in the active cells, as the surface vertices are (a point
  /// outside every active cell is clamped into the nearest one).
  void bindMarkers(const MatX3& rest) override {
    m_markerEmbedding = embedPoints(m_grid, m_voxels, rest);
  }
  MatX3 markers() const override {
    MatX3 out(m_markerEmbedding.nodeIds.rows(), 3);
    evaluateEmbedding(m_markerEmbedding, m_x, out);
    return out;
  }
  const Mat24& elementStiffness() const { return m_K0; }
  /// Volume fraction of each hexahedron inside the surface (1 with fillSamples = 0).
  const std::vector<Real>& cellFill() const { return m_fill; }
  const std::vector<int>& fixedNodes() const { return m_fixedList; }
  /// Node velocities (#N by 3, m/s).
  Eigen::Map<const MatX3> velocities() const {
    return Eigen::Map<const MatX3>(m_v.data(), m_x.rows(), 3);
  }
  const CholeskySolver& cholesky() const { return m_chol; }
  /// The nodes carrying the grasped surface vertices of the last step (non-zero weight).
  const std::vector<int>& graspedNodes() const { return m_grasped; }
  /// Surface vertices of the fixed region held at rest by the penalty (Clamp::Points).
  const std::vector<int>& heldClampVertices() const { return m_clampVerts; }
  /// Penalty stiffness of one held point, N/m.
  Real holdStiffnessPerPoint() const { return m_kp; }
  /// CG iterations of the last step (0 outside the pcg solver).
  int lastIterations() const { return m_lastIterations; }

 private:
  using Vec24i = Eigen::Matrix<int, 24, 1>;
  void buildPattern();
  void assembleValues(bool rotated);
  /// Adds the grasped points' penalty h^2 kp J_G^T J_G to m_A's values when withGrasps and
  /// factorises.
  void factorize(bool withGrasps);
  /// Position of (row, col), row >= col, in m_A's values.
  int valuePosition(int row, int col) const;
  /// m_A values += s J_v^T J_v (per coordinate) for every vertex v of verts (free nodes only).
  /// axes: per vertex, -1 (all three components) or the one axis held; empty: all three.
  void addHeldValues(const std::vector<int>& verts, Real s, const std::vector<int>& axes = {});
  /// out += scale J_H^T J_H in over the held points (clamped and grasped).
  void applyHeld(const VecX& in, Real scale, VecX& out) const;
  /// out += h kp J_H^T (t - J_H (x + h v0)) over the held points.
  void addHeldResidual(const VecX& v0, VecX& out) const;
  /// z = A0^-1 r on the free dofs (0 on the others); approximate: by the float copy of the
  /// factor where there is one (factorize() builds it for the PCG when the config asks).
  bool precondition(const VecX& r, VecX& z, bool approximate = false);
  /// out += scale * sum_e R_e K0 (R_e^T (a in_e) - b X_e) over elements (all when elems is null).
  void applyElements(const std::vector<int>* elems, const VecX& in, Real a, Real b, Real scale,
                     VecX& out) const;
  void applyAllElements(const VecX& in, Real a, Real b, Real scale, VecX& out, bool rotated) const;
  bool updateRotations();  // false when an element's rotation did not converge
  void updateInverseDiagonal();
  void filter(VecX& r) const;
  /// Grasped surface vertices of `in` and their targets (m_graspVerts, m_graspVertTargets) and
  /// the nodes carrying them (m_grasped, m_isGrasped).
  void collectGrasps(const StepInput& in);
  /// step()'s parts: m_fext = gravity on the lumped masses plus the point loads as J^T f; after
  /// the solve, the reaction of each grasp on its tool (m_graspForces, see step()).
  void applyLoads(const StepInput& in);
  void graspReactions(const StepInput& in, Real h);

  HexFemConfig m_config;
  Real m_dt = 0;
  Real m_c1 = 1, m_c2 = 0;
  VoxelGrid m_voxels;
  HexGrid m_grid;
  Embedding m_embedding;
  Embedding m_markerEmbedding;  ///< bindMarkers()
  Mat24 m_K0;
  std::vector<Real> m_fill;  ///< per hexahedron, scales its K0 and its mass
  VecX m_mass;               // 3N, lumped, per DOF
  VecX m_invDiag;            // 3N, inverse diagonal of the rest system (1/mass on fixed nodes)
  MatX3 m_rest;
  VecX m_restRows;  ///< m_rest node by node (x, y, z per node), for the element pass's gather
  std::vector<int> m_fixedList;
  std::vector<char> m_isFixed;   // N
  std::vector<int> m_dofOfNode;  // N, first reduced DOF or -1 when fixed
  int m_numDofs = 0;             // reduced (free) DOFs

  // System matrix: lower triangle over the free DOFs, values scattered by m_valueIndex.
  SparseMatrix m_A;
  std::vector<int> m_valueIndex;                  // E * 576, position in m_A's values or -1
  std::vector<int> m_diagIndex;                   // reduced DOF -> position of its diagonal
  VecX m_baseValues;                              // c1 M + c2 K0 (unrotated, unconstrained)
  std::vector<int> m_nodeOfDof;                   // reduced DOF -> node
  std::vector<int> m_nodeElemStart, m_nodeElems;  // node -> elements (CSR)
  bool m_factorOk = false;
  long long m_factorNonZeros = 0;
  long long m_fixedInRegion = 0;       // nodes fixedNodesOf returned (before the clamped cells)
  double m_flopsPerFactorNonZero = 0;  // factorisation flops / nnz(L) of the analysed ordering
  Real m_totalMass = 0;
  Vec3 m_restCenter = Vec3::Zero();
  Real m_divergenceRadius = 0;
  CholeskySolver m_chol;
  std::vector<int> m_factorVerts;  // grasped vertices the factorisation holds ({-1}: stale)
  Real m_kp = 0;                   // N/m, penalty per held point
  std::vector<int> m_clampVerts;   // clamped surface vertices held by the penalty
  MatX3 m_clampTargets;            // their embedded rest positions

  // State.
  MatX3 m_x;
  VecX m_v;
  VecX m_contactInvMass;  // N, 1/kg; 0 on fixed and grasped nodes (contact response)
  std::vector<Quat> m_q;
  std::vector<Mat3> m_R;
  MatX3 m_surface;
  MatX3i m_surfaceF;  // the organ's triangles over m_surface: the collision proxy
  MatX3 m_stepStart;  // nodes at the step's start (contact friction)

  /// The collision proxy: the organ's triangles, embedded in the grid nodes by the trilinear
  /// weights (deform/sdk/contact.h).
  ContactProxy contactProxy() {
    return {.nodes = &m_x,
            .invMass = &m_contactInvMass,
            .velocity = m_v.data(),
            .atStepStart = &m_stepStart,
            .faces = &m_surfaceF,
            .embedding = embeddingOf(m_embedding.nodeIds, m_embedding.weights)};
  }

  // Per-step work (allocated once).
  std::vector<char> m_isGrasped;      // N: carries a grasped vertex (contact leaves it alone)
  std::vector<int> m_grasped;         // sorted nodes carrying the grasped vertices
  std::vector<int> m_graspVerts;      // grasped surface vertices of this step (grasp order)
  std::vector<int> m_graspVertOwner;  // their grasp index
  MatX3 m_graspVertTargets;           // their targets
  /// Per grasped vertex: -1 (bonded: the penalty on all three components), else the axis of its
  /// sliding plate's normal (the penalty on that component only, the other two free).
  std::vector<int> m_graspVertAxis;
  std::vector<int> m_carryCol;        // N, index of a carrying node in m_grasped or -1
  MatX m_carryShare;                  // #carrying x #grasps: share of each node's reaction
  std::vector<int> m_touched;         // elements touching carrying nodes
  std::vector<int> m_touchedGrasped;  // carrying set m_touched was built for
  std::vector<char> m_elemMark;
  mutable MatX m_U, m_KU;  // 24 x E element vectors in, K0 times them out
  VecX m_v0, m_vOld, m_dv, m_r, m_z, m_p, m_w, m_fext, m_rd, m_zd;
  /// The squared residual's reduction by the last step's first CG iteration (0: none yet): whether
  /// the next step's start is worth projecting (step()).
  Real m_firstReduction2 = 0;
  std::vector<Vec3> m_graspForces;
  int m_lastIterations = 0;
  double m_msAssembly = 0, m_msSolve = 0, m_msSurface = 0;
  long long m_rotationNotConverged = 0, m_pcgNotConverged = 0, m_ignoredGraspNodes = 0;
  long long m_rotationSvd = 0, m_rotationIterations = 0;  // SVD fallbacks, Newton steps
  long long m_unconvergedSteps = 0;         // steps with a rotation or the CG solve not converged
  long long m_pcgIterations = 0;            // CG iterations over the run
  long long m_preconditionerRefreshes = 0;  // factors of the rotated system after CG gave up
};

}  // namespace deform::fem_hex
