#include "massspring_model.h"

#include "explicit_rows.h"

#include <deform/geometry/surface_mass.h>
#include <deform/geometry/tet_nodes.h>

#include <deform/sdk/contact.h>

#include <deform/geometry/tet_mesher.h>
#include <deform/sdk/mesh.h>

#include <Eigen/IterativeLinearSolvers>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>

namespace deform::massspring {

namespace {}  // namespace

void MassSpringModel::init(const ModelSetup& setup) {
  const MassSpringConfig config = configFromParams(setup.params);
  if (config.volumeNetwork && !setup.organ.volume) {
    Organ organ = setup.organ;
    organ.volume =
        surfaceVolumeCached(organ.surface, config.volumeElements, organ.source, setup.cache);
    init(organ, config);
  } else {
    init(setup.organ, config);
  }
  m_setupDt = setup.dt;
}

Real MassSpringModel::stableStep() const {
  return m_stableStep;
}

// The largest eigenvalue of M^-1 K (or of M^-1 C, the dashpots) over the free nodes at the rest
// shape, where K = sum k n n^T per spring (the transverse term vanishes at rest): power
// iteration on the symmetric M^-1/2 K M^-1/2 from a fixed start, until the Rayleigh quotient
// (a lower bound that rises to the eigenvalue) changes by less than 1e-4 of itself.
Real MassSpringModel::largestRestEigenvalue(bool damping) const {
  const Eigen::Index N = m_rest.rows();
  VecX s(N);
  for (Eigen::Index i = 0; i < N; ++i) s[i] = std::sqrt(m_invMass[i]);  // 0: fixed
  MatX3 u(N, 3), y(N, 3);
  for (Eigen::Index i = 0; i < N; ++i)
    for (int k = 0; k < 3; ++k) u(i, k) = s[i] * (1.0 + 0.5 * std::sin(1.7 * double(i) + k));
  Real rq = 0;
  for (int it = 0; it < 1000; ++it) {
    const Real norm = u.norm();
    if (!(norm > 0)) return 0;
    u /= norm;
    y.setZero();
    for (const Spring& sp : m_springs) {
      const Real coef = damping ? sp.c : sp.k;
      if (coef == 0 || (s[sp.a] == 0 && s[sp.b] == 0)) continue;
      const Vec3 d = (m_rest.row(sp.b) - m_rest.row(sp.a)).transpose();
      const Real l2 = d.squaredNorm();
      if (!(l2 > 0)) continue;
      const Vec3 du = s[sp.a] * u.row(sp.a).transpose() - s[sp.b] * u.row(sp.b).transpose();
      const Vec3 f = (coef * d.dot(du) / l2) * d;
      y.row(sp.a) += s[sp.a] * f.transpose();
      y.row(sp.b) -= s[sp.b] * f.transpose();
    }
    const Real next = (u.array() * y.array()).sum();
    const bool done = it > 0 && std::abs(next - rq) <= 1e-4 * next;
    rq = next;
    if (done) break;
    u = y;
  }
  return rq;
}

Real MassSpringModel::computeStableStep() const {
  if (m_config.integrator == Integrator::ImplicitEuler ||
      m_config.integrator == Integrator::LocalGlobal)
    return std::numeric_limits<Real>::infinity();
  // Block Gershgorin bounds over the free nodes: the largest eigenvalue of M^-1 K is at most
  // max_i 2 sum_{springs at i} k / m_i (each spring's 3x3 block has norm k), and of M^-1 C at
  // most max_i 2 sum c / m_i (axial dashpots) plus the mass damping alpha.
  const int N = static_cast<int>(m_rest.rows());
  std::vector<Real> sumK(N, 0.0), sumC(N, 0.0);
  Real minRatio = std::numeric_limits<Real>::infinity();  // min c/k over the springs
  for (const Spring& s : m_springs) {
    if (m_invMass[s.a] == 0.0 && m_invMass[s.b] == 0.0) continue;
    sumK[s.a] += s.k;
    sumK[s.b] += s.k;
    sumC[s.a] += s.c;
    sumC[s.b] += s.c;
    if (s.k > 0) minRatio = std::min(minRatio, s.c / s.k);
  }
  Real w2 = 0, gamma = 0;
  for (int i = 0; i < N; ++i) {
    if (m_invMass[i] == 0.0) continue;
    w2 = std::max(w2, 2 * sumK[i] * m_invMass[i]);
    gamma = std::max(gamma, 2 * sumC[i] * m_invMass[i]);
  }
  // The bounds overestimate (by 1.86x for w^2 on the liver phantom): the largest eigenvalues
  // themselves, by power iteration, with a margin for the iteration's approach from below.
  if (w2 > 0) w2 = std::min(w2, kEigenMargin * largestRestEigenvalue(false));
  if (gamma > 0) gamma = std::min(gamma, kEigenMargin * largestRestEigenvalue(true));
  if (!(w2 > 0)) return std::numeric_limits<Real>::infinity();
  const Real alpha = m_config.massDamping;
  gamma += alpha;
  Real h;
  if (m_config.integrator == Integrator::SymplecticEuler) {
    // A mode x'' = -w^2 x - g x' under symplectic Euler is stable for w^2 h^2 + 2 g h < 4.
    h = (-gamma + std::sqrt(gamma * gamma + 4 * w2)) / w2;
  } else {
    // Explicit Euler damps a mode only if h < g / w^2 (undamped modes always grow); with the
    // dashpots close to stiffness-proportional (c = beta k) that is h < beta + alpha / w^2 for
    // every mode, and h < 2 / g for the overdamped ones.
    const Real beta = std::isfinite(minRatio) ? minRatio : 0.0;
    h = beta + alpha / w2;
    if (gamma > 0) h = std::min(h, 2 / gamma);
  }
  return kStabilitySafety * h;
}

int MassSpringModel::substepsFor(Real dt) const {
  if (m_config.integrator == Integrator::ImplicitEuler ||
      m_config.integrator == Integrator::LocalGlobal)
    return 1;
  if (m_config.substeps > 0) return m_config.substeps;
  const Real h = stableStep();
  if (!(dt > 0) || !(h < dt)) return 1;
  if (!(h > 0)) return kMaxSubsteps;
  return static_cast<int>(std::min<Real>(kMaxSubsteps, std::ceil(dt / h)));
}

void MassSpringModel::init(const Organ& organ, const MassSpringConfig& config) {
  const Material& mat = organ.material;
  if (!(mat.young > 0) || !(mat.density > 0))
    throw InputError(organ.source, "organ.material", "massspring needs young > 0, density > 0");
  m_config = config;
  m_setupDt = 0;
  m_springs.clear();
  m_tets.resize(0, 4);
  m_surfaceRows.clear();  // a surface network keeps it empty (vertex i is node i)
  m_edgeSprings = m_bendingSprings = 0;
  if (organ.volume) {
    buildTets(organ);
  } else {
    buildSurface(organ);
  }
  const int N = static_cast<int>(m_rest.rows());
  m_contactF = facesOnNodes(organ.surface.F, m_surfaceRows);
  for (Spring& s : m_springs)
    s.c = springDamping(m_config.dampingRatio, s.k, m_mass[s.a], m_mass[s.b]);
  // Springs in the order of their first node: neighbouring springs then touch nearby memory.
  std::stable_sort(m_springs.begin(), m_springs.end(), [](const Spring& p, const Spring& q) {
    return std::min(p.a, p.b) < std::min(q.a, q.b);
  });

  m_fixed.clear();
  if (!organ.fixed.empty()) m_fixed = fixedNodeIndices(m_rest, organ.fixed, organ.surface);
  m_invMass = inverseMasses(m_mass, m_fixed);
  m_stableStep = computeStableStep();  // springs and masses are fixed from here on
  buildSpringArrays();

  const Box box = boundingBox(m_rest);
  m_boxCenter = box.center();
  m_boxHalf = 0.5 * tol::kDivergenceBoxFactor * std::max(box.size().maxCoeff(), Real(1e-9));
  m_graspMask.assign(N, 0);
  if (m_config.integrator == Integrator::ImplicitEuler) buildPattern();
  m_lgChol.reset();  // local_global: pattern analysed and factorised at the first step
  m_lgH = -1;
  m_lgFactoredFor.clear();
  reset();
}

void MassSpringModel::buildSurface(const Organ& organ) {
  const SurfaceMesh& S = organ.surface;
  const int N = S.numVertices();
  if (N == 0 || S.numFaces() == 0)
    throw InputError(organ.source, "organ.surface", "massspring needs a non-empty surface");
  m_rest = S.V;
  m_surfaceIdentity = true;
  m_elements = S.numFaces();
  const Material& mat = organ.material;

  const LumpedSurface lumped = lumpSurface(S, mat.density, m_config.thickness);
  const MatX2i& E = lumped.edges;
  const MatX2i& EF = lumped.edgeFaces;
  m_mass = lumped.mass;

  std::vector<Real> edgeK(E.rows());
  for (Eigen::Index e = 0; e < E.rows(); ++e) {
    Spring s;
    s.a = E(e, 0);
    s.b = E(e, 1);
    s.rest = (S.V.row(s.a) - S.V.row(s.b)).norm();
    if (s.rest <= tol::kDegenerateLength)
      throw InputError(organ.source, "organ.surface edge " + std::to_string(e), "zero-length edge");
    s.k = membraneSpringStiffness(mat.young, m_config.thickness, s.rest, lumped.edgeArea(e));
    edgeK[e] = s.k;
    m_springs.push_back(s);
  }
  m_edgeSprings = E.rows();
  if (m_config.bendingRatio > 0) {
    for (Eigen::Index e = 0; e < E.rows(); ++e) {
      const int f0 = EF(e, 0), f1 = EF(e, 1);
      if (f0 < 0 || f1 < 0) continue;
      auto wing = [&](int f) {
        for (int k = 0; k < 3; ++k)
          if (S.F(f, k) != E(e, 0) && S.F(f, k) != E(e, 1)) return S.F(f, k);
        return -1;
      };
      Spring s;
      s.a = wing(f0);
      s.b = wing(f1);
      s.rest = (S.V.row(s.a) - S.V.row(s.b)).norm();
      if (s.a == s.b || s.rest <= tol::kDegenerateLength) continue;
      s.k = m_config.bendingRatio * edgeK[e];
      m_springs.push_back(s);
      ++m_bendingSprings;
    }
  }
}

void MassSpringModel::buildTets(const Organ& organ) {
  const TetMesh& T = *organ.volume;
  const int N = T.numVertices();
  if (N == 0 || T.numTets() == 0)
    throw InputError(organ.source, "organ.volume", "massspring needs a non-empty tet mesh");
  m_rest = T.V;
  m_tets = T.T;
  m_elements = T.numTets();
  const SurfaceMesh& S = organ.surface;
  m_surfaceIdentity = S.numVertices() == N && S.V == T.V;
  m_surfaceRows.clear();
  if (!m_surfaceIdentity) m_surfaceRows = surfaceVertexNodes(organ, T.V);
  const Material& mat = organ.material;
  const TetMeasures tm = measureTets(T, mat.density, organ.source);
  m_mass = tm.nodeMass;
  for (Eigen::Index e = 0; e < tm.edges.rows(); ++e) {
    Spring s;
    s.a = tm.edges(e, 0);
    s.b = tm.edges(e, 1);
    s.rest = (T.V.row(s.a) - T.V.row(s.b)).norm();
    s.k = volumeSpringStiffness(mat.young, s.rest, tm.edgeVolume[e]);
    m_springs.push_back(s);
  }
  m_edgeSprings = static_cast<long long>(m_springs.size());
}

void MassSpringModel::buildSpringArrays() {
  const size_t n = m_springs.size();
  m_sa.resize(n);
  m_sb.resize(n);
  m_sRest.resize(n);
  m_sK.resize(n);
  m_sC.resize(n);
  for (size_t i = 0; i < n; ++i) {
    const Spring& s = m_springs[i];
    m_sa[i] = 8 * s.a;
    m_sb[i] = 8 * s.b;
    m_sRest[i] = s.rest;
    m_sK[i] = s.k;
    m_sC[i] = s.c;
  }
  const size_t N = static_cast<size_t>(m_rest.rows());
  // Position/velocity rows, then force rows, from a 64-byte boundary (+ 8: room to find it): a
  // row never straddles two cache lines.
  m_rowBuf.assign(12 * N + 8, 0.0);
}

double* MassSpringModel::xvRows() {
  const auto p = reinterpret_cast<std::uintptr_t>(m_rowBuf.data());
  return m_rowBuf.data() + ((64 - p % 64) % 64) / sizeof(double);
}

void MassSpringModel::buildPattern() {
  const int N = static_cast<int>(m_rest.rows());
  std::vector<Triplet> trip;
  trip.reserve(9 * (N + 4 * m_springs.size()));
  auto block = [&](int r, int c) {
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) trip.emplace_back(3 * r + i, 3 * c + j, 0.0);
  };
  for (int i = 0; i < N; ++i) block(i, i);
  for (const Spring& s : m_springs) {
    block(s.a, s.b);
    block(s.b, s.a);
  }
  m_A.resize(3 * N, 3 * N);
  m_A.setFromTriplets(trip.begin(), trip.end());
  m_A.makeCompressed();
  auto slot = [&](int r, int c, int j) {
    const int col = 3 * c + j;
    const int* begin = m_A.innerIndexPtr() + m_A.outerIndexPtr()[col];
    const int* end = m_A.innerIndexPtr() + m_A.outerIndexPtr()[col + 1];
    return static_cast<int>(std::lower_bound(begin, end, 3 * r) - m_A.innerIndexPtr());
  };
  m_nodeSlots.resize(N);
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < 3; ++j) m_nodeSlots[i][j] = slot(i, i, j);
  m_springSlots.resize(m_springs.size());
  for (size_t k = 0; k < m_springs.size(); ++k) {
    const Spring& s = m_springs[k];
    for (int j = 0; j < 3; ++j) {
      m_springSlots[k][j] = slot(s.a, s.a, j);
      m_springSlots[k][3 + j] = slot(s.b, s.b, j);
      m_springSlots[k][6 + j] = slot(s.a, s.b, j);
      m_springSlots[k][9 + j] = slot(s.b, s.a, j);
    }
  }
  m_constrainedDof.assign(3 * N, 0);
}

void MassSpringModel::reset() {
  const int N = static_cast<int>(m_rest.rows());
  m_x = m_rest;
  m_v.setZero(N, 3);
  m_f.setZero(N, 3);
  m_xOld = m_rest;
  m_dv = VecX::Zero(3 * N);
  m_rhs = VecX::Zero(3 * N);
  m_prescribed = VecX::Zero(3 * N);
  std::fill(m_graspMask.begin(), m_graspMask.end(), 0);
  m_graspSpringsFor.clear();
  m_degenerate = m_cgNotConverged = m_cgIterations = 0;
  m_graspForces.clear();
  m_phase.clear();
  m_lgWarm.clear();
  if (!m_surfaceIdentity) {
    m_surface.resize(static_cast<Eigen::Index>(m_surfaceRows.size()), 3);
    for (size_t i = 0; i < m_surfaceRows.size(); ++i) m_surface.row(i) = m_x.row(m_surfaceRows[i]);
  }
}

void MassSpringModel::springForces(const MatX3& x, const MatX3& v, MatX3& f) {
  f.setZero(x.rows(), 3);
  const Real* X = x.data();
  const Real* V = v.data();
  Real* Fp = f.data();
  for (const Spring& s : m_springs) {
    const Real* xa = X + 3 * s.a;
    const Real* xb = X + 3 * s.b;
    const Real d0 = xb[0] - xa[0], d1 = xb[1] - xa[1], d2 = xb[2] - xa[2];
    const Real l2 = d0 * d0 + d1 * d1 + d2 * d2;
    if (l2 <= tol::kDegenerateLength * tol::kDegenerateLength) [[unlikely]] {
      ++m_degenerate;
      continue;
    }
    const Real l = std::sqrt(l2);
    const Real il = 1.0 / l;  // one division per spring: the loop is bound by sqrt/div throughput
    const Real* va = V + 3 * s.a;
    const Real* vb = V + 3 * s.b;
    const Real vn = ((vb[0] - va[0]) * d0 + (vb[1] - va[1]) * d1 + (vb[2] - va[2]) * d2) * il;
    // springForce(): (k (l - L) + c (vb - va).n) n, with n = d / l folded into one factor.
    const Real m = (s.k * (l - s.rest) + s.c * vn) * il;
    rows::addSpringPair(Fp + 3 * s.a, Fp + 3 * s.b, m, d0, d1, d2);
  }
}

void MassSpringModel::setState(const MatX3& x, const MatX3& v) {
  if (x.rows() != m_x.rows() || v.rows() != m_x.rows())
    throw std::invalid_argument("MassSpringModel::setState: wrong number of rows");
  m_x = x;
  m_v = v;
  m_xOld = x;
  if (!m_surfaceIdentity)
    for (size_t i = 0; i < m_surfaceRows.size(); ++i) m_surface.row(i) = m_x.row(m_surfaceRows[i]);
}

StepStatus MassSpringModel::checkDivergence() const {
  // Velocities too: explicit Euler moves positions with the previous velocity, so trouble shows
  // there one step earlier.
  Real sum = m_v.sum(), far = 0;
  const Real* X = m_x.data();
  for (Eigen::Index i = 0; i < m_x.rows(); ++i) {
    for (int k = 0; k < 3; ++k) {
      const Real p = X[3 * i + k];
      sum += p;
      far = std::max(far, std::abs(p - m_boxCenter[k]));
    }
  }
  return (std::isfinite(sum) && far <= m_boxHalf) ? StepStatus::Ok : StepStatus::Diverged;
}

// Grasped nodes end the step on their targets, moving with the tool's velocity; nodes under a
// sliding plate end on its plane, moving with it along its normal (free along the plate).
void MassSpringModel::applyConstraints(const StepInput& in, Real h, const MatX3& xOld) {
  for (const NodeGrasp& g : m_nodeGrasps) {
    if (g.sliding()) continue;
    for (size_t k = 0; k < g.nodes.size(); ++k) {
      const int i = g.nodes[k];
      m_x.row(i) = g.targets.row(k);
      m_v.row(i) = (g.targets.row(k) - xOld.row(i)) / h;
    }
  }
  holdSliding(1, h, m_x.data(), 3, m_v.data(), 3);
}

void MassSpringModel::collectSliding() {
  // m_graspMask marks the bonded grasps' nodes here: a node a bonded grasp holds stays bonded.
  m_sliding.clear();
  for (const NodeGrasp& g : m_nodeGrasps) {
    if (!g.sliding()) continue;
    int axis = -1;
    for (int a = 0; a < 3; ++a)
      if (std::abs(g.slideNormal[a]) == 1 && g.slideNormal.squaredNorm() == 1) axis = a;
    if (axis < 0)
      throw InputError("massspring", "grasp of tool " + std::to_string(g.tool),
                       "a sliding plate's normal must lie along x, y or z");
    for (size_t k = 0; k < g.nodes.size(); ++k)
      if (!m_graspMask[size_t(g.nodes[k])])
        m_sliding.push_back({g.nodes[k], axis, g.targets(Eigen::Index(k), axis)});
  }
}

void MassSpringModel::holdSliding(Real t, Real h, Real* x, int xstride, Real* v,
                                  int vstride) const {
  for (const SlidingHold& s : m_sliding) {
    const Real xo = m_xOld(s.node, s.axis);
    x[size_t(xstride) * size_t(s.node) + size_t(s.axis)] = xo + t * (s.offset - xo);
    if (v) v[size_t(vstride) * size_t(s.node) + size_t(s.axis)] = (s.offset - xo) / h;
  }
}

StepStatus MassSpringModel::step(const StepInput& in) {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  const Real h = in.dt;
  // The grasped surface vertices and the load shares on the nodes that carry them (J a
  // selection: the identity, or a surface vertex -> node table).
  graspsOnNodes(in.grasps, m_surfaceRows, m_nodeGrasps);
  loadsOnNodes(in.loads, m_surfaceRows, m_nodeForces);
  for (size_t i = 0; i < m_graspMask.size(); ++i) m_graspMask[i] = 0;
  for (const NodeGrasp& g : m_nodeGrasps)
    if (!g.sliding())
      for (int i : g.nodes) m_graspMask[i] = 1;
  collectSliding();
  for (const SlidingHold& sh : m_sliding) m_graspMask[size_t(sh.node)] = 1;
  for (const NodeGrasp& g : m_nodeGrasps)
    for (int i : g.nodes) m_xOld.row(i) = m_x.row(i);
  const bool penalty = in.contact && in.contact->params().method == ContactMethod::Penalty;
  if (in.contact) m_stepStart = m_x;
  if (penalty) {
    // Penalty contact: a force on the surface triangles for this step (explicit in the contact).
    m_contactForce.setZero(m_x.rows(), 3);
    const ContactProxy proxy{
        .nodes = &m_x, .velocity = m_v.data(), .faces = &m_contactF, .embedding = {}};
    respondToContact(*in.contact, proxy, ContactResponse::Penalty, h, m_contactForce.data());
  }

  StepStatus status;
  if (m_config.integrator == Integrator::LocalGlobal) {
    status = stepLocalGlobal(in, h);
  } else if (m_config.integrator == Integrator::ImplicitEuler) {
    status = stepImplicit(in, h);
  } else {
    // Explicit and symplectic Euler: n substeps of h / n (substepsFor), the point loads and
    // penalty contact forces held over the step, grasped nodes moved linearly to their targets.
    const int n = substepsFor(h);
    m_lastSubsteps = n;
    const Real hs = h / n;
    const auto t1 = Clock::now();
    double msForces = 0;
    const int N = static_cast<int>(m_x.rows());
    // Positions and velocities as rows of 8 doubles, forces as rows of 4 (explicit_rows.h).
    double* xv = xvRows();
    double* f4 = xv + 8 * static_cast<size_t>(N);
    {
      const Real* X = m_x.data();
      const Real* V = m_v.data();
      for (int i = 0; i < N; ++i)
        for (int k = 0; k < 3; ++k) {
          xv[8 * i + k] = X[3 * i + k];
          xv[8 * i + 4 + k] = V[3 * i + k];
        }
    }
    const rows::SpringArrays springs{m_sa.data(), m_sb.data(), m_sRest.data(),
                                     m_sK.data(), m_sC.data(), m_springs.size()};
    rows::IntegrateArgs args;
    args.w = m_invMass.data();
    args.alpha = m_config.massDamping;
    args.h = hs;
    args.half = m_boxHalf;
    args.symplectic = m_config.integrator == Integrator::SymplecticEuler;
    for (int k = 0; k < 3; ++k) {
      args.g[k] = in.gravity[k];
      args.c[k] = m_boxCenter[k];
    }
    // The divergence check rides along in rows::integrate(): grasped nodes end on their
    // targets, which are finite and inside the box by construction.
    bool ok = true;
    for (int sub = 0; sub < n && ok; ++sub) {
      const auto tf = Clock::now();
      std::fill(f4, f4 + 4 * static_cast<size_t>(N), 0.0);
      m_degenerate += rows::addSpringForces(xv, springs, f4);
      for (const auto& [node, force] : m_nodeForces)
        for (int k = 0; k < 3; ++k) f4[4 * node + k] += force[k];
      if (penalty) {
        const Real* C = m_contactForce.data();
        for (int i = 0; i < N; ++i)
          for (int k = 0; k < 3; ++k) f4[4 * i + k] += C[3 * i + k];
      }
      msForces += std::chrono::duration<double, std::milli>(Clock::now() - tf).count();
      ok = rows::integrate(xv, f4, static_cast<size_t>(N), args);
      if (sub + 1 < n) {
        const Real t = Real(sub + 1) / n;
        for (const NodeGrasp& g : m_nodeGrasps) {
          if (g.sliding()) continue;
          for (size_t k = 0; k < g.nodes.size(); ++k) {
            const int i = g.nodes[k];
            for (int c = 0; c < 3; ++c) {
              const Real xo = m_xOld(i, c), target = g.targets(static_cast<Eigen::Index>(k), c);
              xv[8 * i + 4 + c] = (target - xo) / h;
              xv[8 * i + c] = xo + t * (target - xo);
            }
          }
        }
        holdSliding(t, h, xv, 8, xv + 4, 8);
      }
    }
    {
      Real* X = m_x.data();
      Real* V = m_v.data();
      m_f.resize(N, 3);
      Real* Fp = m_f.data();
      for (int i = 0; i < N; ++i)
        for (int k = 0; k < 3; ++k) {
          X[3 * i + k] = xv[8 * i + k];
          V[3 * i + k] = xv[8 * i + 4 + k];
          Fp[3 * i + k] = f4[4 * i + k];
        }
    }
    applyConstraints(in, h, m_xOld);
    const auto t2 = Clock::now();
    m_phase["forces"] = std::chrono::duration<double, std::milli>(t1 - t0).count() + msForces;
    m_phase["integrate"] = std::chrono::duration<double, std::milli>(t2 - t1).count() - msForces;
    status = ok ? StepStatus::Ok : StepStatus::Diverged;
  }
  if (in.contact && !penalty) {
    // Contact after the integrator: the surface triangles are projected out of the instruments
    // and lose their inward normal velocity; fixed and grasped nodes stay where their
    // constraint put them.
    m_contactInvMass = m_invMass;
    for (const NodeGrasp& g : m_nodeGrasps)
      for (int i : g.nodes) m_contactInvMass[i] = 0;
    const ContactProxy proxy{.nodes = &m_x,
                             .invMass = &m_contactInvMass,
                             .velocity = m_v.data(),
                             .atStepStart = &m_stepStart,
                             .faces = &m_contactF,
                             .embedding = {}};
    respondToContact(*in.contact, proxy, ContactResponse::Project, h);
  }
  if (!m_surfaceIdentity)
    for (size_t i = 0; i < m_surfaceRows.size(); ++i) m_surface.row(i) = m_x.row(m_surfaceRows[i]);
  computeGraspForces(in);
  return status;
}

// Baraff & Witkin 1998, Eq. (16) with df/dx = -Kglob, df/dv = -Dglob - alpha M:
//   ((1 + h alpha) M + h Dglob + h^2 Kglob) dv = h (f0 - h Kglob v0),
// dv prescribed on fixed and grasped nodes (moved to the right-hand side).
StepStatus MassSpringModel::stepImplicit(const StepInput& in, Real h) {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  const int N = static_cast<int>(m_x.rows());
  springForces(m_x, m_v, m_f);
  for (const auto& [node, force] : m_nodeForces) m_f.row(node) += force.transpose();
  if (in.contact && in.contact->params().method == ContactMethod::Penalty) m_f += m_contactForce;
  const Real alpha = m_config.massDamping;
  for (int i = 0; i < N; ++i)
    m_f.row(i) += m_mass[i] * (in.gravity.transpose() - alpha * m_v.row(i));

  // Assemble values into the fixed pattern and Kglob v0 on the way.
  Real* val = m_A.valuePtr();
  std::fill(val, val + m_A.nonZeros(), 0.0);
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < 3; ++j) val[m_nodeSlots[i][j] + j] += (1.0 + h * alpha) * m_mass[i];
  VecX& rhs = m_rhs;
  for (int i = 0; i < N; ++i) rhs.segment<3>(3 * i) = h * m_f.row(i).transpose();
  for (size_t k = 0; k < m_springs.size(); ++k) {
    const Spring& s = m_springs[k];
    const Vec3 xa = m_x.row(s.a), xb = m_x.row(s.b);
    Mat3 K;
    if (!springStiffness(xa, xb, s.k, s.rest, true, K)) continue;  // counted in springForces
    const Vec3 n = (xb - xa).normalized();
    const Mat3 B = h * h * K + (h * s.c) * (n * n.transpose());
    const Vec3 Kv = K * (m_v.row(s.a) - m_v.row(s.b)).transpose();
    rhs.segment<3>(3 * s.a) -= h * h * Kv;
    rhs.segment<3>(3 * s.b) += h * h * Kv;
    const auto& sl = m_springSlots[k];
    for (int j = 0; j < 3; ++j) {
      for (int i = 0; i < 3; ++i) {
        val[sl[j] + i] += B(i, j);
        val[sl[3 + j] + i] += B(i, j);
        val[sl[6 + j] + i] -= B(i, j);
        val[sl[9 + j] + i] -= B(i, j);
      }
    }
  }
  // Prescribed dv: fixed/massless nodes stop, grasped nodes reach their targets.
  std::fill(m_constrainedDof.begin(), m_constrainedDof.end(), 0);
  m_prescribed.setZero();
  for (int i = 0; i < N; ++i) {
    if (m_invMass[i] == 0.0) {
      for (int k = 0; k < 3; ++k) m_constrainedDof[3 * i + k] = 1;
      m_prescribed.segment<3>(3 * i) = -m_v.row(i).transpose();
    }
  }
  for (const NodeGrasp& g : m_nodeGrasps) {
    if (g.sliding()) continue;
    for (size_t k = 0; k < g.nodes.size(); ++k) {
      const int i = g.nodes[k];
      for (int c = 0; c < 3; ++c) m_constrainedDof[3 * i + c] = 1;
      m_prescribed.segment<3>(3 * i) =
          ((g.targets.row(k) - m_x.row(i)) / h - m_v.row(i)).transpose();
    }
  }
  // A sliding plate prescribes the normal dof only.
  for (const SlidingHold& sh : m_sliding) {
    const int d = 3 * sh.node + sh.axis;
    m_constrainedDof[size_t(d)] = 1;
    m_prescribed[d] = (sh.offset - m_x(sh.node, sh.axis)) / h - m_v(sh.node, sh.axis);
  }
  rhs.noalias() -= m_A * m_prescribed;
  for (int col = 0; col < m_A.outerSize(); ++col) {
    for (int p = m_A.outerIndexPtr()[col]; p < m_A.outerIndexPtr()[col + 1]; ++p) {
      const int row = m_A.innerIndexPtr()[p];
      if (m_constrainedDof[col] || m_constrainedDof[row]) val[p] = (row == col) ? 1.0 : 0.0;
    }
  }
  for (int d = 0; d < 3 * N; ++d)
    if (m_constrainedDof[d]) rhs[d] = m_prescribed[d];
  const auto t1 = Clock::now();

  // Conjugate gradients, Jacobi-preconditioned, warm-started with the previous step's dv.
  Eigen::ConjugateGradient<SparseMatrix, Eigen::Lower | Eigen::Upper> cg;
  cg.setTolerance(m_config.cgTolerance);
  cg.setMaxIterations(m_config.cgMaxIterations);
  cg.compute(m_A);
  for (int d = 0; d < 3 * N; ++d)
    if (m_constrainedDof[d]) m_dv[d] = m_prescribed[d];
  m_dv = cg.solveWithGuess(rhs, m_dv);
  m_cgIterations += cg.iterations();
  if (cg.info() != Eigen::Success) ++m_cgNotConverged;
  const auto t2 = Clock::now();

  for (int i = 0; i < N; ++i) {
    m_v.row(i) += m_dv.segment<3>(3 * i).transpose();
    if (m_invMass[i] == 0.0) {
      m_v.row(i).setZero();
      continue;
    }
    m_x.row(i) += h * m_v.row(i);
  }
  applyConstraints(in, h, m_xOld);
  const auto t3 = Clock::now();
  auto ms = [](auto a, auto b) { return std::chrono::duration<double, std::milli>(b - a).count(); };
  m_phase["assembly"] = ms(t0, t1);
  m_phase["solve"] = ms(t1, t2);
  m_phase["integrate"] = ms(t2, t3);
  if (!m_dv.allFinite()) return StepStatus::Diverged;
  return checkDivergence();
}

// Force the tissue exerts on each grasp: the internal spring forces (elastic + axial damping) on
// the grasped nodes at the end of the step.
void MassSpringModel::computeGraspForces(const StepInput& in) {
  m_graspForces.assign(in.grasps.size(), Vec3::Zero());
  if (in.grasps.empty()) return;
  // The springs touching a grasped node, listed again only when the grasped set changes (a grasp
  // holds the same nodes for many steps): the per-step cost is then that of the few springs.
  std::vector<int>& grasped = m_graspedScratch;
  graspedNodeSet(m_nodeGrasps, grasped);
  if (grasped != m_graspSpringsFor) {
    m_graspSprings.clear();
    for (size_t k = 0; k < m_springs.size(); ++k)
      if (m_graspMask[m_springs[k].a] | m_graspMask[m_springs[k].b])
        m_graspSprings.push_back(static_cast<int>(k));
    m_graspSpringsFor = grasped;
  }
  for (int i : grasped) m_f.row(i).setZero();
  for (int k : m_graspSprings) {
    const Spring& s = m_springs[k];
    Vec3 fa;
    if (!springForce(m_x.row(s.a), m_x.row(s.b), m_v.row(s.a), m_v.row(s.b), s.k, s.c, s.rest, fa))
      continue;
    if (m_graspMask[s.a]) m_f.row(s.a) += fa.transpose();
    if (m_graspMask[s.b]) m_f.row(s.b) -= fa.transpose();
  }
  for (size_t g = 0; g < in.grasps.size(); ++g) {
    for (int node : m_nodeGrasps[g].nodes) m_graspForces[g] += m_f.row(node).transpose();
    // A sliding plate takes the normal component only (the tangential is left to the tissue).
    if (m_nodeGrasps[g].sliding()) {
      const Vec3 n = m_nodeGrasps[g].slideNormal;
      m_graspForces[g] = n * n.dot(m_graspForces[g]);
    }
  }
}

Counts MassSpringModel::counts() const {
  return {{"nodes", m_x.rows()},
          {"elements", m_elements},
          {"springs", static_cast<long long>(m_springs.size())},
          {"edge_springs", m_edgeSprings},
          {"bending_springs", m_bendingSprings},
          {"substeps", m_setupDt > 0 ? substepsFor(m_setupDt) : 1}};
}

NumericCounters MassSpringModel::numericCounters() const {
  NumericCounters c{{"degenerate_springs", m_degenerate}};
  if (m_tets.rows() > 0) c["inverted_tets"] = invertedTets(m_tets, m_x);
  if (m_config.integrator == Integrator::ImplicitEuler) {
    c["cg_not_converged"] = m_cgNotConverged;
    c["cg_iterations"] = m_cgIterations;
  }
  if (m_config.integrator == Integrator::LocalGlobal) c["factorisations"] = m_lgFactorisations;
  return c;
}

}  // namespace deform::massspring
