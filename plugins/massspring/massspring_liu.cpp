// Implicit Euler for the mass-spring network by local/global alternation (Liu, Bargteil, O'Brien,
// Kavan 2013, "Fast simulation of mass-spring systems", ACM TOG 32(6) 214). One step minimises
//   g(x) = 1/(2 h^2) (x - y)^T M (x - y) + sum_s k_s/2 |x_a - x_b - d_s|^2,
//   y = x_n + h v_n + h^2 M^-1 f_ext,
// over the positions x and the spring directions d_s (|d_s| = L_s): the minimum over d is the
// implicit Euler step of the Hookean springs (Liu et al., Sec. 3, Eq. (4)-(5)). Alternately
//   local:  d_s = L_s (x_a - x_b) / |x_a - x_b|                       (per spring, exact)
//   global: (M + h^2 L) x = M y + h^2 J d,  L = sum_s k_s (e_a - e_b)(e_a - e_b)^T,
//           J d = sum_s k_s (e_a - e_b) d_s^T                         (Eq. (11)-(12))
// starting from x = y. A = M + h^2 L is the same for x, y and z and does not depend on x, so it is
// factorised once (CHOLMOD supernodal Cholesky, an N x N matrix with three right-hand sides) and
// each iteration costs one pass over the springs and two triangular solves. Constrained nodes
// (fixed, massless, grasped) take their positions as Dirichlet values: their rows and columns of
// A become the identity and their coupling moves to the right-hand side; A is refactorised only
// when h or the set of constrained nodes changes (a grasp closing or opening).
//
// Differences to the other integrators: the axial dashpots (damping_ratio) are not part of
// Liu et al.'s energy and are ignored here; mass damping is applied implicitly to the new
// velocity, v = (x - x_n) / (h (1 + h mass_damping)). The fixed iteration count makes this an
// approximation of implicit Euler that converges to it (linearly) as the iterations grow.
#include "massspring_model.h"

#include <deform/contact.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace deform::massspring {

void MassSpringModel::factorLocalGlobal(Real h) {
  const int N = static_cast<int>(m_rest.rows());
  if (!m_lgAnalysed) {
    std::vector<Triplet> trip;
    trip.reserve(N + 4 * m_springs.size());
    for (int i = 0; i < N; ++i) trip.emplace_back(i, i, 1.0);
    for (const Spring& s : m_springs) {
      trip.emplace_back(s.a, s.b, 0.0);
      trip.emplace_back(s.b, s.a, 0.0);
    }
    m_lgA.resize(N, N);
    m_lgA.setFromTriplets(trip.begin(), trip.end());
    m_lgA.makeCompressed();
    const auto slot = [&](int r, int c) {
      const int* begin = m_lgA.innerIndexPtr() + m_lgA.outerIndexPtr()[c];
      const int* end = m_lgA.innerIndexPtr() + m_lgA.outerIndexPtr()[c + 1];
      return static_cast<int>(std::lower_bound(begin, end, r) - m_lgA.innerIndexPtr());
    };
    m_lgDiag.resize(N);
    for (int i = 0; i < N; ++i) m_lgDiag[i] = slot(i, i);
    m_lgSpringSlots.resize(m_springs.size());
    for (size_t k = 0; k < m_springs.size(); ++k) {
      const Spring& s = m_springs[k];
      m_lgSpringSlots[k] = {slot(s.a, s.a), slot(s.b, s.b), slot(s.a, s.b), slot(s.b, s.a)};
    }
    installCholmodAllocator();
    m_lgChol = std::make_unique<SparseCholesky>();
    SerialOpenMpScope serial;
    m_lgChol->analyzePattern(m_lgA);
    m_lgAnalysed = true;
  }
  Real* val = m_lgA.valuePtr();
  std::fill(val, val + m_lgA.nonZeros(), 0.0);
  const unsigned char* fixed = m_lgConstrained.data();
  for (int i = 0; i < N; ++i) val[m_lgDiag[i]] = fixed[i] ? 1.0 : m_mass[i];
  const Real h2 = h * h;
  for (size_t k = 0; k < m_springs.size(); ++k) {
    const Spring& s = m_springs[k];
    const auto& sl = m_lgSpringSlots[k];
    const Real c = h2 * s.k;
    if (!fixed[s.a]) val[sl[0]] += c;
    if (!fixed[s.b]) val[sl[1]] += c;
    if (!fixed[s.a] && !fixed[s.b]) {
      val[sl[2]] -= c;
      val[sl[3]] -= c;
    }
  }
  SerialOpenMpScope serial;
  m_lgChol->factorize(m_lgA);
  if (m_lgChol->info() != Eigen::Success)
    throw std::runtime_error(
        "massspring local_global: the system matrix M + h^2 L did not factorise");
  ++m_lgFactorisations;
  m_lgH = h;
  m_lgFactoredFor = m_lgConstrained;
}

StepStatus MassSpringModel::stepLocalGlobal(const StepInput& in, Real h) {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  const int N = static_cast<int>(m_x.rows());
  // Constrained nodes: fixed or massless (m_invMass 0), and grasped (their targets).
  m_lgConstrained.assign(N, 0);
  for (int i = 0; i < N; ++i) m_lgConstrained[i] = m_invMass[i] == 0.0;
  for (const NodeGrasp& g : m_nodeGrasps)
    for (int i : g.nodes) m_lgConstrained[i] = 1;
  if (h != m_lgH || m_lgConstrained != m_lgFactoredFor) factorLocalGlobal(h);
  const unsigned char* fixed = m_lgConstrained.data();

  // External forces (point loads, penalty contact) and gravity fold into y.
  m_f.setZero(N, 3);
  for (const auto& [node, force] : m_nodeForces) m_f.row(node) += force.transpose();
  if (in.contact && in.contact->params().method == ContactMethod::Penalty) m_f += m_contactForce;
  m_lgY.resize(N, 3);
  for (int i = 0; i < N; ++i) {
    if (fixed[i]) {
      m_lgY.row(i) = m_x.row(i);
      continue;
    }
    m_lgY.row(i) = m_x.row(i) + h * m_v.row(i) +
                   (h * h) * (m_f.row(i) * m_invMass[i] + in.gravity.transpose());
  }
  for (const NodeGrasp& g : m_nodeGrasps)
    for (size_t k = 0; k < g.nodes.size(); ++k) m_lgY.row(g.nodes[k]) = g.targets.row(k);

  // The constant part of the right-hand side: M y on free rows plus the coupling to constrained
  // neighbours (h^2 k x_c), and the Dirichlet values on constrained rows.
  const Real h2 = h * h;
  m_lgRhs0.resize(N, 3);
  for (int i = 0; i < N; ++i)
    for (int c = 0; c < 3; ++c) m_lgRhs0(i, c) = fixed[i] ? m_lgY(i, c) : m_mass[i] * m_lgY(i, c);
  for (const Spring& s : m_springs) {
    if (fixed[s.a] == fixed[s.b]) continue;
    const int f = fixed[s.a] ? s.b : s.a, c = fixed[s.a] ? s.a : s.b;
    for (int d = 0; d < 3; ++d) m_lgRhs0(f, d) += h2 * s.k * m_lgY(c, d);
  }

  m_xOld = m_x;
  m_lgX = m_lgY;  // column-major N x 3: x = y to start
  double localMs = 0, globalMs = 0;
  for (int it = 0; it < m_config.localGlobalIterations; ++it) {
    const auto a = Clock::now();
    m_lgRhs = m_lgRhs0;
    const Real* X = m_lgX.data();
    Real* R = m_lgRhs.data();
    for (const Spring& s : m_springs) {
      if (fixed[s.a] && fixed[s.b]) continue;
      const Real d0 = X[s.a] - X[s.b], d1 = X[N + s.a] - X[N + s.b],
                 d2 = X[2 * N + s.a] - X[2 * N + s.b];
      const Real l2 = d0 * d0 + d1 * d1 + d2 * d2;
      if (l2 <= tol::kDegenerateLength * tol::kDegenerateLength) [[unlikely]] {
        ++m_degenerate;
        continue;
      }
      // h^2 k d_s with d_s = L (x_a - x_b) / |x_a - x_b|.
      const Real m = h2 * s.k * s.rest / std::sqrt(l2);
      if (!fixed[s.a]) {
        R[s.a] += m * d0;
        R[N + s.a] += m * d1;
        R[2 * N + s.a] += m * d2;
      }
      if (!fixed[s.b]) {
        R[s.b] -= m * d0;
        R[N + s.b] -= m * d1;
        R[2 * N + s.b] -= m * d2;
      }
    }
    const auto b = Clock::now();
    m_lgX = m_lgChol->solve(m_lgRhs);
    const auto c = Clock::now();
    localMs += std::chrono::duration<double, std::milli>(b - a).count();
    globalMs += std::chrono::duration<double, std::milli>(c - b).count();
  }

  const auto t1 = Clock::now();
  const Real damp = 1.0 / (h * (1.0 + h * m_config.massDamping));
  for (int i = 0; i < N; ++i) {
    if (m_invMass[i] == 0.0) {
      m_v.row(i).setZero();
      continue;
    }
    for (int c = 0; c < 3; ++c) {
      m_v(i, c) = (m_lgX(i, c) - m_x(i, c)) * damp;
      m_x(i, c) = m_lgX(i, c);
    }
  }
  applyConstraints(in, h, m_xOld);
  const auto t2 = Clock::now();
  auto ms = [](auto p, auto q) { return std::chrono::duration<double, std::milli>(q - p).count(); };
  m_phase["setup"] = ms(t0, t1) - localMs - globalMs;
  m_phase["local"] = localMs;
  m_phase["global"] = globalMs;
  m_phase["integrate"] = ms(t1, t2);
  return checkDivergence();
}

}  // namespace deform::massspring
