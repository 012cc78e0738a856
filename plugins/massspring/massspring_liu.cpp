// Implicit Euler for the mass-spring network by local/global alternation (Liu, Bargteil, O'Brien,
// Kavan 2013, "Fast simulation of mass-spring systems", ACM TOG 32(6) 214). One step minimises
//   g(x) = 1/(2 h^2) (x - y)^T M (x - y) + sum_s k_s/2 |x_a - x_b - d_s|^2,
//   y = x_n + h v_n + h^2 M^-1 f_ext,
// over the positions x and the spring directions d_s (|d_s| = L_s): the minimum over d is the
// implicit Euler step of the Hookean springs (Liu et al., Sec. 3, Eq. (4)-(5)). Alternately
//   local:  d_s = L_s (x_a - x_b) / |x_a - x_b|                       (per spring, exact)
//   global: (M + h^2 L) x = M y + h^2 J d,  L = sum_s k_s (e_a - e_b)(e_a - e_b)^T,
//           J d = sum_s k_s (e_a - e_b) d_s^T                         (Eq. (11)-(12))
// A = M + h^2 L is the same for x, y and z and does not depend on x, so it is factorised once
// (node_cholesky.h: CHOLMOD's ordering and factorisation, an N x N matrix with three right-hand
// sides stored per node). Constrained nodes (fixed, massless, grasped) take their positions as
// Dirichlet values: their rows and columns of A become the identity; A is refactorised only when
// h or the set of constrained nodes changes (a grasp closing or opening).
//
// How the iterations run (each one spring pass and one solve):
// - In correction form, x <- x + A^-1 r with r = M (y - x) + h^2 sum_s k_s (e_a - e_b)(d_s -
//   (x_a - x_b)) the residual of the global step at the current x: the same iterate as Liu et al.'s
//   global step, but the factor's values, kept in float, only change how fast it converges, not
//   the fixed point (which is the implicit Euler step, to double precision).
// - Chebyshev semi-iterative acceleration (Wang 2015, "A Chebyshev semi-iterative approach for
//   accelerating projective and position-based dynamics", ACM TOG 34(6) 246), with the spectral
//   radius rho of the plain iteration estimated whenever A is factorised (power iteration).
// - Warm start: the first iterate is y plus the previous step's correction x_n - y_{n-1}
//   (cleared by reset() and when A is refactorised).
//
// Differences to the other integrators: the axial dashpots (damping_ratio) are not part of
// Liu et al.'s energy and are ignored here; mass damping is applied implicitly to the new
// velocity, v = (x - x_n) / (h (1 + h mass_damping)). The fixed iteration count makes this an
// approximation of implicit Euler that converges to it as the iterations grow.
#include "massspring_model.h"

#include <deform/sdk/contact.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace deform::massspring {

namespace {

// may_alias: the rows are std::vector<Row4> storage, read and written through this type.
using V4 = double __attribute__((vector_size(32), may_alias));

V4* rows(std::vector<Row4>& r) {
  return reinterpret_cast<V4*>(r.data());
}

// The spring part of the global step's residual: R[a] += f, R[b] -= f with f = h^2 k (d_s -
// (x_a - x_b)) = c (L / l - 1)(x_a - x_b), d_s = L (x_a - x_b) / l the local step. Returns the
// number of degenerate (zero-length) springs. No fused multiply-add, so the AVX2 and the generic
// build agree bit for bit.
__attribute__((always_inline)) inline long long localPass(const V4* X, V4* R,
                                                          const LocalGlobalSpring* s, size_t n) {
  long long degenerate = 0;
  for (size_t k = 0; k < n; ++k) {
    const V4 d = X[s[k].a] - X[s[k].b];
    const double l2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
    if (l2 <= tol::kDegenerateLength * tol::kDegenerateLength) [[unlikely]] {
      ++degenerate;
      continue;
    }
    const V4 f = (s[k].c * (s[k].rest / std::sqrt(l2) - 1.0)) * d;
    R[s[k].a] += f;
    R[s[k].b] -= f;
  }
  return degenerate;
}
__attribute__((target("avx2"))) long long localPassAvx2(const V4* X, V4* R,
                                                        const LocalGlobalSpring* s, size_t n) {
  return localPass(X, R, s, n);
}
long long localPassGeneric(const V4* X, V4* R, const LocalGlobalSpring* s, size_t n) {
  return localPass(X, R, s, n);
}

constexpr int kRhoPowerIterations = 50;
constexpr Real kRhoTolerance = 1e-3;

}  // namespace

void MassSpringModel::factorLocalGlobal(Real h) {
  const int N = static_cast<int>(m_rest.rows());
  if (!m_lgChol) {
    std::vector<Triplet> trip;
    trip.reserve(N + 4 * m_springs.size());
    for (int i = 0; i < N; ++i) trip.emplace_back(i, i, 1.0);
    // Springs to a node that never moves (fixed or massless) are no part of the pattern: they
    // only add to the other node's diagonal.
    for (const Spring& s : m_springs) {
      if (m_invMass[s.a] == 0.0 || m_invMass[s.b] == 0.0) continue;
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
      const bool coupled = m_invMass[s.a] != 0.0 && m_invMass[s.b] != 0.0;
      m_lgSpringSlots[k] = {slot(s.a, s.a), slot(s.b, s.b), coupled ? slot(s.a, s.b) : -1,
                            coupled ? slot(s.b, s.a) : -1};
    }
    m_lgChol = std::make_unique<NodeCholesky>();
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
  try {
    m_lgChol->factor(m_lgA);
  } catch (const std::runtime_error&) {
    throw std::runtime_error(
        "massspring local_global: the system matrix M + h^2 L did not factorise");
  }
  ++m_lgFactorisations;
  m_lgH = h;
  m_lgFactoredFor = m_lgConstrained;

  // The springs and constrained rows in the factor's node order; springs sorted by their first
  // row so that neighbouring springs touch nearby rows.
  const std::vector<int>& perm = m_lgChol->perm();
  std::vector<int> row(N), order;
  for (int k = 0; k < N; ++k) row[perm[k]] = k;
  for (size_t k = 0; k < m_springs.size(); ++k)
    if (!fixed[m_springs[k].a] || !fixed[m_springs[k].b]) order.push_back(static_cast<int>(k));
  const auto first = [&](int k) { return std::min(row[m_springs[k].a], row[m_springs[k].b]); };
  std::stable_sort(order.begin(), order.end(), [&](int p, int q) { return first(p) < first(q); });
  m_lgSprings.clear();
  for (int k : order) {
    const Spring& s = m_springs[k];
    m_lgSprings.push_back({row[s.a], row[s.b], h2 * s.k, s.rest});
  }
  m_lgRowMass.resize(N);
  for (int k = 0; k < N; ++k) m_lgRowMass[k] = fixed[perm[k]] ? 0.0 : m_mass[perm[k]];
  m_lgConstrainedRows.clear();
  for (int i = 0; i < N; ++i)
    if (fixed[i]) m_lgConstrainedRows.push_back(row[i]);
  std::sort(m_lgConstrainedRows.begin(), m_lgConstrainedRows.end());
  m_lgWarm.clear();
  if (m_config.localGlobalAcceleration == LocalGlobalAcceleration::None)
    m_lgRho = 0;
  else
    m_lgRho = m_config.localGlobalRho > 0 ? m_config.localGlobalRho : estimateLocalGlobalRho();
}

// Power iteration on the local/global map linearised at the current positions: one iteration
// changes an error e to G e with G = A^-1 h^2 sum_s k_s (L_s / l_s) (e_a - e_b)(e_a - e_b)^T x
// (I - n_s n_s^T) (the derivative of d_s = L_s n_s is (L_s / l_s)(I - n_s n_s^T)). G is
// self-adjoint in the A inner product with eigenvalues >= 0, so the Rayleigh quotient
// e^T h^2 K e / e^T A e of the iterates rises to the spectral radius from below.
Real MassSpringModel::estimateLocalGlobalRho() {
  const int N = static_cast<int>(m_x.rows());
  const std::vector<int>& perm = m_lgChol->perm();
  std::vector<int> row(N);
  for (int k = 0; k < N; ++k) row[perm[k]] = k;
  const Real h2 = m_lgH * m_lgH;
  const unsigned char* fixed = m_lgConstrained.data();
  std::vector<Row4> E(N), R(N);
  for (int i = 0; i < N; ++i) {
    // A deterministic start with components along every direction.
    const unsigned hsh = static_cast<unsigned>(i + 1) * 2654435761u;
    Row4& e = E[row[i]];
    e = {{double(hsh % 1024) / 1024.0 - 0.5, double((hsh >> 10) % 1024) / 1024.0 - 0.5,
          double((hsh >> 20) % 1024) / 1024.0 - 0.5, 0.0}};
    if (fixed[i]) e = {{0, 0, 0, 0}};
  }
  Real rho = 0;
  for (int it = 0; it < kRhoPowerIterations; ++it) {
    Real eKe = 0, eAe = 0;
    for (int i = 0; i < N; ++i) {
      const Row4& e = E[row[i]];
      if (!fixed[i]) eAe += m_mass[i] * (e.v[0] * e.v[0] + e.v[1] * e.v[1] + e.v[2] * e.v[2]);
    }
    std::fill(R.begin(), R.end(), Row4{{0, 0, 0, 0}});
    for (const Spring& s : m_springs) {
      if (fixed[s.a] && fixed[s.b]) continue;
      const int a = row[s.a], b = row[s.b];
      const Vec3 d = (m_x.row(s.a) - m_x.row(s.b)).transpose();
      const Vec3 e(E[a].v[0] - E[b].v[0], E[a].v[1] - E[b].v[1], E[a].v[2] - E[b].v[2]);
      const Real l = d.norm();
      eAe += h2 * s.k * e.squaredNorm();
      if (l <= tol::kDegenerateLength) continue;
      const Vec3 n = d / l;
      const Vec3 t = h2 * s.k * s.rest / l * (e - n * n.dot(e));
      eKe += t.dot(e);
      for (int c = 0; c < 3; ++c) {
        R[a].v[c] += t[c];
        R[b].v[c] -= t[c];
      }
    }
    if (!(eAe > 0)) return 0;  // nothing free
    const Real next = eKe / eAe;
    for (int k : m_lgConstrainedRows) R[k] = {{0, 0, 0, 0}};
    m_lgChol->solveInPlace(R.data());
    // Normalise (the iterates shrink by rho per iteration).
    Real norm2 = 0;
    for (const Row4& r : R) norm2 += r.v[0] * r.v[0] + r.v[1] * r.v[1] + r.v[2] * r.v[2];
    if (!(norm2 > 0)) return next;
    const Real scale = 1.0 / std::sqrt(norm2);
    for (int k = 0; k < N; ++k)
      for (int c = 0; c < 3; ++c) E[k].v[c] = R[k].v[c] * scale;
    const bool converged = std::abs(next - rho) <= kRhoTolerance * next;
    rho = next;
    if (converged) break;
  }
  return rho;
}

StepStatus MassSpringModel::stepLocalGlobal(const StepInput& in, Real h) {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  const int N = static_cast<int>(m_x.rows());
  // Constrained nodes: fixed or massless (m_invMass 0), and grasped (their targets).
  m_lgConstrained.assign(N, 0);
  for (int i = 0; i < N; ++i) m_lgConstrained[i] = m_invMass[i] == 0.0;
  for (const NodeGrasp& g : m_nodeGrasps)
    if (!g.sliding())
      for (int i : g.nodes) m_lgConstrained[i] = 1;
  if (h != m_lgH || m_lgConstrained != m_lgFactoredFor) factorLocalGlobal(h);
  const unsigned char* fixed = m_lgConstrained.data();
  const std::vector<int>& perm = m_lgChol->perm();

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
    if (!g.sliding())
      for (size_t k = 0; k < g.nodes.size(); ++k) m_lgY.row(g.nodes[k]) = g.targets.row(k);
  // Nodes under a sliding plate stay free in A; their normal coordinate is held on the plate's
  // plane (y, every iterate) and their residual along it is zeroed before each solve. The fixed
  // point is then the constrained one: a correction z = A^-1 r with r zero on the held
  // coordinates, z nonzero only on them, would give z^T A z = z^T r = 0, so z = 0 and r = 0.
  m_lgSliding.clear();
  if (!m_sliding.empty()) {
    std::vector<int> rowOf(static_cast<size_t>(N));
    for (int k = 0; k < N; ++k) rowOf[size_t(perm[k])] = k;
    for (const SlidingHold& sh : m_sliding) {
      m_lgY(sh.node, sh.axis) = sh.offset;
      m_lgSliding.push_back({rowOf[size_t(sh.node)], sh.axis, sh.offset});
    }
  }
  const auto holdSlidingRows = [&](V4* X) {
    for (const SlidingHold& sh : m_lgSliding) X[sh.node][sh.axis] = sh.offset;
  };

  // In the factor's order: y, and the first iterate (y, or y plus the previous correction).
  m_lgY4.resize(N);
  for (int k = 0; k < N; ++k) {
    const int i = perm[k];
    m_lgY4[k] = {{m_lgY(i, 0), m_lgY(i, 1), m_lgY(i, 2), 0.0}};
  }
  const V4* Y = rows(m_lgY4);
  m_xOld = m_x;
  m_lgX = m_lgY4;
  if (m_config.localGlobalWarmStart && static_cast<int>(m_lgWarm.size()) == N) {
    V4* X = rows(m_lgX);
    const V4* W = rows(m_lgWarm);
    for (int k = 0; k < N; ++k) X[k] += W[k];
    holdSlidingRows(X);
  }
  m_lgXPrev = m_lgX;
  m_lgR.resize(N);
  static const bool kAvx2 = __builtin_cpu_supports("avx2");
  const auto local = kAvx2 ? localPassAvx2 : localPassGeneric;
  const bool chebyshev = m_config.localGlobalAcceleration == LocalGlobalAcceleration::Chebyshev &&
                         m_lgRho > 0 && m_lgRho < 1;
  // Chebyshev weights for the eigenvalues of the linearised iteration, which lie in [0, rho]:
  // relaxing by gamma = 2 / (2 - rho) maps them onto [-rho', rho'], rho' = rho / (2 - rho), the
  // symmetric interval Wang's recurrence assumes.
  const Real gamma = 2.0 / (2.0 - m_lgRho), rhoShifted = m_lgRho / (2.0 - m_lgRho);
  const Real rho2 = rhoShifted * rhoShifted;
  const double* rowMass = m_lgRowMass.data();
  Real omega = 1;
  double localMs = 0, globalMs = 0;
  for (int it = 0; it < m_config.localGlobalIterations; ++it) {
    const auto a = Clock::now();
    V4* X = rows(m_lgX);
    V4* R = rows(m_lgR);
    for (int k = 0; k < N; ++k) R[k] = rowMass[k] * (Y[k] - X[k]);
    m_degenerate += local(X, R, m_lgSprings.data(), m_lgSprings.size());
    for (int k : m_lgConstrainedRows) R[k] = V4{0, 0, 0, 0};
    for (const SlidingHold& sh : m_lgSliding) R[sh.node][sh.axis] = 0;
    const auto b = Clock::now();
    m_lgChol->solveInPlace(m_lgR.data());  // R: the correction
    const auto c = Clock::now();
    V4* P = rows(m_lgXPrev);
    if (chebyshev && it >= 1) {
      // Wang 2015: x <- omega (gamma (x^ - x) + x - x_prev) + x_prev, x^ - x the correction,
      // with omega_2 = 2 / (2 - rho^2), omega_k+1 = 4 / (4 - rho^2 omega_k); the first
      // iteration is plain (omega_1 = 1).
      omega = it == 1 ? 2.0 / (2.0 - rho2) : 4.0 / (4.0 - rho2 * omega);
      for (int k = 0; k < N; ++k) {
        const V4 next = omega * (gamma * R[k] + X[k] - P[k]) + P[k];
        P[k] = X[k];
        X[k] = next;
      }
    } else {
      for (int k = 0; k < N; ++k) {
        P[k] = X[k];
        X[k] += R[k];
      }
    }
    holdSlidingRows(X);
    localMs += std::chrono::duration<double, std::milli>(b - a).count();
    globalMs += std::chrono::duration<double, std::milli>(c - b).count();
  }

  const auto t1 = Clock::now();
  if (m_config.localGlobalWarmStart) {
    m_lgWarm.resize(N);
    V4* W = rows(m_lgWarm);
    const V4* X = rows(m_lgX);
    for (int k = 0; k < N; ++k) W[k] = X[k] - Y[k];
  }
  const Real damp = 1.0 / (h * (1.0 + h * m_config.massDamping));
  for (int k = 0; k < N; ++k) {
    const int i = perm[k];
    if (m_invMass[i] == 0.0) {
      m_v.row(i).setZero();
      continue;
    }
    for (int c = 0; c < 3; ++c) {
      m_v(i, c) = (m_lgX[k].v[c] - m_x(i, c)) * damp;
      m_x(i, c) = m_lgX[k].v[c];
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
