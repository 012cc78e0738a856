// EquilibriumSolver (fem_solver.h): Newton with load stepping, line search and inexact CG
// solves; solveEquilibrium().
#include "fem_solver.h"

#include <deform/geometry/organ_tets.h>
#include <deform/geometry/pressure_patch.h>
#include <deform/sdk/error.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <limits>
#include <map>
#include <string>

namespace deform::reference_fem {

namespace {

/// Damped (line-searched, alpha < 1) Newton iterations allowed in one load step before it is
/// declared failed and halved.
constexpr int kMaxDampedIterations = 12;
/// Largest factor by which a step solved with a projected tangent is lengthened while the
/// objective keeps falling along it (see lineSearchStep).
constexpr Real kMaxExtrapolation = 64;
/// Inexact Newton (see loadStep): largest relative accuracy of a CG solve, the accuracy of the
/// Dirichlet predictor, the CG iterations after which the tangent is refactorised for the next
/// Newton iteration, and the most CG iterations before it is refactorised at once.
constexpr Real kMaxForcing = 0.1;
constexpr Real kLiftForcing = 1e-2;
constexpr int kRefactorCg = 25;
constexpr int kMaxCg = 60;
constexpr Real kArmijo = 1e-4;           // sufficient decrease (delta)
constexpr Real kObjectiveNoise = 1e-10;  // relative round-off allowed in Pi for that condition

using Clock = std::chrono::steady_clock;
/// DEFORM_REFFEM_TRACE set: one line per Newton iteration on stderr (residual, CG outcome, step
/// length and where it is largest), for diagnosing slow solves (diagnose_newton.cpp).
const bool kTrace = std::getenv("DEFORM_REFFEM_TRACE") != nullptr;

/// Adds the wall time of its scope to `total` (s).
class ScopedTimer {
 public:
  explicit ScopedTimer(double& total) : m_total(total), m_start(Clock::now()) {}
  ~ScopedTimer() { m_total += std::chrono::duration<double>(Clock::now() - m_start).count(); }
  ScopedTimer(const ScopedTimer&) = delete;
  ScopedTimer& operator=(const ScopedTimer&) = delete;

 private:
  double& m_total;
  Clock::time_point m_start;
};

Eigen::Map<const SparseMatrix> withValues(const SparseMatrix& pattern, const VecX& values) {
  return Eigen::Map<const SparseMatrix>(pattern.rows(), pattern.cols(), pattern.nonZeros(),
                                        pattern.outerIndexPtr(), pattern.innerIndexPtr(),
                                        values.data());
}

/// Fill-reducing elimination order of the graph of `nodes` (indices into the 3N x 3N pattern P,
/// whose 3x3 node blocks are dense): CHOLMOD's nested dissection (NESDIS: METIS bisection with
/// constrained minimum degree on the parts) of the node-level pattern. Returns positions into
/// `nodes` in elimination order. Why nodes, not dofs: the graph is 9x smaller, so the ordering
/// takes ~20 ms instead of ~0.15 s on the 51k-tet liver, and the factor is as sparse (5.79
/// Gflop; METIS on the dof graph, CHOLMOD's own choice there: 5.85; METIS on nodes 6.03; AMD 12).
std::vector<int> freeNodeOrdering(const SparseMatrix& P, const std::vector<int>& nodes) {
  const int nn = int(nodes.size());
  std::vector<int> local(size_t(P.rows() / 3), -1);
  for (int k = 0; k < nn; ++k) local[size_t(nodes[size_t(k)])] = k;
  cholmod_common c;
  cholmod_start(&c);
  c.print = 0;
  long long nnz = 0;
  for (int k = 0; k < nn; ++k) {
    const int col = 3 * nodes[size_t(k)];
    nnz += (P.outerIndexPtr()[col + 1] - P.outerIndexPtr()[col]) / 3;
  }
  cholmod_sparse* A =
      cholmod_allocate_sparse(size_t(nn), size_t(nn), size_t(nnz), 1, 1, -1, CHOLMOD_PATTERN, &c);
  int* Ap = static_cast<int*>(A->p);
  int* Ai = static_cast<int*>(A->i);
  int q = 0;
  for (int k = 0; k < nn; ++k) {
    Ap[k] = q;
    const int col = 3 * nodes[size_t(k)];
    std::vector<int> rows;
    for (int p = P.outerIndexPtr()[col]; p < P.outerIndexPtr()[col + 1]; p += 3) {
      const int r = local[size_t(P.innerIndexPtr()[p] / 3)];
      if (r >= k) rows.push_back(r);
    }
    std::sort(rows.begin(), rows.end());
    for (int r : rows) Ai[q++] = r;
  }
  Ap[nn] = q;
  c.nmethods = 1;
  c.method[0].ordering = CHOLMOD_NESDIS;
  cholmod_factor* L = cholmod_analyze(A, &c);
  std::vector<int> perm(static_cast<size_t>(nn));
  if (L) {
    const int* Lp = static_cast<const int*>(L->Perm);
    for (int k = 0; k < nn; ++k) perm[size_t(k)] = Lp[k];
  } else {
    for (int k = 0; k < nn; ++k) perm[size_t(k)] = k;
  }
  cholmod_free_factor(&L, &c);
  cholmod_free_sparse(&A, &c);
  cholmod_finish(&c);
  return perm;
}

}  // namespace

// ---- EquilibriumSolver ----------------------------------------------------------------------

void EquilibriumSolver::prepareConstraints(const std::vector<int>& dofs) {
  if (m_prepared && dofs == m_constrainedDofs) return;
  m_constrainedDofs = dofs;
  const int n = m_sys.numNodes(), ndof = 3 * n;
  m_freeIndex.assign(size_t(ndof), 0);
  for (int d : dofs) m_freeIndex[size_t(d)] = -1;
  const SparseMatrix& P = m_sys.stiffnessPattern();
  int nf = 0;
  {
    // Free dofs numbered node by node in a fill-reducing order of the node graph, so CHOLMOD
    // factorises in the given order (see freeNodeOrdering).
    std::vector<int> nodes;
    for (int i = 0; i < n; ++i)
      if (m_freeIndex[size_t(3 * i)] >= 0 || m_freeIndex[size_t(3 * i + 1)] >= 0 ||
          m_freeIndex[size_t(3 * i + 2)] >= 0)
        nodes.push_back(i);
    const std::vector<int> perm = freeNodeOrdering(P, nodes);
    for (int k : perm)
      for (int a = 0; a < 3; ++a)
        if (m_freeIndex[size_t(3 * nodes[size_t(k)] + a)] >= 0)
          m_freeIndex[size_t(3 * nodes[size_t(k)] + a)] = nf++;
  }
  // K_ff holds its lower triangle only (CHOLMOD reads no more): entries (fr, fc), fr >= fc, of
  // the full pattern's free block, each remembered by its full-pattern index.
  std::vector<int> count(size_t(nf) + 1, 0);
  for (int c = 0; c < ndof; ++c) {
    const int fc = m_freeIndex[size_t(c)];
    if (fc < 0) continue;
    for (int p = P.outerIndexPtr()[c]; p < P.outerIndexPtr()[c + 1]; ++p) {
      const int fr = m_freeIndex[size_t(P.innerIndexPtr()[p])];
      if (fr >= fc) ++count[size_t(fc) + 1];
    }
  }
  for (int fc = 0; fc < nf; ++fc) count[size_t(fc) + 1] += count[size_t(fc)];
  std::vector<std::pair<int, int>, LargePageAllocator<std::pair<int, int>>> entries(
      static_cast<size_t>(count[size_t(nf)]));  // (row, full index)
  {
    std::vector<int> next(count.begin(), count.end() - 1);
    for (int c = 0; c < ndof; ++c) {
      const int fc = m_freeIndex[size_t(c)];
      if (fc < 0) continue;
      for (int p = P.outerIndexPtr()[c]; p < P.outerIndexPtr()[c + 1]; ++p) {
        const int fr = m_freeIndex[size_t(P.innerIndexPtr()[p])];
        if (fr >= fc) entries[size_t(next[size_t(fc)]++)] = {fr, p};
      }
    }
  }
  m_Kff.resize(nf, nf);
  m_Kff.resizeNonZeros(Eigen::Index(entries.size()));
  m_fullToFree.assign(size_t(P.nonZeros()), -1);
  for (int fc = 0; fc < nf; ++fc) {
    m_Kff.outerIndexPtr()[fc] = count[size_t(fc)];
    std::sort(entries.begin() + count[size_t(fc)], entries.begin() + count[size_t(fc) + 1]);
  }
  m_Kff.outerIndexPtr()[nf] = count[size_t(nf)];
  for (size_t q = 0; q < entries.size(); ++q) {
    m_Kff.innerIndexPtr()[q] = entries[q].first;
    m_fullToFree[size_t(entries[q].second)] = int(q);
  }
  // Each element entry pair (r, c) / (c, r) lands on the one of its two full-pattern entries
  // that lies in K_ff's lower triangle (or nowhere, when a dof is constrained).
  {
    const int nt = m_sys.rest().numTets(), nd = 3 * m_sys.nodesPerElement();
    const int np = nd * (nd + 1) / 2;
    m_elementFreeSlots.assign(size_t(nt) * size_t(np), -1);
    const int nen = m_sys.nodesPerElement();
    std::array<int, 30> dofFree{};  // free index of each element dof (-1: constrained)
    for (int t = 0; t < nt; ++t) {
      for (int a = 0; a < nen; ++a)
        for (int k = 0; k < 3; ++k)
          dofFree[size_t(3 * a + k)] = m_freeIndex[size_t(3 * m_sys.elementNode(t, a) + k)];
      int* slot = m_elementFreeSlots.data() + size_t(t) * size_t(np);
      for (int c = 0; c < nd; ++c)
        for (int r = c; r < nd; ++r, ++slot) {
          const int fr = dofFree[size_t(r)], fc = dofFree[size_t(c)];
          if (fr < 0 || fc < 0) continue;  // stays -1
          *slot = m_fullToFree[size_t(fr >= fc ? m_sys.elementSlot(t, r, c)
                                               : m_sys.elementSlot(t, c, r))];
        }
    }
  }
  m_Kff.coeffs().setZero();
  m_freeDiagonal.assign(size_t(nf), 0);
  for (int fc = 0; fc < nf; ++fc) {
    m_freeDiagonal[size_t(fc)] = m_Kff.outerIndexPtr()[fc];  // lower CSC: diagonal comes first
    if (m_Kff.innerIndexPtr()[m_freeDiagonal[size_t(fc)]] != fc)
      throw std::logic_error("reference_fem: stiffness pattern without a diagonal entry");
  }
  m_haveFactor = false;
  installCholmodAllocator();  // the factor on cached blocks (see sparse.h)
  m_chol = std::make_unique<CholeskySolver>();
  m_chol->setKind(CholeskySolver::Kind::Supernodal);
  m_chol->cholmod().print = 0;  // a non-PD matrix is handled here, not printed
  if (nf > 0) {
    m_chol->cholmod().nmethods = 1;  // m_Kff is already in fill-reducing order
    m_chol->cholmod().method[0].ordering = CHOLMOD_NATURAL;
    m_chol->analyzePattern(m_Kff);
    m_factorNonZeros = static_cast<long long>(m_chol->cholmod().lnz);
    m_factorFlops = m_chol->cholmod().fl;
  }
  m_prepared = true;
}

Real EquilibriumSolver::objective(const VecX& x, const VecX& f, const InertiaTerms* in) const {
  ScopedTimer timer(m_report->objectiveSeconds);
  Real phi = m_sys.elasticEnergy(x);
  if (!std::isfinite(phi)) return std::numeric_limits<Real>::infinity();
  phi -= f.dot(x);
  if (in) {
    phi += 0.5 * (in->weight.array() * (x - in->center).array().square()).sum();
    if (in->dampingValues.size()) {
      const VecX d = x - in->dampingCenter;
      phi += 0.5 * d.dot(withValues(m_sys.stiffnessPattern(), in->dampingValues) * d);
    }
  }
  return phi;
}

Real EquilibriumSolver::objectiveGradient(const VecX& x, const VecX& f, const InertiaTerms* in,
                                          VecX& g) const {
  ScopedTimer timer(m_report->objectiveSeconds);
  Real phi = m_sys.elasticGradient(x, g);
  g -= f;
  if (!std::isfinite(phi)) phi = std::numeric_limits<Real>::infinity();
  phi -= f.dot(x);
  if (in) {
    phi += 0.5 * (in->weight.array() * (x - in->center).array().square()).sum();
    g.array() += in->weight.array() * (x - in->center).array();
    if (in->dampingValues.size()) {
      const VecX d = x - in->dampingCenter;
      const VecX Kd = withValues(m_sys.stiffnessPattern(), in->dampingValues) * d;
      phi += 0.5 * d.dot(Kd);
      g += Kd;
    }
  }
  return phi;
}

void EquilibriumSolver::assembleFree(const VecX& x, const InertiaTerms* in, bool projectSpd) {
  Eigen::Map<VecX> free(m_Kff.valuePtr(), m_Kff.nonZeros());
  if (in && in->dampingValues.size()) {
    {
      ScopedTimer timer(m_report->assemblySeconds);
      m_sys.stiffnessValues(x, m_fullValues, projectSpd);
    }
    m_fullValues += in->dampingValues;
    free.setZero();
    for (size_t p = 0; p < m_fullToFree.size(); ++p)
      if (m_fullToFree[p] >= 0) free(m_fullToFree[p]) += m_fullValues(Eigen::Index(p));
  } else {
    // Straight into the free block's lower triangle: each element adds one entry of every
    // symmetric pair.
    ScopedTimer timer(m_report->assemblySeconds);
    m_sys.stiffnessValues(x, free, projectSpd, m_elementFreeSlots.data());
  }
  addInertiaDiagonal(in);
}

void EquilibriumSolver::addInertiaDiagonal(const InertiaTerms* in) {
  if (!in) return;
  Real* values = m_Kff.valuePtr();
  for (size_t d = 0; d < m_freeIndex.size(); ++d)
    if (m_freeIndex[d] >= 0)
      values[m_freeDiagonal[size_t(m_freeIndex[d])]] += in->weight(Eigen::Index(d));
}

void EquilibriumSolver::subtractLiftForce(const VecX& x, const InertiaTerms* in, const VecX& dc,
                                          VecX& rhs) {
  {
    ScopedTimer timer(m_report->assemblySeconds);
    m_sys.stiffnessTimes(x, dc, m_liftForce);
  }
  if (in && in->dampingValues.size())
    m_liftForce += withValues(m_sys.stiffnessPattern(), in->dampingValues) * dc;
  // The inertia terms are diagonal: no coupling of free and constrained dofs.
  for (size_t d = 0; d < m_freeIndex.size(); ++d)
    if (m_freeIndex[d] >= 0) rhs(m_freeIndex[d]) -= m_liftForce(Eigen::Index(d));
}

bool EquilibriumSolver::factorize(const VecX& x, const InertiaTerms* in, bool indefinite,
                                  int& fallbacks, bool projectedAssembled) {
  m_haveFactor = false;
  Real shifted = 0;  // diagonal shift already in m_Kff
  for (int attempt = indefinite ? 1 : 0; attempt < 8; ++attempt) {
    if (attempt == 1) {
      // Not positive definite: project the element stress derivatives onto the PSD cone.
      if (!projectedAssembled) assembleFree(x, in, true);
    } else if (attempt > 1) {
      Real mean = 0;
      for (int fd : m_freeDiagonal) mean += m_Kff.valuePtr()[fd] - shifted;
      mean /= std::max<size_t>(m_freeDiagonal.size(), 1);
      const Real shift = 1e-8 * std::pow(10.0, attempt - 2) * mean;
      for (int fd : m_freeDiagonal) m_Kff.valuePtr()[fd] += shift - shifted;
      shifted = shift;
    }
    {
      ScopedTimer timer(m_report->factorSeconds);
      const SerialOpenMpScope serial;
      m_chol->factorize(m_Kff);
      m_chol->dropFloatFactor();
      if (m_preconditionerCopy && m_chol->info() == Eigen::Success)
        m_chol->buildFloatFactor(*m_preconditionerCopy);
    }
    if (m_chol->info() == Eigen::Success) {
      if (attempt > 0) ++fallbacks;
      ++m_report->factorizations;
      m_haveFactor = true;
      m_factorProjected = attempt > 0;
      return true;
    }
    ++m_report->failedFactorizations;
  }
  return false;
}

int EquilibriumSolver::preconditionedCg(const VecX& b, Real tolerance, int maxIterations,
                                        VecX& xOut) {
  ScopedTimer timer(m_report->solveSeconds);
  const SparseMatrix& K = m_Kff;  // the exact tangent (assembled this iteration)
  xOut = VecX::Zero(b.size());
  VecX r = b, z, p, q(b.size());
  const auto precondition = [&] {
    if (m_chol->hasFloatFactor())
      m_chol->solveFloatInto(r, z);
    else
      z = m_chol->solve(r);
  };
  precondition();
  p = z;
  Real rz = r.dot(z);
  for (int it = 1; it <= maxIterations; ++it) {
    q.noalias() = K.selfadjointView<Eigen::Lower>() * p;
    const Real pq = p.dot(q);
    if (!(pq > 0)) return -2;  // the operator is not positive definite
    const Real a = rz / pq;
    xOut += a * p;
    r -= a * q;
    ++m_report->pcgIterations;
    if (r.norm() <= tolerance) return it;
    precondition();
    const Real rzNew = r.dot(z);
    p = z + (rzNew / rz) * p;
    rz = rzNew;
  }
  return -1;
}

/// The state of one solve(): its options and report, the constrained dofs, and the buffers and
/// iterate of the current load step's Newton iterations.
struct EquilibriumSolver::Newton {
  const InertiaTerms* in = nullptr;
  const SolveOptions& opt;
  SolveReport& rep;
  const std::vector<int>& cdofs;
  int ndof = 0, nf = 0;
  Real floorForce = 0;
  bool refactor = false;      ///< CG was slow: factorise the next tangent afresh
  bool staleFactor = false;   ///< the factor is a previous solve's (no fresh one yet)
  bool modifiedStep = false;  ///< the step solves a projected (not the exact) tangent
  VecX g, gTrial, rhs, dxFree, step;
  // The load step's Newton iterations.
  VecX dc;                ///< remaining increments of the constrained dofs
  bool lift = false;      ///< dc is not yet applied
  int damped = 0;         ///< iterations whose line search cut the Newton step
  Real prevResidual = 0;  ///< of the previous iteration (the forcing term)
  Real phiCur = 0;        ///< objective at the iterate
  bool haveG = false;     ///< g and phiCur already hold the iterate's values
  Real phiNext = 0;       ///< objective at the accepted full step (with gTrial)

  Newton(const InertiaTerms* inertia, const SolveOptions& options, SolveReport& report,
         const std::vector<int>& constrained)
      : in(inertia), opt(options), rep(report), cdofs(constrained) {}
};

std::vector<int> EquilibriumSolver::constrainedDofs(const LoadCase& loads, VecX& target) const {
  const int n = m_sys.numNodes();
  std::vector<char> isFixed(size_t(n), 0);
  std::vector<int> cdofs;
  const MatX3& restV = m_sys.rest().V;
  for (int node : loads.fixedNodes) {
    isFixed[size_t(node)] = 1;
    for (int k = 0; k < 3; ++k) cdofs.push_back(3 * node + k);
    target.segment<3>(3 * node) = restV.row(node).transpose();
  }
  for (size_t i = 0; i < loads.prescribedNodes.size(); ++i) {
    const int node = loads.prescribedNodes[i];
    if (isFixed[size_t(node)]) continue;
    for (int k = 0; k < 3; ++k) cdofs.push_back(3 * node + k);
    target.segment<3>(3 * node) = loads.targets.row(Eigen::Index(i)).transpose();
  }
  const size_t held = cdofs.size();  // the dofs of the fully held nodes
  for (int d : loads.fixedDofs) {
    cdofs.push_back(d);
    target(d) = restV(d / 3, d % 3);
  }
  std::vector<int> whole(cdofs.begin(), cdofs.begin() + std::ptrdiff_t(held));
  std::sort(whole.begin(), whole.end());
  for (const auto& [d, value] : loads.prescribedDofs) {
    if (std::binary_search(whole.begin(), whole.end(), d)) continue;
    cdofs.push_back(d);
    target(d) = value;
  }
  std::sort(cdofs.begin(), cdofs.end());
  cdofs.erase(std::unique(cdofs.begin(), cdofs.end()), cdofs.end());
  return cdofs;
}

bool EquilibriumSolver::isUnloadedRest(const VecX& x, const VecX& fStart, const VecX& fEnd,
                                       const std::vector<int>& cdofs, const VecX& target) const {
  if ((fStart.array() != 0).any() || (fEnd.array() != 0).any()) return false;
  const VecX rest = m_sys.restPositions();
  if (x != rest) return false;
  for (int d : cdofs)
    if (target(d) != rest(d)) return false;
  return true;
}

Real EquilibriumSolver::residual(Newton& s, const VecX& grad, const VecX& f) const {
  Real rf = 0, rc = 0;
  for (int d = 0; d < s.ndof; ++d) {
    const Real v = grad(d) * grad(d);
    (m_freeIndex[size_t(d)] >= 0 ? rf : rc) += v;
  }
  s.rep.forceScale = std::max({f.norm(), std::sqrt(rc), s.floorForce});
  return std::sqrt(rf);
}

SolveReport EquilibriumSolver::solve(const LoadCase& loads, VecX& x, const VecX& fStartIn,
                                     const InertiaTerms* in, const SolveOptions& opt) {
  const auto start = Clock::now();
  SolveReport rep;
  m_report = &rep;
  m_preconditionerCopy = opt.preconditionerCopy;
  const int ndof = 3 * m_sys.numNodes();
  // Constrained nodes and their final targets; fixed wins over prescribed.
  VecX target = x;
  const std::vector<int> cdofs = constrainedDofs(loads, target);
  {
    ScopedTimer timer(rep.analyzeSeconds);  // ordering, K_ff pattern, slots, symbolic factor
    prepareConstraints(cdofs);
  }

  const VecX fEnd = m_sys.externalForce(loads);
  const VecX fStart = fStartIn.size() == ndof ? fStartIn : VecX::Zero(ndof);
  const VecX xStart = x;
  const Box box = boundingBox(m_sys.rest().V);
  Newton s(in, opt, rep, cdofs);
  s.ndof = ndof;
  s.nf = m_Kff.rows();
  // Force floor for unloaded problems: 1e-6 of the force that strains the organ's bounding
  // cross-section by 100%, far above the round-off of internal forces at rest (which grows with
  // the bulk modulus as nu -> 1/2: stiffestModulus).
  s.floorForce =
      1e-6 * m_sys.stiffestModulus() * std::max<Real>(box.diagonal() * box.diagonal(), 1e-300);
  // A factor left by the previous solve on the same constrained set (prepareConstraints drops it
  // otherwise) preconditions this solve's first CG; it is refactorised when CG is slow with it.
  s.staleFactor = m_haveFactor;
  s.rhs.resize(s.nf);
  s.dxFree.resize(s.nf);
  s.step.resize(ndof);

  // The report of a finished solve: the residual at the forces reached, the factorisation, the
  // time.
  const auto finish = [&](const VecX& fReached) {
    objectiveGradient(x, fReached, in, m_gradient);
    rep.residual = residual(s, m_gradient, fEnd);
    rep.factorNonZeros = m_factorNonZeros;
    rep.factorFlops = m_factorFlops;
    rep.seconds = std::chrono::duration<double>(Clock::now() - start).count();
    m_report = nullptr;
    return rep;
  };

  if (!in && isUnloadedRest(x, fStart, fEnd, cdofs, target)) {
    // The rest state is stress free, so under no load with every constrained node at rest it is
    // the solution: zero Newton iterations, whatever the round-off of the internal forces there
    // (~ kappa eps, above the tolerance of an unloaded solve at nu = 0.4999).
    rep.converged = true;
    rep.loadSteps = 1;  // the whole increment, accepted as it stands
    return finish(fEnd);
  }

  // Load stepping: the forces and the constrained dofs' targets ramp from the start (s = 0) to
  // the end (s = 1); a failed increment is halved, a converged one doubles the next.
  Real t = 0, dt = 1;
  const Real minStep = std::ldexp(1.0, -opt.maxHalvings);
  while (t < 1) {
    const Real tn = std::min<Real>(1, t + dt);
    const VecX f = fStart + tn * (fEnd - fStart);
    VecX tgt = x;
    for (int d : cdofs) tgt(d) = xStart(d) + tn * (target(d) - xStart(d));
    VecX xs = x;
    if (loadStep(s, xs, f, tgt)) {
      x = xs;
      t = tn;
      ++rep.loadSteps;
      dt = std::min<Real>(2 * dt, 1);
      if (t < 1 && !in && opt.admissible && !opt.admissible(x)) {
        rep.stoppedEarly = true;
        break;
      }
    } else {
      ++rep.failedLoadSteps;
      if (rep.outOfBudget) break;
      dt = 0.5 * (tn - t);  // half of the increment that failed (not of a doubled one)
      if (dt < minStep || rep.failedLoadSteps >= opt.maxFailedLoadSteps) break;
    }
  }
  rep.converged = t >= 1;
  return finish(fStart + t * (fEnd - fStart));
}

bool EquilibriumSolver::loadStep(Newton& s, VecX& xs, const VecX& f, const VecX& tgt) {
  s.dc = VecX::Zero(s.ndof);
  s.lift = false;
  for (int d : s.cdofs) {
    s.dc(d) = tgt(d) - xs(d);
    s.lift |= s.dc(d) != 0;
  }
  s.damped = 0;
  s.prevResidual = 0;
  s.phiCur = 0;
  s.haveG = false;
  SolveReport& rep = s.rep;
  for (int it = 0; it <= s.opt.maxIterations; ++it) {
    if (!s.haveG) s.phiCur = objectiveGradient(xs, f, s.in, s.g);
    s.haveG = false;
    rep.residual = residual(s, s.g, f);
    if (!s.lift && rep.residual <= s.opt.tolerance * rep.forceScale) return true;
    if (s.opt.maxSolveIterations > 0 && rep.newtonIterations >= s.opt.maxSolveIterations &&
        s.nf > 0) {
      rep.outOfBudget = true;
      return false;
    }
    if (it == s.opt.maxIterations || s.nf == 0) {
      if (s.nf == 0) {
        xs += s.dc;
        objectiveGradient(xs, f, s.in, s.g);
        rep.residual = residual(s, s.g, f);
        return std::isfinite(rep.residual);
      }
      return false;
    }
    if (!newtonDirection(s, xs)) return false;
    const NewtonOutcome next = s.lift ? liftStep(s, xs, f) : lineSearchStep(s, xs, f);
    if (next != NewtonOutcome::Continue) return next == NewtonOutcome::Converged;
  }
  return false;
}

bool EquilibriumSolver::newtonDirection(Newton& s, const VecX& xs) {
  SolveReport& rep = s.rep;
  assembleFree(xs, s.in, false);  // the exact tangent: CG's operator
  ++rep.newtonIterations;
  for (int d = 0; d < s.ndof; ++d)
    if (m_freeIndex[size_t(d)] >= 0) s.rhs(m_freeIndex[size_t(d)]) = -s.g(d);
  if (s.lift) subtractLiftForce(xs, s.in, s.dc, s.rhs);
  // Inexact Newton: K dx = rhs is solved by conjugate gradients preconditioned with an earlier
  // factorisation, to the relative accuracy eta (Eisenstat & Walker's choice 2, capped at 0.1,
  // never finer than the final tolerance needs); the tangent is factorised afresh only when CG
  // is slow or meets a direction of non-positive curvature.
  Real eta = s.lift ? kLiftForcing : kMaxForcing;
  if (s.prevResidual > 0 && !s.lift)
    eta = std::min(kMaxForcing, 0.9 * std::pow(rep.residual / s.prevResidual, 2));
  s.prevResidual = rep.residual;
  const Real rhsNorm = s.rhs.norm();
  eta = std::max(eta, 0.1 * s.opt.tolerance * rep.forceScale / std::max(rhsNorm, 1e-300));
  int its = -1;
  s.modifiedStep = false;
  // With a previous solve's factor, give up after kRefactorCg iterations instead of kMaxCg.
  if (m_haveFactor && !s.refactor)
    its = preconditionedCg(s.rhs, eta * rhsNorm, s.staleFactor ? kRefactorCg : kMaxCg, s.dxFree);
  s.refactor = its > kRefactorCg;
  int projectedCg = 0;
  if (its == -2 && m_haveFactor && m_factorProjected) {
    // The exact tangent is indefinite again and the factor is of an earlier projected tangent:
    // CG on the current projected tangent with that factor, which differs from it mostly where
    // the state changed since, before refactorising. Measured on the liver phantom under
    // gravity (P2, 57k nodes): 3 instead of 52 factorisations for ~50 Newton iterations.
    assembleFree(xs, s.in, true);
    projectedCg = preconditionedCg(s.rhs, eta * rhsNorm, kRefactorCg, s.dxFree);
    if (projectedCg >= 0) {
      its = projectedCg;
      s.modifiedStep = true;
    }
  }
  if (its < 0) {
    s.staleFactor = false;
    // Measured on the liver lift: when the tangent is indefinite (CG met non-positive
    // curvature), a fresh factorisation of its projection both gives a better step than CG on
    // the projection with the old factor of an exact tangent (which took 28 instead of 10
    // iterations) and serves as the preconditioner of the following iterations.
    const int fallbacks = rep.spdFallbacks;
    if (!factorize(xs, s.in, its == -2, rep.spdFallbacks, projectedCg < 0)) return false;
    s.modifiedStep = rep.spdFallbacks > fallbacks;
    ScopedTimer timer(rep.solveSeconds);
    s.dxFree = m_chol->solve(s.rhs);
  }
  if (s.modifiedStep) ++rep.projectedSteps;
  if (kTrace)
    std::fprintf(stderr, "TRACE it %d res %.3e rel %.3e cg %d pcg %d lift %d fact %d fb %d\n",
                 rep.newtonIterations, rep.residual, rep.residual / rep.forceScale, its,
                 projectedCg, int(s.lift), rep.factorizations, rep.spdFallbacks);
  if (!s.dxFree.allFinite()) return false;
  s.step.setZero();
  for (int d = 0; d < s.ndof; ++d)
    if (m_freeIndex[size_t(d)] >= 0) s.step(d) = s.dxFree(m_freeIndex[size_t(d)]);
  return true;
}

EquilibriumSolver::NewtonOutcome EquilibriumSolver::liftStep(Newton& s, VecX& xs, const VecX& f) {
  // Constrained nodes move to their targets with the linearised response of the free nodes.
  // When that predicted state is inadmissible (inverted elements), the whole step, Dirichlet
  // increment included, is shortened and the rest of the increment is applied in the next
  // iteration, from a state whose tangent has seen part of the motion.
  s.step += s.dc;
  Real alpha = 1;
  Real phiLift = objective(xs + s.step, f, s.in);
  for (int ls = 0; ls < 20 && !std::isfinite(phiLift); ++ls) {
    alpha *= 0.5;
    phiLift = objective(xs + alpha * s.step, f, s.in);
  }
  if (!std::isfinite(phiLift)) return NewtonOutcome::Failed;
  xs += alpha * s.step;
  s.dc *= 1 - alpha;
  s.lift = alpha < 1;
  return NewtonOutcome::Continue;
}

EquilibriumSolver::NewtonOutcome EquilibriumSolver::lineSearchStep(Newton& s, VecX& xs,
                                                                   const VecX& f) {
  const Real phi0 = s.phiCur;
  const Real slope = s.g.dot(s.step);
  if (!(slope < 0)) return NewtonOutcome::Failed;
  if (-slope <= 1e-13 * std::abs(phi0)) return roundOffStep(s, xs, f);
  Real alpha = 1;
  if (!armijo(s, xs, f, phi0, slope, alpha)) {
    // Near the solution Pi changes below round-off: accept a full step that lowers the
    // residual.
    const VecX xt = xs + s.step;
    const Real phi1 = objectiveGradient(xt, f, s.in, s.gTrial);
    if (!std::isfinite(phi1)) return NewtonOutcome::Failed;
    // Only a round-off-level rise of Pi qualifies; otherwise the direction is poor.
    if (phi1 - phi0 > 1e-10 * std::max(std::abs(phi0), s.rep.forceScale * 1e-3))
      return NewtonOutcome::Failed;
    if (!(residual(s, s.gTrial, f) < s.rep.residual)) return NewtonOutcome::Failed;
    alpha = 1;
    s.phiNext = phi1;
  }
  // A step that solved a projected tangent (the exact one is indefinite here) underestimates
  // how far the objective keeps falling along it: try longer steps while it does.
  if (alpha == 1 && s.modifiedStep) {
    Real best = s.phiNext;
    Real bestAlpha = 1;
    for (Real a = 2; a <= kMaxExtrapolation; a *= 2) {
      const Real phi = objective(xs + a * s.step, f, s.in);
      if (!(phi < best) || !(phi <= phi0 + kArmijo * a * slope)) break;
      best = phi;
      bestAlpha = a;
    }
    if (bestAlpha > 1) {
      if (kTrace) std::fprintf(stderr, "TRACE   extrapolated to %g\n", bestAlpha);
      xs += bestAlpha * s.step;
      return NewtonOutcome::Continue;  // s.haveG stays false: the gradient is recomputed
    }
  }
  if (kTrace) {
    Eigen::Index imax = 0;
    s.step.cwiseAbs().maxCoeff(&imax);
    const int nd = int(imax / 3);
    const Vec3 X = m_sys.rest().V.row(nd).transpose();
    std::fprintf(stderr,
                 "TRACE   alpha %.4g |step| %.3e at node %d (%.4f %.4f %.4f)%s phi0 %.9e phi "
                 "%.9e\n",
                 alpha, s.step.lpNorm<Eigen::Infinity>(), nd, X(0), X(1), X(2),
                 nd >= m_sys.numCornerNodes() ? " midside" : "", phi0, s.phiNext);
  }
  // A load step that keeps needing damped steps is too large for Newton's region of fast
  // convergence: give up early so it is halved, instead of grinding to maxIterations.
  if (alpha < 1 && ++s.damped > kMaxDampedIterations) return NewtonOutcome::Failed;
  xs += alpha * s.step;
  if (alpha == 1) {
    s.g.swap(s.gTrial);
    s.phiCur = s.phiNext;
    s.haveG = true;
  }
  return NewtonOutcome::Continue;
}

bool EquilibriumSolver::armijo(Newton& s, const VecX& xs, const VecX& f, Real phi0, Real slope,
                               Real& alpha) {
  for (int ls = 0; ls < 30; ++ls, alpha *= 0.5) {
    // The full step is usually accepted: its gradient is computed with the energy and serves
    // the next iteration.
    const Real phi = ls == 0 ? objectiveGradient(xs + s.step, f, s.in, s.gTrial)
                             : objective(xs + alpha * s.step, f, s.in);
    // Armijo, or for the full step the approximate Wolfe condition of Hager & Zhang ("A new
    // conjugate gradient method with guaranteed descent and an efficient line search", SIAM J.
    // Optim. 16(1) 2005, eq. 4.2): near the solution the decrease of Pi drops to the round-off
    // of its sum, and the derivative along the step, g(x + s) . s <= (2 delta - 1) g(x) . s,
    // judges it where Pi's values cannot.
    if (phi <= phi0 + kArmijo * alpha * slope ||
        (ls == 0 && phi <= phi0 + kObjectiveNoise * std::abs(phi0) &&
         s.gTrial.dot(s.step) <= (2 * kArmijo - 1) * slope)) {
      s.phiNext = phi;
      return true;
    }
  }
  return false;
}

EquilibriumSolver::NewtonOutcome EquilibriumSolver::roundOffStep(Newton& s, VecX& xs,
                                                                 const VecX& f) {
  // The predicted decrease of Pi is below its round-off: Armijo cannot judge the step. Take the
  // full Newton step; if it no longer halves the residual, the residual has reached its
  // round-off floor and the state is accepted as converged.
  const VecX xt = xs + s.step;
  const Real phiT = objectiveGradient(xt, f, s.in, s.gTrial);
  if (!std::isfinite(phiT)) return NewtonOutcome::Failed;
  const Real before = s.rep.residual, after = residual(s, s.gTrial, f);
  xs = xt;
  if (!(after < 0.5 * before)) {
    s.rep.residual = after;
    return after <= 1e3 * s.opt.tolerance * s.rep.forceScale ? NewtonOutcome::Converged
                                                             : NewtonOutcome::Failed;
  }
  s.g.swap(s.gTrial);
  s.phiCur = phiT;
  s.haveG = true;
  return NewtonOutcome::Continue;
}

SolveReport EquilibriumSolver::solveStatic(const LoadCase& loads, VecX& x, const VecX& fStart,
                                           const SolveOptions& options) {
  return solve(loads, x, fStart, nullptr, options);
}

SolveReport EquilibriumSolver::stepDynamic(const LoadCase& loads, Real h, Real alpha, Real beta,
                                           VecX& x, VecX& v, const SolveOptions& options) {
  const int ndof = 3 * m_sys.numNodes();
  InertiaTerms in;
  in.weight.resize(ndof);
  for (int i = 0; i < m_sys.numNodes(); ++i)
    in.weight.segment<3>(3 * i).setConstant(m_sys.nodeMass()(i) * (1.0 / (h * h) + alpha / h));
  // Minimiser of 1/(2h^2)|x - x_pred|^2_M + alpha/(2h)|x - x_n|^2_M in one quadratic.
  const Real a = 1.0 / (h * h), b = alpha / h;
  in.center = (a * (x + h * v) + b * x) / (a + b);
  if (beta > 0) {
    m_sys.stiffnessValues(x, in.dampingValues, true);
    in.dampingValues *= beta / h;
    in.dampingCenter = x;
  }
  const VecX xn = x;
  // Forces are applied fully (no ramp from zero): inertia keeps the step well posed.
  const VecX f = m_sys.externalForce(loads);
  SolveReport rep = solve(loads, x, f, &in, options);
  v = (x - xn) / h;
  return rep;
}

VecX solveEquilibrium(const FemSystem& system, const LoadCase& loads, const SolveOptions& options,
                      SolveReport* report) {
  EquilibriumSolver solver(system);
  VecX x = system.restPositions();
  const SolveReport r = solver.solveStatic(loads, x, VecX(), options);
  if (report) *report = r;
  return x;
}

}  // namespace deform::reference_fem
