// Mass-spring model of an organ: the thin stateful layer over spring_kernels.h. Nodes are the
// organ's surface vertices, with springs on mesh edges and bending springs across every interior
// edge (between the two opposite vertices), or, for tetrahedral input, the tet nodes with springs
// on the tet edges. Masses are lumped. Time integration: explicit Euler (the papers' baseline),
// symplectic Euler, or implicit Euler with one Newton step per time step (Baraff & Witkin 1998,
// "Large steps in cloth simulation", SIGGRAPH '98, Eqs. (15)-(18)) solved by conjugate gradients,
// or implicit Euler by local/global alternation with a constant, prefactored system matrix (Liu,
// Bargteil, O'Brien, Kavan 2013, "Fast simulation of mass-spring systems", ACM TOG 32(6) 214,
// doi:10.1145/2508363.2508406; massspring_liu.cpp).
// See README.md for every modelling choice.
#pragma once

#include "node_cholesky.h"
#include "spring_kernels.h"

#include <deform/geometry/tet_embedding.h>
#include <deform/kernels/sparse.h>
#include <deform/sdk/model.h>
#include <deform/sdk/params.h>

#include <array>
#include <memory>
#include <vector>

namespace deform::massspring {

enum class Integrator { ExplicitEuler, SymplecticEuler, ImplicitEuler, LocalGlobal };
/// local_global: plain alternation (Liu et al. 2013) or Chebyshev semi-iterative acceleration of
/// it (Wang 2015, "A Chebyshev semi-iterative approach for accelerating projective and
/// position-based dynamics", ACM TOG 34(6) 246).
enum class LocalGlobalAcceleration { None, Chebyshev };

struct MassSpringConfig {
  Integrator integrator = Integrator::SymplecticEuler;
  bool volumeNetwork = false;       ///< tetrahedralise a surface organ (network = volume)
  long long volumeElements = 4000;  ///< target tets of that volume
  Real thickness = 0.01;            ///< m, membrane thickness for the surface rule
  Real bendingRatio = 0.1;  ///< bending spring stiffness / stiffness of the hinge edge's spring
  Real dampingRatio = 0.1;  ///< zeta of each spring's axial dashpot
  Real massDamping = 1.0;   ///< 1/s, force -massDamping * m * v on every node
  Real cgTolerance = 1e-6;  ///< relative residual of the implicit solve
  int cgMaxIterations = 200;
  int substeps = 0;               ///< explicit/symplectic Euler substeps per step; 0 = automatic
  int localGlobalIterations = 5;  ///< local/global iterations per step (Liu et al. 2013)
  LocalGlobalAcceleration localGlobalAcceleration = LocalGlobalAcceleration::Chebyshev;
  /// Chebyshev: spectral radius of the plain iteration; 0 = estimated at each factorisation
  /// (power iteration on the iteration linearised at the current positions).
  Real localGlobalRho = 0.0;
  /// Start each step's iterations from y + (x - y) of the previous step instead of from y.
  bool localGlobalWarmStart = true;
};

/// local_global: a spring with a free end, as the iterations see it: its nodes' rows in the
/// factor's order, c = h^2 k and the rest length L.
struct LocalGlobalSpring {
  int a, b;
  Real c, rest;
};

/// Upper bound of the substeps parameter (and of the automatic choice).
constexpr int kMaxSubsteps = 100000;
/// The automatic substep is this fraction of the estimated stability limit.
constexpr Real kStabilitySafety = 0.5;
/// The power-iteration estimates of the largest eigenvalues enter the limit times this.
constexpr Real kEigenMargin = 1.05;

std::vector<ParamSpec> paramSpecs();
/// Reads validated parameters; throws InputError on an unknown integrator.
MassSpringConfig configFromParams(const ParamValues& params);

class MassSpringModel final : public Model {
 public:
  void init(const ModelSetup& setup) override;
  /// init() without the parameter layer (tests and benchmarks).
  void init(const Organ& organ, const MassSpringConfig& config);

  StepStatus step(const StepInput& in) override;
  const MatX3& nodes() const override { return m_x; }
  const MatX3& surface() const override { return m_surfaceIdentity ? m_x : m_surface; }
  void reset() override;
  Counts counts() const override;
  PhaseTimes phaseTimes() const override { return m_phase; }
  NumericCounters numericCounters() const override;
  std::vector<Vec3> graspForces() const override { return m_graspForces; }
  /// Markers: barycentric coordinates in the containing tet of the volume network
  /// (deform/geometry/tet_embedding.h); a surface network has no interior.
  void bindMarkers(const MatX3& rest) override {
    if (m_tets.rows() == 0)
      throw UnsupportedError("no interior: surface network (network = volume maps markers)");
    m_markerEmbedding = embedInTets(m_rest, m_tets, rest);
  }
  MatX3 markers() const override { return embeddedPositions(m_markerEmbedding, m_x, m_tets); }

  const MassSpringConfig& config() const { return m_config; }
  const VecX& masses() const { return m_mass; }
  const std::vector<Spring>& springs() const { return m_springs; }
  const MatX3& velocities() const { return m_v; }

  /// Explicit/symplectic Euler: the largest step estimated stable (spring stiffness, dashpots
  /// and mass damping over the node masses, Gershgorin bounds) times kStabilitySafety; +inf for
  /// the implicit integrators or without free springs. Computed once at init.
  Real stableStep() const;
  /// The largest eigenvalue of M^-1 K (1/s^2; damping: of M^-1 C, the dashpots, 1/s) over the
  /// free nodes at the rest shape, by power iteration (a lower bound within about 1e-4 of it);
  /// stableStep() uses it times kEigenMargin, capped by the Gershgorin bound.
  Real largestRestEigenvalue(bool damping) const;
  /// Substeps a step of dt takes: the substeps parameter, or automatic (ceil(dt / stableStep()),
  /// at most kMaxSubsteps); 1 for the implicit integrators (implicit_euler, local_global).
  int substepsFor(Real dt) const;
  /// Substeps the last explicit/symplectic step took.
  int lastSubsteps() const { return m_lastSubsteps; }

  /// Internal spring forces (elastic + axial damping) at positions x, velocities v: #N by 3, N.
  /// Counts degenerate springs.
  void springForces(const MatX3& x, const MatX3& v, MatX3& f);

  /// Replaces the positions and velocities (#N by 3, m and m/s): the next step starts there.
  /// For tests and measurements that compare integrators from one state. Keeps the
  /// local_global warm start (the last step's correction; reset() clears it).
  void setState(const MatX3& x, const MatX3& v);
  /// local_global: the spectral radius the Chebyshev weights use (estimated or given); 0 before
  /// the first step and without acceleration.
  Real localGlobalRho() const { return m_lgRho; }

 private:
  void buildSurface(const Organ& organ);
  void buildTets(const Organ& organ);
  void buildPattern();
  void buildSpringArrays();
  Real computeStableStep() const;
  // The explicit integrators' node rows (explicit_rows.h), 64-byte aligned: 8 doubles per node
  // (position, velocity), then 4 per node (force).
  double* xvRows();
  StepStatus stepImplicit(const StepInput& in, Real h);
  // Liu et al. 2013 (massspring_liu.cpp).
  StepStatus stepLocalGlobal(const StepInput& in, Real h);
  void factorLocalGlobal(Real h);
  Real estimateLocalGlobalRho();
  void applyConstraints(const StepInput& in, Real h, const MatX3& xOld);
  void computeGraspForces(const StepInput& in);
  StepStatus checkDivergence() const;

  MassSpringConfig m_config;
  MatX3 m_rest, m_x, m_v, m_f, m_xOld;
  MatX4i m_tets;  // tet input: the tets (for inverted_tets)
  TetEmbedding m_markerEmbedding;
  VecX m_mass, m_invMass;  // invMass 0 for fixed or massless nodes
  VecX m_contactInvMass;   // invMass with grasped nodes 0 too (contact response)
  std::vector<int> m_fixed;
  std::vector<Spring> m_springs;
  // The springs as arrays for the explicit integrators (explicit_rows.h): node row offsets
  // (8 x node), rest length, stiffness, damping; and the node rows they work on.
  std::vector<int> m_sa, m_sb;
  std::vector<Real> m_sRest, m_sK, m_sC;
  std::vector<double> m_rowBuf;
  Real m_stableStep = 0;  // stableStep(), computed at init
  long long m_edgeSprings = 0, m_bendingSprings = 0, m_elements = 0;

  bool m_surfaceIdentity = true;
  std::vector<int> m_surfaceRows;
  std::vector<NodeGrasp> m_nodeGrasps;  // this step's grasps on nodes
  /// This step's nodes under a sliding plate (GraspInput::slideNormal) and not also held by a
  /// bonded grasp: coordinate `axis` (the plate's normal) ends the step at `offset` and moves with
  /// the plate; the other two are free (a frictionless plate).
  struct SlidingHold {
    int node;
    int axis;
    Real offset;
  };
  std::vector<SlidingHold> m_sliding;
  /// m_sliding from m_nodeGrasps (throws InputError for a normal off the coordinate axes).
  void collectSliding();
  /// Puts the sliding nodes' normal coordinate at the fraction t of its way from the step's start
  /// (m_xOld) to the plate and gives it the plate's velocity (x: rows of `stride` doubles, the
  /// velocity at +velocityOffset; stride 3 and no velocity for an N x 3 matrix's data).
  void holdSliding(Real t, Real h, Real* x, int stride, Real* v, int vstride) const;
  std::vector<std::pair<int, Vec3>> m_nodeForces;  // this step's load shares on nodes
  MatX3 m_surface;
  MatX3i m_contactF;     // surface triangles as node rows: the collision proxy
  MatX3 m_stepStart;     // positions at the step's start (contact friction)
  MatX3 m_contactForce;  // penalty contact forces of the step (N)

  // Implicit Euler: the system matrix with a fixed pattern, and where each spring's four 3x3
  // blocks and each node's diagonal block live in its value array (index of the block's first
  // row, per block column; the block's three rows follow).
  SparseMatrix m_A;
  std::vector<std::array<int, 12>> m_springSlots;  // (aa, bb, ab, ba) x 3 columns
  std::vector<std::array<int, 3>> m_nodeSlots;
  VecX m_dv, m_rhs, m_prescribed;
  std::vector<unsigned char> m_constrainedDof;

  // Local/global: A = M + h^2 L over nodes (the same for x, y and z), with the rows and columns of
  // constrained (fixed, massless, grasped) nodes replaced by the identity; factorised when h or
  // the constrained set changes (the pattern is analysed once). The iterations run in the
  // factor's node order (rows of 4 doubles, NodeCholesky).
  SparseMatrix m_lgA;
  std::vector<std::array<int, 4>> m_lgSpringSlots;  // (aa, bb, ab, ba) value indices
  std::vector<int> m_lgDiag;
  std::unique_ptr<NodeCholesky> m_lgChol;
  Real m_lgH = -1;
  Real m_lgRho = 0;
  std::vector<unsigned char> m_lgConstrained, m_lgFactoredFor;
  std::vector<LocalGlobalSpring> m_lgSprings;  // springs with a free end
  std::vector<Real> m_lgRowMass;         // node masses in the factor's order, 0 if constrained
  std::vector<int> m_lgConstrainedRows;  // constrained nodes' rows
  std::vector<Row4> m_lgR, m_lgX, m_lgXPrev, m_lgY4, m_lgWarm;
  std::vector<SlidingHold> m_lgSliding;  // m_sliding with `node` the factor's row
  MatX3 m_lgY;
  long long m_lgFactorisations = 0;

  std::vector<unsigned char> m_graspMask;
  std::vector<int> m_graspedScratch, m_graspSpringsFor, m_graspSprings;
  Vec3 m_boxCenter = Vec3::Zero();
  Real m_boxHalf = 0;
  Real m_setupDt = 0;  // the scene's dt given at init (for counts()["substeps"])
  int m_lastSubsteps = 1;
  long long m_degenerate = 0, m_cgNotConverged = 0, m_cgIterations = 0;
  std::vector<Vec3> m_graspForces;
  PhaseTimes m_phase;
};

}  // namespace deform::massspring
