#include "metaballs_model.h"

#include <deform/sdk/contact.h>
#include <deform/sdk/sliding_plate.h>
#include "pbd_constraints.h"

#include <Eigen/SVD>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace deform::metaballs {

namespace {
using Clock = std::chrono::steady_clock;

/// Damped least-squares inverse of A (m x n): V diag(s / (s^2 + mu)) U^T, mu = kDamping s_max^2.
/// The grasp's skinning rows can be nearly dependent (spheres seen alike by every grasped
/// vertex); the plain pseudo-inverse then turns the small changes of the skinning offsets (radii,
/// rotations) into large sphere motions, which feed back through the rotations. The damping
/// bounds the gain by 1 / (2 sqrt(mu)) and leaves the well-conditioned directions (a rigid
/// translation among them) corrected to within a factor mu / s^2 per correction.
MatX dampedInverse(const MatX& A) {
  constexpr Real kDamping = 1e-3;
  if (A.size() == 0) return MatX(A.cols(), A.rows());
  const Eigen::JacobiSVD<MatX> svd(A, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const VecX& s = svd.singularValues();
  const Real mu = kDamping * s(0) * s(0);
  const VecX gain = s.array() / (s.array().square() + mu).max(1e-300);
  return svd.matrixV() * gain.asDiagonal() * svd.matrixU().transpose();
}
double msSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}
}  // namespace

void MetaballsModel::init(const ModelSetup& setup) {
  const ParamValues& p = setup.params;
  const Organ& organ = setup.organ;
  try {
    m_mb = constructMetaballsCached(organ.surface, constructionParams(p), setup.cache, &m_cacheHit);
  } catch (const std::runtime_error& e) {
    throw InputError(organ.source, "metaballs construction", e.what());
  }
  m_iterations = int(p.integer("iterations"));
  m_mode = p.choiceAs<StiffnessMode>(
      "stiffness_mode", {{"xpbd", StiffnessMode::Xpbd}, {"classic", StiffnessMode::Classic}});
  // Classic PBD: make the effective stiffness independent of the iteration count.
  m_stiffness = 1.0 - std::pow(1.0 - p.real("stiffness"), 1.0 / m_iterations);
  m_laplacian = p.flag("laplacian");
  const Real lapK = p.real("laplacian_stiffness");
  m_lapStiffness = 1.0 - std::pow(1.0 - lapK, 1.0 / m_iterations);
  const std::vector<std::pair<std::string, Frame>> frames = {{"rotated", Frame::Rotated},
                                                             {"fixed", Frame::Fixed}};
  m_lapFrame = p.choiceAs<Frame>("laplacian_frame", frames);
  m_skinFrame = p.choiceAs<Frame>("skinning_frame", frames);
  m_volume = p.flag("volume_preservation");
  m_damping = p.real("damping");

  const SphereSet& s = m_mb.spheres;
  const int n = s.size();
  const MatX2i& L = m_mb.topology.links;
  const int nl = int(L.rows());
  m_x0 = s.centers;
  m_restSurface = organ.surface.V;
  m_skinThreshold = p.real("skin_threshold");
  m_skinMaxSpheres = int(p.integer("skin_max_spheres"));
  m_skin = buildSkinning(organ.surface.V, s, m_skinThreshold, m_skinMaxSpheres);

  // Mass: the organ's mass rho V shared in proportion to sphere volume.
  const Real E = organ.material.young, rho = organ.material.density;
  const Real volume = std::abs(signedVolume(organ.surface.V, organ.surface.F));
  const Real r3sum = s.radii.array().cube().sum();
  m_invMass.resize(n);
  for (int i = 0; i < n; ++i) m_invMass(i) = r3sum / (rho * volume * std::pow(s.radii(i), 3));

  // Links: rest lengths; XPBD compliance of a rod k = E A / L with the common cross-section
  // A = V / sum(L) (the links together fill the organ's volume once).
  m_linkRest.resize(size_t(nl));
  m_linkAlpha.resize(size_t(nl));
  Real lsum = 0;
  for (int l = 0; l < nl; ++l) {
    m_linkRest[size_t(l)] = (s.center(L(l, 0)) - s.center(L(l, 1))).norm();
    lsum += m_linkRest[size_t(l)];
  }
  const Real area = lsum > 0 ? volume / lsum : 0;
  for (int l = 0; l < nl; ++l) m_linkAlpha[size_t(l)] = m_linkRest[size_t(l)] / (E * area);

  // CSR adjacency, neighbours sorted.
  m_adjStart.assign(size_t(n) + 1, 0);
  for (int l = 0; l < nl; ++l) {
    ++m_adjStart[size_t(L(l, 0)) + 1];
    ++m_adjStart[size_t(L(l, 1)) + 1];
  }
  for (int i = 0; i < n; ++i) m_adjStart[size_t(i) + 1] += m_adjStart[size_t(i)];
  m_adj.assign(size_t(m_adjStart[size_t(n)]), 0);
  std::vector<int> fill(m_adjStart.begin(), m_adjStart.end() - 1);
  for (int l = 0; l < nl; ++l) {
    m_adj[size_t(fill[size_t(L(l, 0))]++)] = L(l, 1);
    m_adj[size_t(fill[size_t(L(l, 1))]++)] = L(l, 0);
  }
  m_lapRest.setZero(n, 3);
  m_lapAlpha.setZero(n);
  m_restSumD.setZero(n);
  for (int m = 0; m < n; ++m) {
    const int b = m_adjStart[size_t(m)], e = m_adjStart[size_t(m) + 1];
    Vec3 centre = Vec3::Zero();
    for (int k = b; k < e; ++k) {
      centre += s.center(m_adj[size_t(k)]);
      m_restSumD(m) += (s.center(m) - s.center(m_adj[size_t(k)])).norm();
    }
    if (e > b) m_lapRest.row(m) = (s.center(m) - centre / Real(e - b)).transpose();
    m_lapAlpha(m) = lapK > 0 ? 1.0 / (lapK * E * s.radii(m)) : 0;
  }
  m_laplacian = m_laplacian && lapK > 0;

  // The fixed region holds the spheres whose centres it contains and, since it is defined on the
  // surface as grasps are, the sphere carrying most of each surface vertex inside it: the centres
  // lie deep in the organ, and a thin fixed slab along the surface contains none of them (the
  // organ then fell freely under gravity).
  // Every sphere that carries a clamped surface vertex is held (at rest, unrotated, its rest
  // radius): holding only the main carrier let the free ones drag the clamped skin along (6.2 of
  // an 11.2 mm lift in the conformance grasp).
  m_fixedList = fixedNodeIndices(m_x0, organ.fixed, organ.surface);
  for (int v : fixedNodeIndices(organ.surface.V, organ.fixed, organ.surface)) {
    const size_t base = size_t(v) * size_t(m_skin.slots);
    for (int k = 0; k < m_skin.count[size_t(v)]; ++k)
      if (m_skin.weight[base + size_t(k)] > 0)
        m_fixedList.push_back(m_skin.sphere[base + size_t(k)]);
  }
  std::sort(m_fixedList.begin(), m_fixedList.end());
  m_fixedList.erase(std::unique(m_fixedList.begin(), m_fixedList.end()), m_fixedList.end());
  m_fixed.assign(size_t(n), 0);
  for (int i : m_fixedList) m_fixed[size_t(i)] = 1;

  // Solver layout: links by colour; rest offsets of every adjacency entry for the rotations.
  m_batches = buildStretchBatches(
      L, m_linkRest, m_mode == StiffnessMode::Xpbd ? m_linkAlpha : std::vector<Real>(size_t(nl), 0),
      n);
  const size_t nb = size_t(m_batches.size());
  m_sdata.wa.assign(nb, 0);
  m_sdata.wb.assign(nb, 0);
  m_sdata.alphaTilde.assign(nb, 0);
  m_sdata.lambda.assign(nb, 0);
  m_restOff.assign(m_adj.size() * 3, 0);
  for (int m = 0; m < n; ++m)
    for (int k = m_adjStart[size_t(m)]; k < m_adjStart[size_t(m) + 1]; ++k)
      for (int c = 0; c < 3; ++c)
        m_restOff[3 * size_t(k) + size_t(c)] = m_x0(m_adj[size_t(k)], c) - m_x0(m, c);
  m_ldata.order = laplacianOrder(m_adjStart, m_adj);
  m_ldata.W.assign(size_t(n), 0);
  m_ldata.invDenom.assign(size_t(n), 0);
  m_ldata.coef.assign(m_adj.size(), 0);
  m_ldata.target.assign(size_t(n) * 4, 0);
  m_ldata.alphaTilde.assign(size_t(n), 0);
  m_ldata.lambda.assign(size_t(n) * 4, 0);
  m_alphaDt = -1;

  m_p4.assign(size_t(n + 1) * 4, 0);
  m_f.resize(n, 3);
  m_kin.assign(size_t(n), 0);
  m_wEff.assign(size_t(n) + 1, 0);
  m_volFactorSum.assign(size_t(n), 0);
  m_volCount.assign(size_t(n), 0);
  m_rot.assign(size_t(n) * 9, 0);
  m_rotBatch.resize(n);
  m_frames.assign(size_t(n) * kFrameStride, 0);
  m_contacted.reserve(size_t(n));
  buildSkinTranspose();
  reset();
}

void MetaballsModel::reset() {
  const int n = m_mb.spheres.size();
  m_x = m_x0;
  m_v.setZero(n, 3);
  m_r = m_mb.spheres.radii;
  m_rotBatch.setIdentity();
  for (int i = 0; i < n; ++i)
    for (int q = 0; q < 9; ++q) m_rot[size_t(9 * i + q)] = (q % 4 == 0) ? 1.0 : 0.0;
  m_surface = m_restSurface;
  m_mapVerts.clear();
  m_carry.clear();
  m_sliding.clear();
  m_phases = Phases();
  m_degenerate = 0;
}

void MetaballsModel::computeRotations() {
  const int n = m_mb.spheres.size();
  const Real* X = m_x.data();
  const size_t P = size_t(m_rotBatch.padded);
  Real* A = m_rotBatch.A.data();
  for (int m = 0; m < n; ++m) {
    // A = sum_i (x_i - x_m)(x0_i - x0_m)^T over the linked spheres (0 without links: identity).
    Real a[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
    const Real* xm = X + 3 * m;
    for (int k = m_adjStart[size_t(m)]; k < m_adjStart[size_t(m) + 1]; ++k) {
      const Real* xi = X + 3 * m_adj[size_t(k)];
      const Real* r0 = m_restOff.data() + 3 * size_t(k);
      const Real d[3] = {xi[0] - xm[0], xi[1] - xm[1], xi[2] - xm[2]};
      for (int r = 0; r < 3; ++r)
        for (int c = 0; c < 3; ++c) a[3 * r + c] += d[r] * r0[c];
    }
    for (int q = 0; q < 9; ++q) A[size_t(q) * P + size_t(m)] = a[q];
  }
  // Warm-started from the previous step: a few iterations track the rotation.
  extractRotations(m_rotBatch, 3, m_rot.data(), m_simd);
}

PhaseTimes MetaballsModel::phaseTimes() const {
  return {{"pbd", m_phases.pbd},
          {"laplacian", m_phases.laplacian},
          {"volume", m_phases.volume},
          {"rotations", m_phases.rotations},
          {"skinning", m_phases.skinning}};
}

void MetaballsModel::collectGrasps(const StepInput& in) {
  flattenGrasps(bondedGrasps(in.grasps, m_bondedScratch), m_skin.numVertices, m_graspVerts,
                m_graspTargets);
  m_bondedChanged = m_graspVerts != m_mapVerts;
  if (m_graspVerts == m_mapVerts) return;
  // The grasped set changed (a grasp closed or opened): carrying spheres and W_C^+.
  m_mapVerts = m_graspVerts;
  m_carry.clear();
  const int K = m_skin.slots;
  for (int v : m_graspVerts)
    for (int k = 0; k < m_skin.count[size_t(v)]; ++k) {
      const size_t slot = size_t(v) * size_t(K) + size_t(k);
      if (m_skin.weight[slot] > 0 && !m_fixed[size_t(m_skin.sphere[slot])])
        m_carry.push_back(m_skin.sphere[slot]);
    }
  std::sort(m_carry.begin(), m_carry.end());
  m_carry.erase(std::unique(m_carry.begin(), m_carry.end()), m_carry.end());
  const Eigen::Index m = Eigen::Index(m_graspVerts.size()), nc = Eigen::Index(m_carry.size());
  MatX Wc = MatX::Zero(m, nc);
  for (Eigen::Index r = 0; r < m; ++r)
    for (int k = 0; k < m_skin.count[size_t(m_graspVerts[size_t(r)])]; ++k) {
      const size_t slot = size_t(m_graspVerts[size_t(r)]) * size_t(K) + size_t(k);
      const auto it = std::lower_bound(m_carry.begin(), m_carry.end(), m_skin.sphere[slot]);
      if (it != m_carry.end() && *it == m_skin.sphere[slot])
        Wc(r, Eigen::Index(it - m_carry.begin())) += m_skin.weight[slot];
    }
  m_WcPinv = dampedInverse(Wc);
  // The jaws hold the tissue between them without turning it (the targets translate): the
  // carrying spheres keep their local rotations of the closing while held, so the skinning
  // offsets of the grasped vertices stay reachable by centre motions.
  // Their radii too: eq. (12) would scale them with their links' lengths, which the grasp
  // correction itself changes. Each correction then fed the next (the link stretch shrank the
  // radius, the shrunk radius drew the grasped vertices in, the correction stretched the links
  // further): on the method-comparison liver lift the surface grew by 2x every ~20 ms to 0.1 m.
  m_carryRot.resize(m_carry.size() * 9);
  m_carryR.resize(m_carry.size());
  for (size_t k = 0; k < m_carry.size(); ++k) {
    std::copy_n(m_rot.begin() + 9 * std::ptrdiff_t(m_carry[k]), 9,
                m_carryRot.begin() + 9 * std::ptrdiff_t(k));
    m_carryR[k] = m_r(m_carry[k]);
  }
}

void MetaballsModel::collectSliding(const StepInput& in) {
  size_t count = 0;
  std::vector<int> bonded = m_graspVerts;
  std::sort(bonded.begin(), bonded.end());
  const int K = m_skin.slots;
  for (const GraspInput& g : in.grasps) {
    if (!g.sliding()) continue;
    const SlidingPick pick = slidingPick(g, m_skin.numVertices, bonded, "metaballs");
    const int axis = pick.axis;
    const std::vector<int>& verts = pick.verts;
    if (m_sliding.size() <= count) m_sliding.emplace_back();
    SlidingSet& s = m_sliding[count++];
    s.targets = pick.targets;
    if (verts == s.verts && axis == s.axis && !m_bondedChanged) continue;
    s.verts = verts;
    s.axis = axis;
    s.carry.clear();
    for (int v : verts)
      for (int k = 0; k < m_skin.count[size_t(v)]; ++k) {
        const size_t slot = size_t(v) * size_t(K) + size_t(k);
        const int i = m_skin.sphere[slot];
        if (m_skin.weight[slot] > 0 && !m_fixed[size_t(i)] &&
            !std::binary_search(m_carry.begin(), m_carry.end(), i))
          s.carry.push_back(i);
      }
    std::sort(s.carry.begin(), s.carry.end());
    s.carry.erase(std::unique(s.carry.begin(), s.carry.end()), s.carry.end());
    MatX Wc = MatX::Zero(Eigen::Index(verts.size()), Eigen::Index(s.carry.size()));
    for (size_t r = 0; r < verts.size(); ++r)
      for (int k = 0; k < m_skin.count[size_t(verts[r])]; ++k) {
        const size_t slot = size_t(verts[r]) * size_t(K) + size_t(k);
        const auto it = std::lower_bound(s.carry.begin(), s.carry.end(), m_skin.sphere[slot]);
        if (it != s.carry.end() && *it == m_skin.sphere[slot])
          Wc(Eigen::Index(r), Eigen::Index(it - s.carry.begin())) += m_skin.weight[slot];
      }
    // The carrying spheres move together along the axis (see slidingCorrection): a vertex moves
    // by its weight on them, the row sum of W_C (1 unless it also hangs on fixed spheres).
    s.share = Wc.rowwise().sum();
    // Their radii and rotations stay those of the closing, as a grasp's (see collectGrasps).
    s.radii.resize(s.carry.size());
    s.rot.resize(9 * s.carry.size());
    for (size_t k = 0; k < s.carry.size(); ++k) {
      s.radii[k] = m_r(s.carry[k]);
      std::copy_n(m_rot.begin() + 9 * std::ptrdiff_t(s.carry[k]), 9,
                  s.rot.begin() + 9 * std::ptrdiff_t(k));
    }
  }
  m_sliding.resize(count);
}

VecX MetaballsModel::slidingCorrection(size_t k) const {
  const SlidingSet& s = m_sliding[k];
  VecX gap(Eigen::Index(s.verts.size()));
  for (Eigen::Index r = 0; r < gap.size(); ++r)
    gap[r] = s.targets[r] - m_surface(s.verts[size_t(r)], s.axis);
  // One shift delta of every carrying sphere along the axis, least squares over the vertices
  // (delta = a . gap / a . a, a the rows' shares). The minimum-norm W_C^+ gap moved the carrying
  // spheres apart instead: on the Truth Cube (80 mm, 606 spheres) its corrections, applied step
  // after step, drove big spheres 24 mm up and others 23 mm down under a 4 mm press, and the
  // network pushed them aside (the run invalid); W_C^+ on what the shift leaves settled but
  // fitted the beads worse (4.11 against 2.83 mm at 12.5%). A vertex that also hangs on fixed
  // spheres (shares down to 0.51 there) falls short of the plate: grasp residual 0.16 / 0.45 mm
  // RMS at 4 / 10 mm of travel.
  const Real aa = s.share.squaredNorm();
  const Real delta = aa > 0 ? s.share.dot(gap) / aa : 0.0;
  return VecX::Constant(Eigen::Index(s.carry.size()), delta);
}

void MetaballsModel::holdSliding(Real* P) const {
  for (const SlidingSet& s : m_sliding)
    for (size_t k = 0; k < s.carry.size(); ++k)
      P[4 * size_t(s.carry[k]) + size_t(s.axis)] = s.carryTarget[Eigen::Index(k)];
}

void MetaballsModel::graspCorrection() {
  const Eigen::Index m = Eigen::Index(m_graspVerts.size());
  m_graspGap.resize(m, 3);
  for (Eigen::Index r = 0; r < m; ++r)
    m_graspGap.row(r) = m_graspTargets.row(r) - m_surface.row(m_graspVerts[size_t(r)]);
  m_graspDc.resize(Eigen::Index(m_carry.size()), 3);
  m_graspDc.noalias() = m_WcPinv * m_graspGap;
}

void MetaballsModel::applyLoads(const StepInput& in) {
  m_f.setZero();
  m_contacted.clear();
  const int K = m_skin.slots;
  auto addVertexForce = [&](int v, const Vec3& f) {
    if (v < 0 || v >= m_skin.numVertices) return;
    for (int s = 0; s < K; ++s) {
      const size_t slot = size_t(v) * size_t(K) + size_t(s);
      if (m_skin.weight[slot] <= 0) continue;
      m_f.row(m_skin.sphere[slot]) += m_skin.weight[slot] * f.transpose();
      m_contacted.push_back(m_skin.sphere[slot]);
    }
  };
  for (const PointLoad& load : in.loads) {
    if (load.vertices.empty()) addVertexForce(load.surfaceVertex, load.force);
    for (size_t k = 0; k < load.vertices.size() && k < load.weights.size(); ++k)
      addVertexForce(load.vertices[k], load.weights[k] * load.force);
  }
}

void MetaballsModel::prepareConstraints(Real dt) {
  const int n = m_mb.spheres.size();
  const Real dt2 = dt * dt;
  const bool xpbd = m_mode == StiffnessMode::Xpbd;
  // Per-step constants of the constraints.
  if (dt != m_alphaDt) {
    for (size_t j = 0; j < m_sdata.alphaTilde.size(); ++j)
      m_sdata.alphaTilde[j] = xpbd ? m_batches.compliance[j] / dt2 : 0;
    for (int m = 0; m < n; ++m) m_ldata.alphaTilde[size_t(m)] = xpbd ? m_lapAlpha(m) / dt2 : 0;
    m_alphaDt = dt;
  }
  for (size_t j = 0; j < m_sdata.wa.size(); ++j) {
    m_sdata.wa[j] = m_wEff[size_t(m_batches.a[j])];
    m_sdata.wb[j] = m_wEff[size_t(m_batches.b[j])];
  }
  std::fill(m_sdata.lambda.begin(), m_sdata.lambda.end(), 0.0);
  if (m_laplacian) {
    const bool lapRot = m_lapFrame == Frame::Rotated;
    for (int m = 0; m < n; ++m) {
      const int b = m_adjStart[size_t(m)], e = m_adjStart[size_t(m) + 1];
      const int cnt = e - b;
      Real wsum = 0;
      for (int k = b; k < e; ++k) {
        const Real wi = m_wEff[size_t(m_adj[size_t(k)])];
        wsum += wi;
        m_ldata.coef[size_t(k)] = cnt > 0 ? wi / Real(cnt) : 0;
      }
      const Real wm = m_wEff[size_t(m)];
      m_ldata.W[size_t(m)] = (cnt == 0 || wm + wsum == 0) ? 0 : wm + wsum / Real(cnt * cnt);
      const Vec3 Lm = m_lapRest.row(m).transpose();
      const Vec3 t = lapRot ? Vec3(Eigen::Map<const Eigen::Matrix<Real, 3, 3, Eigen::RowMajor>>(
                                       &m_rot[size_t(9 * m)]) *
                                   Lm)
                            : Lm;
      for (int c = 0; c < 3; ++c) m_ldata.target[4 * size_t(m) + size_t(c)] = t(c);
      const Real W = m_ldata.W[size_t(m)];
      m_ldata.invDenom[size_t(m)] = W > 0 ? 1 / (W + m_ldata.alphaTilde[size_t(m)]) : 0;
    }
    std::fill(m_ldata.lambda.begin(), m_ldata.lambda.end(), 0.0);
  }
}

void MetaballsModel::updateRadii() {
  m_r = m_mb.spheres.radii;
  if (m_volume && !m_contacted.empty()) {
    std::sort(m_contacted.begin(), m_contacted.end());
    m_contacted.erase(std::unique(m_contacted.begin(), m_contacted.end()), m_contacted.end());
    for (int c : m_contacted) {
      const int b = m_adjStart[size_t(c)], e = m_adjStart[size_t(c) + 1];
      Real sum = 0;
      for (int k = b; k < e; ++k) sum += (m_x.row(c) - m_x.row(m_adj[size_t(k)])).norm();
      const Real f = volumeRadiusScale(m_restSumD(c), sum);
      m_volFactorSum[size_t(c)] += f;
      ++m_volCount[size_t(c)];
      for (int k = b; k < e; ++k) {
        m_volFactorSum[size_t(m_adj[size_t(k)])] += f;
        ++m_volCount[size_t(m_adj[size_t(k)])];
      }
    }
    // A sphere in several interaction areas takes the mean of their factors.
    for (int c : m_contacted) {
      for (int k = m_adjStart[size_t(c)] - 1; k < m_adjStart[size_t(c) + 1]; ++k) {
        const int i = k < m_adjStart[size_t(c)] ? c : m_adj[size_t(k)];
        if (m_volCount[size_t(i)] == 0) continue;
        if (!m_fixed[size_t(i)])
          m_r(i) = m_mb.spheres.radii(i) * m_volFactorSum[size_t(i)] / m_volCount[size_t(i)];
        m_volFactorSum[size_t(i)] = 0;
        m_volCount[size_t(i)] = 0;
      }
    }
  }
  for (size_t k = 0; k < m_carry.size(); ++k) m_r(m_carry[k]) = m_carryR[k];
  for (const SlidingSet& s : m_sliding)
    for (size_t k = 0; k < s.carry.size(); ++k) m_r(s.carry[k]) = s.radii[k];
}

void MetaballsModel::buildSkinTranspose() {
  const int n = m_mb.spheres.size();
  // Sphere -> the vertices it skins (the transpose of W), for W dc after a grasp correction.
  m_vertStart.assign(size_t(n) + 1, 0);
  for (int v = 0; v < m_skin.numVertices; ++v)
    for (int k = 0; k < m_skin.count[size_t(v)]; ++k)
      ++m_vertStart[size_t(m_skin.sphere[size_t(v) * size_t(m_skin.slots) + size_t(k)]) + 1];
  for (int i = 0; i < n; ++i) m_vertStart[size_t(i) + 1] += m_vertStart[size_t(i)];
  m_vertOf.assign(size_t(m_vertStart[size_t(n)]), 0);
  m_vertW.assign(m_vertOf.size(), 0);
  {
    std::vector<int> at(m_vertStart.begin(), m_vertStart.end() - 1);
    for (int v = 0; v < m_skin.numVertices; ++v)
      for (int k = 0; k < m_skin.count[size_t(v)]; ++k) {
        const size_t slot = size_t(v) * size_t(m_skin.slots) + size_t(k);
        const int pos = at[size_t(m_skin.sphere[slot])]++;
        m_vertOf[size_t(pos)] = v;
        m_vertW[size_t(pos)] = m_skin.weight[slot];
      }
  }
}

void MetaballsModel::placeHeldSpheres(const StepInput& in, Real* P) {
  // Kinematic spheres: fixed ones stay at rest; the carrying spheres of the grasped vertices move
  // by dc_C = W_C^+ (t - v), from the surface at the step's start.
  std::copy(m_fixed.begin(), m_fixed.end(), m_kin.begin());
  for (int i : m_fixedList)
    for (int c = 0; c < 3; ++c) P[4 * i + c] = m_x0(i, c);
  collectGrasps(in);
  if (!m_graspVerts.empty()) {
    graspCorrection();
    for (size_t k = 0; k < m_carry.size(); ++k) {
      const int i = m_carry[k];
      m_kin[size_t(i)] = 1;
      for (int c = 0; c < 3; ++c) P[4 * i + c] = m_x(i, c) + m_graspDc(Eigen::Index(k), c);
      m_contacted.push_back(i);
    }
  }
  // Spheres carrying a sliding plate's vertices: free, their axis coordinate held (holdSliding).
  collectSliding(in);
  for (size_t k = 0; k < m_sliding.size(); ++k) {
    SlidingSet& s = m_sliding[k];
    const VecX dc = slidingCorrection(k);
    s.carryTarget.resize(Eigen::Index(s.carry.size()));
    for (size_t c = 0; c < s.carry.size(); ++c) {
      s.carryTarget[Eigen::Index(c)] = m_x(s.carry[c], s.axis) + dc[Eigen::Index(c)];
      m_contacted.push_back(s.carry[c]);
    }
  }
}

void MetaballsModel::correctHeldAfterSkinning(Real dt) {
  if (!m_graspVerts.empty() && !m_carry.empty()) {
    // The radii and rotations of this step moved the grasped vertices off W dc: correct the
    // carrying spheres again; with the radii and rotations kept, the skinned surface changes by
    // exactly W dc (the vertices of those spheres only).
    graspCorrection();
    for (size_t k = 0; k < m_carry.size(); ++k) {
      const int i = m_carry[k];
      const Eigen::RowVector3d dc = m_graspDc.row(Eigen::Index(k));
      m_x.row(i) += dc;
      m_v.row(i) += dc / dt;
      for (int q = m_vertStart[size_t(i)]; q < m_vertStart[size_t(i) + 1]; ++q)
        m_surface.row(m_vertOf[size_t(q)]) += m_vertW[size_t(q)] * dc;
    }
  }
  // The same along each sliding plate's axis alone.
  for (size_t k = 0; k < m_sliding.size(); ++k) {
    const SlidingSet& s = m_sliding[k];
    if (s.carry.empty()) continue;
    const VecX dc = slidingCorrection(k);
    for (size_t c = 0; c < s.carry.size(); ++c) {
      const int i = s.carry[c];
      m_x(i, s.axis) += dc[Eigen::Index(c)];
      m_v(i, s.axis) += dc[Eigen::Index(c)] / dt;
      for (int q = m_vertStart[size_t(i)]; q < m_vertStart[size_t(i) + 1]; ++q)
        m_surface(m_vertOf[size_t(q)], s.axis) += m_vertW[size_t(q)] * dc[Eigen::Index(c)];
    }
  }
}

StepStatus MetaballsModel::step(const StepInput& in) {
  const int n = m_mb.spheres.size();
  const Real dt = in.dt;
  if (!(dt > 0)) return StepStatus::Ok;
  auto t0 = Clock::now();

  // External forces: W^T f, every per-vertex share of the harness's patch over the vertex's
  // spheres by skinning weight (a load without a spread acts on its vertex alone).
  applyLoads(in);
  Real* P = m_p4.data();
  placeHeldSpheres(in, P);
  // Algorithm 3, lines 8-13: prediction with damping.
  const Real keep = std::max(Real(0), 1 - m_damping * dt);
  for (int i = 0; i < n; ++i) {
    if (m_kin[size_t(i)]) {
      m_wEff[size_t(i)] = 0;
      continue;
    }
    m_wEff[size_t(i)] = m_invMass(i);
    m_v.row(i) = keep * (m_v.row(i) + dt * (in.gravity.transpose() + m_invMass(i) * m_f.row(i)));
    for (int c = 0; c < 3; ++c) P[4 * i + c] = m_x(i, c) + dt * m_v(i, c);
  }
  holdSliding(P);
  const bool xpbd = m_mode == StiffnessMode::Xpbd;
  prepareConstraints(dt);
  double tStretch = msSince(t0), tLap = 0;
  long long degenerate = 0;
  const Real kStretch = xpbd ? 1.0 : m_stiffness, kLap = xpbd ? 1.0 : m_lapStiffness;
  for (int it = 0; it < m_iterations; ++it) {
    auto ts = Clock::now();
    degenerate += projectStretchSweep(m_batches, m_sdata, P, kStretch, m_simd);
    auto tl = Clock::now();
    tStretch += std::chrono::duration<double, std::milli>(tl - ts).count();
    if (m_laplacian) {
      projectLaplacianSweep(m_adjStart, m_adj, m_wEff.data(), m_ldata, P, kLap, m_simd);
      tLap += msSince(tl);
    }
    holdSliding(P);
  }
  // Contact: the spheres (current radii) are projected out of the instruments after the sweeps,
  // like any other position constraint; kinematic spheres do not move.
  if (in.contact) {
    // The sweeps work on the padded rows P; the shared contact routine takes a #n by 3 matrix.
    m_p.resize(n, 3);
    for (int i = 0; i < n; ++i)
      for (int c = 0; c < 3; ++c) m_p(i, c) = P[4 * i + c];
    const VecX w = Eigen::Map<const VecX>(m_wEff.data(), n);
    ContactProxy proxy;
    proxy.nodes = &m_p;
    proxy.invMass = &w;
    proxy.radii = &m_r;
    respondToContact(*in.contact, proxy, ContactResponse::Project, dt);
    for (int i = 0; i < n; ++i)
      for (int c = 0; c < 3; ++c) P[4 * i + c] = m_p(i, c);
  }
  // Algorithm 3, lines 18-21.
  auto ts = Clock::now();
  const Real invDt = 1.0 / dt;
  for (int i = 0; i < n; ++i) {
    for (int c = 0; c < 3; ++c) {
      m_v(i, c) = m_fixed[size_t(i)] ? 0.0 : (P[4 * i + c] - m_x(i, c)) * invDt;
      m_x(i, c) = P[4 * i + c];
    }
  }
  tStretch += msSince(ts);
  m_degenerate += degenerate;
  computeGraspForces(in, dt);

  // Eq. (12) on the spheres under interaction and their linked spheres.
  ts = Clock::now();
  updateRadii();
  const double tVol = msSince(ts);

  ts = Clock::now();
  if (m_lapFrame == Frame::Rotated || m_skinFrame == Frame::Rotated) {
    computeRotations();
    if (!m_graspVerts.empty())
      for (size_t k = 0; k < m_carry.size(); ++k)
        std::copy_n(m_carryRot.begin() + 9 * std::ptrdiff_t(k), 9,
                    m_rot.begin() + 9 * std::ptrdiff_t(m_carry[k]));
    for (const SlidingSet& sl : m_sliding)
      for (size_t k = 0; k < sl.carry.size(); ++k)
        std::copy_n(sl.rot.begin() + 9 * std::ptrdiff_t(k), 9,
                    m_rot.begin() + 9 * std::ptrdiff_t(sl.carry[k]));
    for (int i : m_fixedList)  // held spheres do not turn
      for (int q = 0; q < 9; ++q) m_rot[9 * size_t(i) + size_t(q)] = (q % 4 == 0) ? 1.0 : 0.0;
  }
  const double tRot = msSince(ts);
  ts = Clock::now();
  const bool skinRot = m_skinFrame == Frame::Rotated;
  packSphereFrames(m_x, m_r, skinRot ? m_rot.data() : nullptr, m_frames);
  applySkinningFrames(m_skin, m_frames.data(), skinRot, m_surface, m_simd);
  correctHeldAfterSkinning(dt);
  // The skinned surface can bulge past the spheres: keep it out of the instruments too (display
  // level, no force: the spheres carried it).
  if (in.contact) {
    ContactProxy surface;
    surface.nodes = &m_surface;
    respondToContact(*in.contact, surface, ContactResponse::Display, dt);
  }
  const double tSkin = msSince(ts);

  m_phases = {tStretch, tLap, tVol, tRot, tSkin};
  if (!m_x.allFinite() || !m_surface.allFinite() || !m_r.allFinite()) return StepStatus::Diverged;
  return StepStatus::Ok;
}

void MetaballsModel::computeGraspForces(const StepInput& in, Real dt) {
  m_graspForces.assign(in.grasps.size(), Vec3::Zero());
  if (in.grasps.empty()) return;
  const int n = m_mb.spheres.size();
  if (m_heldForce.rows() != n) m_heldForce.setZero(n, 3);
  m_heldList.assign(m_carry.begin(), m_carry.end());
  if (m_graspVerts.empty()) m_heldList.clear();
  for (const SlidingSet& sl : m_sliding)
    m_heldList.insert(m_heldList.end(), sl.carry.begin(), sl.carry.end());
  if (m_heldList.empty()) return;
  std::vector<uint8_t> held(size_t(n), 0);
  for (int i : m_heldList) held[size_t(i)] = 1;
  const Real invDt2 = 1.0 / (dt * dt);
  // Links: lambda pushes a along (c_a - c_b) / |c_a - c_b| and b the other way.
  for (int j = 0; j < m_batches.size(); ++j) {
    if (m_batches.link[size_t(j)] < 0) continue;
    const int a = m_batches.a[size_t(j)], b = m_batches.b[size_t(j)];
    if (!held[size_t(a)] && !held[size_t(b)]) continue;
    const Vec3 d = (m_x.row(a) - m_x.row(b)).transpose();
    const Real len = d.norm();
    if (len <= 1e-12) continue;
    const Vec3 f = (m_sdata.lambda[size_t(j)] * invDt2 / len) * d;
    if (held[size_t(a)]) m_heldForce.row(a) += f.transpose();
    if (held[size_t(b)]) m_heldForce.row(b) -= f.transpose();
  }
  // Laplacian constraints: lambda_m pushes m by +1 and each of its n neighbours by -1/n.
  if (m_laplacian)
    for (int i : m_heldList) {
      const auto lam = [&](int m) {
        return Vec3(m_ldata.lambda[4 * size_t(m)], m_ldata.lambda[4 * size_t(m) + 1],
                    m_ldata.lambda[4 * size_t(m) + 2]);
      };
      Vec3 f = m_ldata.W[size_t(i)] > 0 ? lam(i) : Vec3::Zero();
      for (int k = m_adjStart[size_t(i)]; k < m_adjStart[size_t(i) + 1]; ++k) {
        const int m = m_adj[size_t(k)];
        const int cnt = m_adjStart[size_t(m) + 1] - m_adjStart[size_t(m)];
        if (m_ldata.W[size_t(m)] > 0 && cnt > 0) f -= lam(m) / Real(cnt);
      }
      m_heldForce.row(i) += (invDt2 * f).transpose();
    }
  // Bonded grasps: each carrying sphere's force shared by its skinning weight on each grasp's
  // vertices. Sliding plates: the axis component of their carrying spheres' forces.
  const int K = m_skin.slots;
  std::vector<std::vector<Real>> share(in.grasps.size());
  std::vector<Real> total(m_carry.size(), 0.0);
  size_t slide = 0;
  for (size_t g = 0; g < in.grasps.size(); ++g) {
    const GraspInput& gr = in.grasps[g];
    if (gr.sliding()) {
      if (slide >= m_sliding.size()) continue;
      const SlidingSet& sl = m_sliding[slide++];
      if (sl.axis < 0) continue;
      for (int i : sl.carry) m_graspForces[g][sl.axis] += m_heldForce(i, sl.axis);
      continue;
    }
    if (m_graspVerts.empty()) continue;
    share[g].assign(m_carry.size(), 0.0);
    for (int v : gr.vertices) {
      if (v < 0 || v >= m_skin.numVertices) continue;
      for (int k = 0; k < m_skin.count[size_t(v)]; ++k) {
        const size_t slot = size_t(v) * size_t(K) + size_t(k);
        const auto it = std::lower_bound(m_carry.begin(), m_carry.end(), m_skin.sphere[slot]);
        if (it != m_carry.end() && *it == m_skin.sphere[slot]) {
          share[g][size_t(it - m_carry.begin())] += m_skin.weight[slot];
          total[size_t(it - m_carry.begin())] += m_skin.weight[slot];
        }
      }
    }
  }
  for (size_t g = 0; g < in.grasps.size(); ++g)
    for (size_t k = 0; k < share[g].size(); ++k)
      if (total[k] > 0)
        m_graspForces[g] += (share[g][k] / total[k]) * m_heldForce.row(m_carry[k]).transpose();

  for (int i : m_heldList) m_heldForce.row(i).setZero();
}

Counts MetaballsModel::counts() const {
  const long long s = m_mb.spheres.size(), l = m_mb.topology.links.rows();
  return {{"spheres", s},
          {"nodes", s},
          {"links", l},
          {"constraints", l + (m_laplacian ? s : 0)},
          {"surface_vertices", m_skin.numVertices},
          {"fixed_spheres", static_cast<long long>(m_fixedList.size())},
          // The harness's fixed_nodes (and its "holds nothing" validity rule) takes this count:
          // the spheres this model pins by its own rule, not only those whose centres lie in
          // the region.
          {"fixed_nodes", static_cast<long long>(m_fixedList.size())}};
}

NumericCounters MetaballsModel::numericCounters() const {
  const ConstructionReport& r = m_mb.report;
  NumericCounters c;
  c["degenerate_constraints"] = m_degenerate;
  c["skinning_fallback_vertices"] = m_skin.fallbacks;
  c["construction_cache_hit"] = m_cacheHit ? 1 : 0;
  c["medial_candidates"] = r.medialCandidates;
  c["packed_spheres"] = r.packedSpheres;
  c["degenerate_delaunay_tets"] = r.degenerateTets;
  c["spheres_outside_before_adjustment"] = r.outsideBeforeAdjustment;
  c["spheres_outside_after_adjustment"] = r.outsideAfterAdjustment;
  c["spheres_outside_after_optimisation"] = r.outsideAfterOptimisation;
  c["spheres_removed_by_adjustment"] = r.removedByAdjustment;
  c["spheres_filled"] = r.filledSpheres;
  c["sphere_pairs_merged"] = r.mergedPairs;
  c["inside_voxels"] = r.insideVoxels;
  c["hollow_voxels_before_optimisation"] = r.hollowBefore;
  c["hollow_voxels_after_optimisation"] = r.hollowAfter;
  c["optimisation_moves"] = r.optimisationMoves;
  c["bridge_links"] = r.bridges;
  const char* stages[6] = {"packing", "radius_adjustment", "filling",
                           "merging", "optimisation",      "topology"};
  for (int i = 0; i < 6; ++i)
    c[std::string("construction_us_") + stages[i]] = (long long)std::llround(r.seconds[i] * 1e6);
  return c;
}

void MetaballsModel::bindMarkers(const MatX3& rest) {
  m_markerSkin = buildSkinning(rest, m_mb.spheres, m_skinThreshold, m_skinMaxSpheres);
}

MatX3 MetaballsModel::markers() const {
  // The current frames (the grasp correction may have moved spheres since the step packed them).
  const bool rotate = m_skinFrame == Frame::Rotated;
  std::vector<Real> frames(size_t(m_x.rows()) * kFrameStride, 0);
  packSphereFrames(m_x, m_r, rotate ? m_rot.data() : nullptr, frames);
  MatX3 out(Eigen::Index(m_markerSkin.numVertices), 3);
  applySkinningFrames(m_markerSkin, frames.data(), rotate, out, false);
  return out;
}

}  // namespace deform::metaballs
