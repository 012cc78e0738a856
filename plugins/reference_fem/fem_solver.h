// Reference FEM kernels: assembly of linear (4-node) or quadratic (10-node, quadratic_tet.h) tet
// hyperelasticity (material points of deform/kernels/fem_tet.h) and its quasi-static and
// implicit-Euler solves by Newton's method.
//
// Quadratic elements are built from the corner (P1) mesh by adding one node at the midpoint of
// every edge (straight sides, so the polyhedral geometry is unchanged). The corner nodes keep
// their indices 0..N-1 (so the surface vertices stay nodes 0..#V-1) and the midside nodes follow,
// numbered in the order of their sorted (lower, higher) corner pairs. External loads are
// consistent: gravity f_i = g integral rho N_i dV (a P2 corner node gets -1/20 of its elements'
// weight, a midside node 1/5); the dynamic solve uses the HRZ-lumped mass (positive, see
// quadratic_tet.h).
//
// Quasi-static: x minimises the total potential
//     Pi(x) = sum_e V_e psi(F_e(x)) - f_ext . x,   f_ext = lumped gravity m_i g + point forces,
// subject to Dirichlet conditions x_c = target_c (fixed nodes at rest, grasped nodes at their
// tool targets), eliminated from the system. Newton: K_ff dx_f = -(g_f + K_fc dx_c), where the
// Dirichlet increment dx_c is applied with the first iteration of each load step (linearised
// lift; when the predicted state is inadmissible, i.e. has inverted elements, the step including
// dx_c is shortened and the rest of dx_c is applied by the next iteration), later iterations
// move free nodes only, with Armijo backtracking on Pi.
// Linear solves (inexact Newton, Eisenstat & Walker, "Choosing the forcing terms in an inexact
// Newton method", SIAM J. Sci. Comput. 17(1) 1996, choice 2): conjugate gradients on the exact
// tangent K_ff, preconditioned by the CHOLMOD supernodal LL^T factor of an earlier tangent, to
// |r| <= eta |rhs|, eta = min(0.1, 0.9 (|g_k| / |g_{k-1}|)^2) (1e-2 for a lift step), never
// tighter than the final tolerance needs. The tangent is factorised afresh (pattern analysed once
// per set of constrained nodes, lower triangle only, free dofs numbered node by node in CHOLMOD's
// nested-dissection order of the node graph) at the first iteration of a solve (unless the
// previous solve on the same constrained set left a factor: CG with it, up to 25 iterations), when
// CG does not converge in 60 iterations, after a CG solve that needed more than 25, and when CG
// meets a direction of non-positive curvature (K_ff indefinite: Neo-Hookean far from rest); then
// the step is a direct solve with that factor. An indefinite tangent is replaced by one whose
// element stress derivatives dP/dF are projected onto the PSD cone (eigenvalues clamped at 0;
// closed form for Neo-Hookean), then, if needed, a growing diagonal shift is added. When the
// factor is already one of a projected tangent, CG on the current projected tangent with it (up
// to 25 iterations) comes first; a step solved on a projected tangent is lengthened (x2, x4, ...
// up to x64) while the objective keeps falling along it. The convergence
// test is on the true residual, so the answer does not depend on these choices beyond the
// tolerance. When a load step fails (no convergence, more than 12 damped line-search iterations,
// inverted elements that the line search cannot leave), it is halved (load stepping on both
// Dirichlet targets and forces), down to 1/1024 of the whole increment; after a success the next
// increment doubles (continuation).
//
// Dynamic (implicit Euler with step h, lumped mass M, Rayleigh damping C = alpha M + beta K):
// x_{n+1} minimises the incremental potential
//     E(x) = 1/(2 h^2) |x - x_n - h v_n|_M^2 + alpha/(2h) |x - x_n|_M^2
//            + beta/(2h) (x - x_n)^T K(x_n) (x - x_n) + Pi(x),
// whose stationarity is M (v_{n+1} - v_n)/h = f(x_{n+1}) - (alpha M + beta K(x_n)) v_{n+1}; the
// stiffness-proportional damping uses K at the start of the step (Kharevych et al., "Geometric,
// variational integrators for computer animation", SCA 2006, treat the same incremental
// potential). v_{n+1} = (x_{n+1} - x_n)/h.
//
// Positions are 3N vectors, node-major (x of node i at 3 i + k), metres.
#pragma once

#include "mean_dilatation_tet.h"
#include "quadratic_tet.h"

#include <deform/kernels/cholesky_solver.h>
#include <deform/kernels/fem_tet.h>
#include <deform/kernels/sparse.h>
#include <deform/sdk/mesh.h>
#include <deform/sdk/model.h>

#include <array>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace deform::reference_fem {

enum class MaterialModel { Linear, Corotational, NeoHookean };

/// "linear" | "corotational" | "neo_hookean"; throws InputError on anything else.
MaterialModel parseMaterialModel(const std::string& name);
const char* materialModelName(MaterialModel m);

/// Interpolation order of the tetrahedra: 4-node (P1) or 10-node (P2, straight-sided).
enum class ElementOrder { Linear = 1, Quadratic = 2 };

/// 1 -> Linear, 2 -> Quadratic; throws InputError otherwise.
ElementOrder parseElementOrder(long long order);

/// How the volumetric part of the Neo-Hookean energy is integrated: at every quadrature point
/// (the plain displacement element), or on the element's volume (mean dilatation, P2-P0: free of
/// volumetric locking as nu -> 1/2; mean_dilatation_tet.h).
enum class VolumetricFormulation { Displacement, MeanDilatation };
/// The `volumetric` parameter: auto picks by the material (see resolveVolumetricFormulation).
enum class VolumetricChoice { Auto, Displacement, MeanDilatation };
/// Poisson ratio from which `auto` uses the mean-dilatation element (and the force floor of an
/// unloaded solve follows the bulk modulus, see EquilibriumSolver::solve): published soft-tissue
/// and phantom values are 0.45-0.499 (docs/scene-format.md).
inline constexpr Real kNearlyIncompressiblePoisson = 0.45;

/// "auto" | "displacement" | "mean_dilatation"; throws InputError on anything else.
VolumetricChoice parseVolumetricChoice(const std::string& name);
/// auto: MeanDilatation for Neo-Hookean P2 tets at nu >= kNearlyIncompressiblePoisson, else
/// Displacement. An explicit mean_dilatation needs Neo-Hookean and P2 tets (a 4-node tet has a
/// single volume already, the element would not change); InputError otherwise.
VolumetricFormulation resolveVolumetricFormulation(VolumetricChoice choice, MaterialModel model,
                                                   ElementOrder order, Real poisson);
const char* volumetricFormulationName(VolumetricFormulation f);

/// Boundary conditions and loads of one solve.
struct LoadCase {
  std::vector<int> fixedNodes;       ///< held at their rest positions
  std::vector<int> fixedDofs;        ///< single dofs (3 node + axis) held at rest (rollers)
  std::vector<int> prescribedNodes;  ///< held at `targets` (grasped nodes); fixed wins on overlap
  MatX3 targets;                     ///< #prescribedNodes by 3, m
  /// Single dofs (3 node + axis) held at a value, m: the normal component of a node under a
  /// sliding plate. A dof of a fixed or prescribed node stays as those hold it.
  std::vector<std::pair<int, Real>> prescribedDofs;
  Vec3 gravity = Vec3::Zero();                   ///< m/s^2
  std::vector<std::pair<int, Vec3>> nodeForces;  ///< (node, force in N)
};

struct SolveOptions {
  Real tolerance = 1e-8;    ///< |residual_free| <= tolerance * force scale (see SolveReport)
  int maxIterations = 100;  ///< Newton iterations per load step
  int maxHalvings = 10;     ///< load step may shrink to 2^-maxHalvings of the increment
  /// Rejected load steps after which a solve gives up (not converged), however far it got: a
  /// load with no equilibrium in reach otherwise alternates accepted and rejected increments
  /// near the smallest step for as long as it is left to (no answer in 900 s, issue H1).
  int maxFailedLoadSteps = 40;
  /// Newton iterations of one solve over all its load steps; reaching it ends the solve (not
  /// converged, SolveReport::outOfBudget). 0: no limit beyond maxIterations per load step and
  /// maxFailedLoadSteps. Bounds a solve that crosses a long non-convex stretch, or has no
  /// equilibrium within reach, in a time known beforehand (deterministic, unlike a wall clock).
  int maxSolveIterations = 0;
  /// The CG iterations of the inexact Newton steps precondition with a float (Float32, half the
  /// double factor's bytes) or half (Float16, a quarter) copy of the factor
  /// (CholeskySolver::solveFloatInto: the triangular solves dominate a CG iteration and stream the
  /// whole factor; the CG and every direct solve stay in double, so the tolerance and the answer
  /// are the same). None: CHOLMOD's double solve.
  std::optional<CholeskySolver::Precision> preconditionerCopy;
  /// Quasi-static solves: false when state x is no state of the solid (the model's use: its
  /// surface passes through itself away from the held nodes; the reference has no self-contact).
  /// An accepted load step short of the whole load whose state it refuses ends the solve there
  /// (not converged, SolveReport::stoppedEarly): further along a load's path lies only a deeper
  /// fold. Newton's iterates are not checked (tried: rejecting a load step whose iterate folded
  /// after 10 iterations on an indefinite tangent made the hybrid tables' 5 N liver, P2, take
  /// over 150 Newton iterations instead of 78).
  std::function<bool(const VecX& x)> admissible;
};

struct SolveReport {
  bool converged = false;
  int newtonIterations = 0;  ///< total over load steps
  int loadSteps = 0;         ///< accepted load steps
  int spdFallbacks = 0;      ///< factorisations that needed projection or a shift
  /// Newton steps solved on a PSD-projected tangent (the exact one was indefinite), by a fresh
  /// factorisation or by CG with an earlier projected factor.
  int projectedSteps = 0;
  Real residual = 0;    ///< final |g_free|_2, N
  Real forceScale = 0;  ///< max(|f_ext|, |reaction|, 1e-6 E diag^2), N
  double seconds = 0;
  int failedLoadSteps = 0;       ///< load steps rejected (and halved)
  int factorizations = 0;        ///< successful numerical factorisations
  int failedFactorizations = 0;  ///< factorisations that found the matrix not positive definite
  int pcgIterations = 0;         ///< conjugate-gradient iterations (preconditioned by a factor)
  long long factorNonZeros = 0;  ///< nonzeros of the Cholesky factor L (CHOLMOD's analysis)
  double factorFlops = 0;        ///< flops of one numerical factorisation (CHOLMOD's analysis)
  /// SolveOptions::admissible refused an accepted state: the solve ended there, short of its
  /// load (the state is that load step's equilibrium).
  bool stoppedEarly = false;
  /// The solve used SolveOptions::maxSolveIterations Newton iterations and gave up, short of its
  /// load.
  bool outOfBudget = false;
  /// Wall-time breakdown of `seconds` (s): pattern analysis (when the constrained set is new:
  /// ordering, the free block's pattern and element slots, symbolic factorisation),
  /// stiffness assembly (element tangents, projection, scatter), numerical factorisation,
  /// triangular solves, and objective / gradient evaluations (line search, residuals).
  double analyzeSeconds = 0, assemblySeconds = 0, factorSeconds = 0, solveSeconds = 0,
         objectiveSeconds = 0;
};

/// Mesh, material, element rest data, lumped masses and the stiffness sparsity pattern.
class FemSystem {
 public:
  FemSystem(TetMesh rest, const Material& material, MaterialModel model,
            CorotationalTangent corotationalTangent = CorotationalTangent::Exact);
  /// `rest` is the corner (P1) mesh; Quadratic adds the midside nodes (see the file comment).
  FemSystem(TetMesh rest, const Material& material, MaterialModel model, ElementOrder order,
            CorotationalTangent corotationalTangent = CorotationalTangent::Exact);
  /// With the volumetric formulation (MeanDilatation: Neo-Hookean P2 only, else InputError).
  FemSystem(TetMesh rest, const Material& material, MaterialModel model, ElementOrder order,
            VolumetricFormulation volumetric);

  /// Rest nodes (all of them: corners, then midside nodes for P2) and the corner tets.
  const TetMesh& rest() const { return m_rest; }
  int numNodes() const { return m_rest.numVertices(); }
  int numCornerNodes() const { return m_numCorners; }  ///< nodes of the P1 mesh
  ElementOrder order() const { return m_order; }
  int nodesPerElement() const { return m_order == ElementOrder::Quadratic ? 10 : 4; }
  /// Node a (0..nodesPerElement()-1, corners first, then the edges of kQuadraticEdges) of tet t.
  int elementNode(int t, int a) const { return m_elemNodes[size_t(t * nodesPerElement() + a)]; }
  /// Midside node of the edge between corner nodes a and b (-1 when there is none).
  int edgeNode(int a, int b) const;
  MaterialModel model() const { return m_model; }
  VolumetricFormulation volumetric() const { return m_volumetric; }
  const Material& material() const { return m_material; }
  /// Pa: the modulus that scales the internal forces' round-off: E, or the bulk modulus when that
  /// is larger at nu >= kNearlyIncompressiblePoisson (kappa = 167 E at nu = 0.499).
  Real stiffestModulus() const;
  VecX restPositions() const;  ///< 3N
  /// #N, kg: lumped mass (P1: rho V / 4 per tet; P2: HRZ, rho V / 36 per corner, 4 rho V / 27
  /// per midside node). Used by the dynamic solve.
  const VecX& nodeMass() const { return m_mass; }
  /// #N, kg: integral rho N_i dV, the consistent gravity weight (P1: = nodeMass; P2: corners
  /// -rho V / 20, midside nodes rho V / 5 per tet).
  const VecX& gravityWeight() const { return m_gravityWeight; }
  long long degenerateElements() const { return m_degenerate; }  ///< skipped at rest

  /// Elastic energy sum_e V_e psi(F_e) (J); +inf when an element is inverted (Neo-Hookean).
  Real elasticEnergy(const VecX& x) const;
  /// dW/dx (3N), N; returns the elastic energy (as elasticEnergy, computed in the same pass).
  Real elasticGradient(const VecX& x, VecX& g) const;
  /// Tangent stiffness values on the full 3N x 3N pattern (stiffnessPattern()).
  void stiffnessValues(const VecX& x, VecX& values, bool projectSpd) const;
  /// The same values gathered into a symmetric pattern of which one triangle is stored: values
  /// gets `size` entries, and the element stiffness entry (r, c), r >= c (element dofs 3 a + k,
  /// one of each symmetric pair), of tet t is added to values(slots[t * P + i]) when that is
  /// >= 0 (dropped otherwise), i the position of (r, c) in the column-major lower triangle
  /// (c = 0: r = 0..n-1, then c = 1: r = 1..n-1, ...), P = n (n + 1) / 2, n = 3
  /// nodesPerElement(). Why: half the scatter of the full element matrix, and no second lookup.
  void stiffnessValues(const VecX& x, Eigen::Ref<VecX> values, bool projectSpd,
                       const int* slots) const;
  /// out = K(x) v (3N): the exact tangent applied element by element, skipping the elements on
  /// whose nodes v vanishes (the lift's K_fc dc touches only the elements of moving nodes).
  void stiffnessTimes(const VecX& x, const VecX& v, VecX& out) const;
  /// Full-pattern index of element stiffness entry (r, c) of tet t (column-major, r, c < 3
  /// nodesPerElement()).
  int elementSlot(int t, int r, int c) const {
    const int nd = 3 * nodesPerElement();
    return m_slots[size_t(t) * size_t(nd * nd) + size_t(c * nd + r)];
  }
  const SparseMatrix& stiffnessPattern() const { return m_pattern; }

  /// External force vector (3N) of a load case: gravityWeight_i g + point forces.
  VecX externalForce(const LoadCase& loads) const;

 private:
  template <class Fn>
  void forEachMaterial(Fn&& fn) const;
  /// Calls sink(t, k) with the column-major element stiffness k (3n x 3n) of every tet t that
  /// is not degenerate nor inverted, and for which want(t) holds.
  /// One P2 tet (t) at x: evaluateQuadraticTet with `mat`, or the mean-dilatation element.
  template <class Mat>
  void evaluateQuadratic(const Mat& mat, int t, const VecX& x, TetEvalMode mode,
                         QuadraticTetEvaluation& e, bool projectSpd) const;
  template <class Sink, class Want>
  void forEachElementStiffness(const VecX& x, bool projectSpd, Sink&& sink, Want&& want) const;
  void addMidsideNodes();
  TetMesh m_rest;
  Material m_material;
  MaterialModel m_model;
  ElementOrder m_order = ElementOrder::Linear;
  VolumetricFormulation m_volumetric = VolumetricFormulation::Displacement;
  LameParameters m_lame;
  MeanDilatationNeoHookean m_meanDilatation;
  CorotationalTangent m_corotationalTangent;
  int m_numCorners = 0;
  std::vector<int> m_elemNodes;                  ///< #tets x nodesPerElement()
  std::vector<std::pair<int, int>> m_edges;      ///< sorted corner pairs of the midside nodes
  std::vector<TetRest> m_elements;               ///< one per tet (volume <= 0: degenerate, skipped)
  std::vector<QuadraticTetRest> m_quadElements;  ///< P2 only, one per tet
  VecX m_mass, m_gravityWeight;
  long long m_degenerate = 0;
  SparseMatrix m_pattern;    ///< full symmetric pattern, values unused
  std::vector<int> m_slots;  ///< element stiffness (3n x 3n, col-major) -> value index, per tet
};

/// Extra terms of the dynamic incremental potential (see the file comment).
struct InertiaTerms {
  VecX weight;         ///< 3N: M (1/h^2 + alpha/h)
  VecX center;         ///< 3N
  VecX dampingValues;  ///< beta/h K(x_n) on the full pattern (empty: no stiffness damping)
  VecX dampingCenter;  ///< x_n
};

/// Newton solver owning the factorisation (reused while the constrained set is unchanged).
class EquilibriumSolver {
 public:
  explicit EquilibriumSolver(const FemSystem& system) : m_sys(system) {}

  /// Static equilibrium under `loads`, starting from x (3N, in equilibrium with external force
  /// fStart and with its constrained nodes where they are) and ending at the solution (or at the
  /// last converged load step). fStart empty: zero.
  SolveReport solveStatic(const LoadCase& loads, VecX& x, const VecX& fStart = VecX(),
                          const SolveOptions& options = {});

  /// One implicit Euler step of size h: x, v (3N) in and out.
  SolveReport stepDynamic(const LoadCase& loads, Real h, Real alpha, Real beta, VecX& x, VecX& v,
                          const SolveOptions& options = {});

  /// Gradient of the last solved objective at the solution (3N): on constrained dofs it is the
  /// force the constraints exert on the nodes; minus it is what the tissue exerts on the tool.
  const VecX& lastGradient() const { return m_gradient; }

 private:
  SolveReport solve(const LoadCase& loads, VecX& x, const VecX& fStart, const InertiaTerms* inertia,
                    const SolveOptions& options);
  // The pieces of solve() (equilibrium_solver.cpp): the constrained dofs, load stepping, and in
  // each load step Newton iterations (an inexact Newton direction, then the Dirichlet lift or a
  // line search).
  struct Newton;  ///< one solve's state
  enum class NewtonOutcome { Continue, Converged, Failed };
  /// The sorted constrained dofs of `loads`, their final positions written into target (fixed
  /// wins over prescribed).
  std::vector<int> constrainedDofs(const LoadCase& loads, VecX& target) const;
  /// No force at the start nor the end, x at rest, every constrained dof's target at rest.
  bool isUnloadedRest(const VecX& x, const VecX& fStart, const VecX& fEnd,
                      const std::vector<int>& cdofs, const VecX& target) const;
  /// |free part of grad|; sets the report's force scale (|f|, |constrained part|, the floor).
  Real residual(Newton& s, const VecX& grad, const VecX& f) const;
  /// One load step: from xs (converged at the previous level) to forces f and targets tgt.
  bool loadStep(Newton& s, VecX& xs, const VecX& f, const VecX& tgt);
  /// The Newton step at xs into s.step (CG with the old factor, or a fresh factorisation).
  bool newtonDirection(Newton& s, const VecX& xs);
  /// Applies the step with the constrained dofs' remaining increment, shortened while the
  /// state is inadmissible.
  NewtonOutcome liftStep(Newton& s, VecX& xs, const VecX& f);
  /// Backtracking (Armijo / approximate Wolfe) line search along s.step, and its fallbacks.
  NewtonOutcome lineSearchStep(Newton& s, VecX& xs, const VecX& f);
  bool armijo(Newton& s, const VecX& xs, const VecX& f, Real phi0, Real slope, Real& alpha);
  /// The full step when the predicted decrease is below the objective's round-off.
  NewtonOutcome roundOffStep(Newton& s, VecX& xs, const VecX& f);
  void prepareConstraints(const std::vector<int>& constrainedDofs);
  Real objective(const VecX& x, const VecX& f, const InertiaTerms* in) const;
  /// Gradient into g; returns the objective (as objective()) from the same element pass.
  Real objectiveGradient(const VecX& x, const VecX& f, const InertiaTerms* in, VecX& g) const;
  /// Tangent at x (projectSpd: PSD-projected) with the inertia terms into m_Kff's values (free
  /// block, lower). With stiffness damping it goes through m_fullValues (full pattern).
  void assembleFree(const VecX& x, const InertiaTerms* in, bool projectSpd);
  void addInertiaDiagonal(const InertiaTerms* in);
  /// rhs -= K_fc dc (dc: the increments of the constrained dofs), element by element.
  void subtractLiftForce(const VecX& x, const InertiaTerms* in, const VecX& dc, VecX& rhs);
  /// Factorises m_Kff (the exact tangent, assembled by the caller), else (when not positive
  /// definite, or known to be indefinite) the tangent with PSD-projected element stress
  /// derivatives, else that with a growing diagonal shift. A fallback (not the operator
  /// itself) is counted in `fallbacks`. m_Kff holds what was factorised afterwards.
  bool factorize(const VecX& x, const InertiaTerms* in, bool indefinite, int& fallbacks,
                 bool projectedAssembled = false);
  /// Solves K_ff x = b (the operator: m_Kff's values, the exact tangent) to |residual| <=
  /// tolerance by conjugate gradients preconditioned with the current factor. Returns the
  /// iterations, -1 when it did not converge within maxIterations, -2 when it met a direction
  /// of non-positive curvature.
  int preconditionedCg(const VecX& b, Real tolerance, int maxIterations, VecX& x);

  const FemSystem& m_sys;
  std::vector<int> m_constrainedDofs;  ///< sorted; the set the pattern below was built for
  bool m_prepared = false;
  std::vector<int> m_freeIndex;  ///< dof -> free index or -1
  /// Full-pattern value index -> free value index or -1, and element lower-triangle entry ->
  /// free value index. Large (7 and 16 MB on the 51k-tet liver) and rebuilt per constraint set:
  /// on cached blocks that are not faulted in again (see LargePageAllocator).
  std::vector<int, LargePageAllocator<int>> m_fullToFree;
  std::vector<int, LargePageAllocator<int>> m_elementFreeSlots;
  /// Free block, lower triangle. Its values are the tangent of the current Newton iteration:
  /// the exact one (CG's operator) until a factorisation needs the projected one instead.
  SparseMatrix m_Kff;
  std::vector<int> m_freeDiagonal;  ///< free dof -> value index of its diagonal in m_Kff
  VecX m_fullValues;                ///< full-pattern tangent (stiffness damping only)
  VecX m_liftForce;                 ///< K dc (3N), buffer of subtractLiftForce
  bool m_haveFactor = false;        ///< m_chol holds a factor usable as a preconditioner
  bool m_factorProjected = false;   ///< that factor is of a projected (or shifted) tangent
  long long m_factorNonZeros = 0;
  double m_factorFlops = 0;
  std::unique_ptr<CholeskySolver> m_chol;
  VecX m_gradient;
  SolveReport* m_report = nullptr;  ///< the report of the running solve (timings), else null
  /// SolveOptions::preconditionerCopy of the running solve.
  std::optional<CholeskySolver::Precision> m_preconditionerCopy;
};

/// Convenience: static equilibrium of `system` under `loads` from the rest state. Returns the 3N
/// solution; report filled when given.
VecX solveEquilibrium(const FemSystem& system, const LoadCase& loads,
                      const SolveOptions& options = {}, SolveReport* report = nullptr);

/// A point force spread over a small pressure patch of the boundary (see PointLoadSpreader).
struct PointLoadPatch {
  std::vector<int> nodes;     ///< boundary nodes of the patch, the centre first
  std::vector<Real> weights;  ///< share of the force per node; sums to 1
  Real radius = 0;            ///< R actually used, m
};

/// The consistent nodal load of a point force F applied "at boundary node c" of a continuum.
/// A force on a single node is singular in 3D elasticity (the displacement under it grows
/// without bound as the mesh is refined, and Neo-Hookean elements around the node invert under
/// large forces), so the force is read as a pressure patch of radius R around c:
///     t(x) = F k(|X - X_c|) / integral_patch k dA,   k(rho) = 1 - (rho / R)^2 for rho < R,
/// a paraboloid profile (the Hertz contact pressure of a rigid sphere tip has the same support
/// and is smooth at the centre), whose consistent lumped nodal load is
///     f_i = F A_i k(rho_i) / sum_j A_j k(rho_j),
/// A_i the lumped (one third of each incident triangle) boundary area of node i. The patch is
/// the set of boundary nodes connected to c through boundary edges whose nodes all lie within R
/// (so a thin organ's far side is never loaded). R = max(radius, 1.5 x the longest boundary edge
/// at c): the patch always covers c's one-ring (each of whose nodes gets k >= 0.55), on any
/// mesh. Distances are taken at rest (a dead load with a fixed distribution). The total force is
/// F exactly.
///
/// Quadratic elements (constructed from a FemSystem): the same patch node set (over the corner
/// nodes) and profile, but the consistent load of the 6-node boundary triangles,
///     f_i = F integral N_i k dA / integral k dA,
/// over the boundary triangles with a corner in the patch (k clamped at 0 outside R), integrated
/// on 16 sub-triangles per triangle with the 6-point degree-4 rule (exact where k is a
/// polynomial); nodes of those triangles (corners and midside) all get a share, which can be
/// negative at corners (as the consistent load of a uniform pressure is 0 at a P2 corner).
class PointLoadSpreader {
 public:
  /// Boundary triangles, lumped areas and adjacency of the mesh's boundary.
  explicit PointLoadSpreader(const TetMesh& mesh);
  /// For the system's elements (P1: as above; P2: consistent on 6-node triangles).
  explicit PointLoadSpreader(const FemSystem& system);
  /// The patch around node c; a node with no boundary triangle gets the whole force.
  PointLoadPatch patch(int c, Real radius) const;

 private:
  PointLoadPatch quadraticPatch(PointLoadPatch p) const;
  MatX3 m_rest;
  VecX m_area;                                  ///< #N lumped boundary area, m^2 (0: interior)
  std::vector<std::vector<int>> m_neighbors;    ///< boundary edges per node
  std::vector<std::array<int, 6>> m_quadFaces;  ///< P2: boundary triangles (corners, then edges
                                                ///< 01, 12, 20); empty for P1
  std::vector<std::vector<int>> m_nodeFaces;    ///< P2: boundary triangles per corner node
};

/// Nodal forces equivalent to a uniform traction t (N/m^2) on the boundary triangles selected by
/// `select` (a face is used when all three of its vertices pass): each triangle gives area/3 t
/// to each corner. Returned as (node, force) pairs, one per node touched.
std::vector<std::pair<int, Vec3>> tractionForces(const TetMesh& mesh, const Vec3& traction,
                                                 const std::function<bool(const Vec3&)>& select);
/// The same for the system's elements: P1 as above; P2 the consistent load of the 6-node
/// triangles (0 on the corners, area/3 t on each midside node).
std::vector<std::pair<int, Vec3>> tractionForces(const FemSystem& system, const Vec3& traction,
                                                 const std::function<bool(const Vec3&)>& select);

}  // namespace deform::reference_fem
