#include "pbd_model.h"

#include <deform/geometry/surface_mass.h>
#include <deform/geometry/tet_nodes.h>

#include <deform/geometry/tet_mesher.h>
#include <deform/sdk/contact.h>
#include <deform/sdk/mesh.h>

#include <algorithm>
#include <array>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>

namespace deform::pbd {

Real surfaceEdgeCompliance(Real young, Real thickness, Real restLength, Real adjacentArea) {
  return restLength * restLength / (young * thickness * adjacentArea);
}

Real hingeCompliance(const Material& m, Real thickness, Real edgeLength, Real adjacentArea) {
  const Real D =
      m.young * thickness * thickness * thickness / (12.0 * (1.0 - m.poisson * m.poisson));
  return adjacentArea / (3.0 * D * edgeLength * edgeLength);
}

Real bulkModulus(const Material& m) {
  const Real d = 3.0 * (1.0 - 2.0 * m.poisson);
  return d > 0 ? m.young / d : std::numeric_limits<Real>::infinity();
}

namespace {

void checkMaterial(const Organ& organ) {
  const Material& m = organ.material;
  if (!(m.young > 0) || !(m.density > 0) || !(m.poisson > -1.0 && m.poisson <= 0.5))
    throw InputError(organ.source, "organ.material",
                     "pbd needs young > 0, density > 0 and poisson in (-1, 0.5]");
}

// Greedy colouring of constraints (each a set of node indices) so that consecutive constraints
// rarely share a node: the Gauss-Seidel order stays fixed and deterministic, but the CPU can
// overlap independent projections instead of waiting on a chain through one vertex.
template <class C, class NodesOf>
std::vector<size_t> orderByColour(std::vector<C>& cs, int numNodes, NodesOf nodesOf) {
  std::vector<std::uint64_t> used(numNodes, 0);
  std::vector<std::pair<int, int>> key(cs.size());
  for (size_t i = 0; i < cs.size(); ++i) {
    std::uint64_t mask = 0;
    for (int n : nodesOf(cs[i])) mask |= used[n];
    const int colour = (~mask == 0) ? 63 : std::countr_zero(~mask);
    for (int n : nodesOf(cs[i])) used[n] |= std::uint64_t(1) << colour;
    key[i] = {colour, static_cast<int>(i)};
  }
  std::sort(key.begin(), key.end());
  std::vector<C> out;
  std::vector<size_t> starts;
  out.reserve(cs.size());
  for (size_t i = 0; i < key.size(); ++i) {
    if (i == 0 || key[i].first != key[i - 1].first) starts.push_back(i);
    out.push_back(cs[key[i].second]);
  }
  starts.push_back(cs.size());
  cs.swap(out);
  return starts;
}

/// One Gauss-Seidel pass over four-particle constraints on positions p: project(c, x, w, lambda,
/// dx) on each one's gathered positions and inverse masses (W, per particle), and dx added back;
/// a constraint it reports degenerate (false) moves nothing. Returns the degenerate count.
template <class Constraint, class Project>
long long projectFourPoint(const std::vector<Constraint>& constraints, const Real* W,
                           std::vector<Real>& lambda, MatX3& p, Project&& project) {
  long long degenerate = 0;
  for (size_t i = 0; i < constraints.size(); ++i) {
    const Constraint& c = constraints[i];
    Vec3 x[4], dx[4];
    Real w[4];
    for (int k = 0; k < 4; ++k) {
      x[k] = p.row(c.p[k]);
      w[k] = W[c.p[k]];
    }
    if (!project(c, x, w, lambda[i], dx)) {
      ++degenerate;
      continue;
    }
    for (int k = 0; k < 4; ++k) p.row(c.p[k]) += dx[k];
  }
  return degenerate;
}

}  // namespace

void PbdModel::init(const ModelSetup& setup) {
  const PbdConfig config = configFromParams(setup.params);
  if (!config.volumeNetwork || setup.organ.volume) return init(setup.organ, config);
  Organ organ = setup.organ;
  organ.volume =
      surfaceVolumeCached(organ.surface, config.volumeElements, organ.source, setup.cache);
  init(organ, config);
}

void PbdModel::init(const Organ& organ, const PbdConfig& config) {
  checkMaterial(organ);
  m_config = config;
  const int n = m_config.iterations;
  const bool classic = m_config.mode == StiffnessMode::Classic;
  m_kStretch = classic ? classicStiffness(m_config.stretchStiffness, n) : 1.0;
  m_kBend = classic ? classicStiffness(m_config.bendingStiffness, n) : 1.0;
  m_kVolume = classic ? classicStiffness(m_config.volumeStiffness, n) : 1.0;
  m_distance.clear();
  m_degenerateAtInit = 0;
  m_dihedral.clear();
  m_iso.clear();
  m_tet.clear();
  m_tets.resize(0, 4);
  m_surfaceRows.clear();  // a surface network keeps it empty (vertex i is node i)
  m_hasVolume = false;

  if (organ.volume) {
    buildTets(organ);
  } else {
    buildSurface(organ);
  }
  const int N = static_cast<int>(m_rest.rows());
  m_contactF = facesOnNodes(organ.surface.F, m_surfaceRows);

  // Colour 63 collects every constraint once 63 colours are used: it is not independent, so it
  // is projected one by one (see projectAll()).
  m_distColours = orderByColour(m_distance, N, [](const DistanceConstraint& c) {
    return std::array{c.a, c.b};
  });
  orderByColour(m_dihedral, N, [](const DihedralConstraint& c) {
    return std::array{c.p[0], c.p[1], c.p[2], c.p[3]};
  });
  m_isoColours = orderByColour(m_iso, N, [](const IsometricHinge& c) {
    return std::array{c.p[0], c.p[1], c.p[2], c.p[3]};
  });
  m_tetColours = orderByColour(m_tet, N, [](const TetVolumeConstraint& c) {
    return std::array{c.p[0], c.p[1], c.p[2], c.p[3]};
  });

  // Immovable nodes: the fixed region, and nodes without mass (unreferenced tet nodes).
  m_fixed.clear();
  if (!organ.fixed.empty()) m_fixed = fixedNodeIndices(m_rest, organ.fixed, organ.surface);
  m_w0 = inverseMasses(m_mass, m_fixed);

  const Box box = boundingBox(m_rest);
  m_boxCenter = box.center();
  m_boxHalf = 0.5 * tol::kDivergenceBoxFactor * std::max(box.size().maxCoeff(), Real(1e-9));

  m_lambdaDist.assign(m_distance.size(), 0.0);
  m_lambdaBend.assign(m_dihedral.size(), 0.0);
  m_distA.resize(m_distance.size());
  m_distB.resize(m_distance.size());
  m_distRest.resize(m_distance.size());
  for (size_t i = 0; i < m_distance.size(); ++i) {
    m_distA[i] = m_distance[i].a;
    m_distB[i] = m_distance[i].b;
    m_distRest[i] = m_distance[i].rest;
  }
  m_distAlphaTilde.resize(m_distance.size());
  m_distScale.resize(m_distance.size());
  m_distWa.resize(m_distance.size());
  m_distWb.resize(m_distance.size());
  m_p4Storage.assign(4 * static_cast<size_t>(N) + 4, 0.0);
  const auto base = reinterpret_cast<std::uintptr_t>(m_p4Storage.data());
  m_p4Offset = ((32 - base % 32) % 32) / sizeof(Real);
  m_graspMask.assign(N, 0);

  m_f32 = m_config.precision == Precision::Float32;
  m_p4fStorage.clear();
  m_distRestF.clear();
  if (m_f32) {
    m_p4fStorage.assign(4 * static_cast<size_t>(N) + 4, 0.0f);
    const auto fbase = reinterpret_cast<std::uintptr_t>(m_p4fStorage.data());
    m_p4fOffset = ((16 - fbase % 16) % 16) / sizeof(float);
    m_p = m_rest;
    packPositions();
    const float* x = p4f();
    m_distA4.resize(m_distance.size());
    m_distB4.resize(m_distance.size());
    m_distRestF.resize(m_distance.size());
    for (size_t i = 0; i < m_distance.size(); ++i) {
      m_distA4[i] = 4 * m_distA[i];
      m_distB4[i] = 4 * m_distB[i];
    }
    // Measured colour by colour like projectAll() projects them (same arithmetic, see
    // distanceLengthsColourF), so that the rest state is exactly at rest.
    forEachIndependentRun(m_distColours, [&](size_t i, size_t e) {
      distanceLengthsColourF(x, m_distA4.data(), m_distB4.data(), i, e, m_distRestF.data());
    });
    if (m_hasVolume) m_restVolumeF = surfaceVolumePaddedF(x, N, m_surfaceF);
    m_distAlphaTildeF.resize(m_distance.size());
    m_distScaleF.resize(m_distance.size());
    m_distWaF.resize(m_distance.size());
    m_distWbF.resize(m_distance.size());
  }
  initIsometric();
  initTets();
  reset();
}

void PbdModel::buildSurface(const Organ& organ) {
  const SurfaceMesh& S = organ.surface;
  const int N = S.numVertices();
  if (N == 0 || S.numFaces() == 0)
    throw InputError(organ.source, "organ.surface", "pbd needs a non-empty triangle surface");
  m_rest = S.V;
  m_surfaceIdentity = true;
  m_surfaceF = S.F;
  m_elements = S.numFaces();
  const Material& mat = organ.material;
  const bool xpbd = m_config.mode == StiffnessMode::Xpbd;

  // Mass: the enclosed volume's mass, distributed by vertex area (a third of each triangle).
  const LumpedSurface lumped = lumpSurface(S, mat.density, m_config.thickness);
  const VecX& faceArea = lumped.faceArea;
  const MatX2i& E = lumped.edges;
  const MatX2i& EF = lumped.edgeFaces;
  m_mass = lumped.mass;

  for (Eigen::Index e = 0; e < E.rows(); ++e) {
    DistanceConstraint c;
    c.a = E(e, 0);
    c.b = E(e, 1);
    c.rest = (S.V.row(c.a) - S.V.row(c.b)).norm();
    c.compliance =
        xpbd ? surfaceEdgeCompliance(mat.young, m_config.thickness, c.rest, lumped.edgeArea(e))
             : 0.0;
    m_distance.push_back(c);
  }

  if (m_config.bending) {
    for (Eigen::Index e = 0; e < E.rows(); ++e) {
      const int f0 = EF(e, 0), f1 = EF(e, 1);
      if (f0 < 0 || f1 < 0) continue;
      // Orient the hinge so that x2 -> x3 runs along triangle f0: f0 = (x0, x2, x3) in cyclic
      // order, and f1 = (x1, x3, x2).
      int k = 0;
      while (!(S.F(f0, k) != E(e, 0) && S.F(f0, k) != E(e, 1))) ++k;
      DihedralConstraint c;
      c.p[0] = S.F(f0, k);
      c.p[2] = S.F(f0, (k + 1) % 3);
      c.p[3] = S.F(f0, (k + 2) % 3);
      int j = 0;
      while (!(S.F(f1, j) != E(e, 0) && S.F(f1, j) != E(e, 1))) ++j;
      c.p[1] = S.F(f1, j);
      Vec3 x[4], g[4];
      for (int i = 0; i < 4; ++i) x[i] = S.V.row(c.p[i]);
      if (m_config.bendingModel == BendingModel::Isometric) {
        IsometricHinge h;
        for (int i = 0; i < 4; ++i) h.p[i] = c.p[i];
        if (!isometricHinge(x, h)) {
          ++m_degenerateAtInit;
          continue;
        }
        h.compliance = xpbd ? isometricHingeCompliance(mat.young, mat.poisson, m_config.thickness,
                                                       faceArea[f0] + faceArea[f1])
                            : 0.0;
        m_iso.push_back(h);
        continue;
      }
      Real theta = 0;
      if (!dihedralAngle(x[0], x[1], x[2], x[3], theta, g)) {
        ++m_degenerateAtInit;
        continue;
      }
      c.restAngle = theta;
      const Real elen = (x[3] - x[2]).norm();
      c.compliance =
          xpbd ? hingeCompliance(mat, m_config.thickness, elen, faceArea[f0] + faceArea[f1]) : 0.0;
      m_dihedral.push_back(c);
    }
  }

  if (m_config.volume && lumped.closed) {
    m_hasVolume = true;
    m_restVolume = signedVolume(S.V, S.F);
    const Real K = bulkModulus(mat);
    // C = V - V0 with energy (K / 2) (dV / V0)^2 V0, so alpha = V0 / K.
    m_volumeCompliance = xpbd ? std::abs(m_restVolume) / K : 0.0;
  }
}

void PbdModel::buildTets(const Organ& organ) {
  const TetMesh& T = *organ.volume;
  m_tets = T.T;
  const int N = T.numVertices();
  if (N == 0 || T.numTets() == 0)
    throw InputError(organ.source, "organ.volume", "pbd needs a non-empty tetrahedral mesh");
  m_rest = T.V;
  m_elements = T.numTets();
  m_surfaceF.resize(0, 3);
  const Material& mat = organ.material;
  const bool xpbd = m_config.mode == StiffnessMode::Xpbd;

  // Surface vertices -> nodes: the identity when the surface shares the volume's node list,
  // otherwise the node at the same position.
  const SurfaceMesh& S = organ.surface;
  m_surfaceIdentity = S.numVertices() == N && S.V == T.V;
  m_surfaceRows.clear();
  if (!m_surfaceIdentity) m_surfaceRows = surfaceVertexNodes(organ, T.V);

  const TetMeasures tm = measureTets(T, mat.density, organ.source);
  m_mass = tm.nodeMass;
  const Real K = bulkModulus(mat);
  const Real G = mat.young / (2.0 * (1.0 + mat.poisson));
  // Edge springs k = gamma sum V_T / L^2 with gamma = 5G/2 give an isotropic network with shear
  // modulus G and bulk modulus 5G/3; the tet volume constraints add the missing K - 5G/3 (Golec
  // et al. 2019). Below nu = 1/4 that would be negative: clamp to zero (nu_eff = 1/4).
  const Real gamma = 2.5 * G;
  const Real extraK = std::max<Real>(K - 5.0 * G / 3.0, 0.0);
  if (extraK > 0 || !xpbd) {
    for (int t = 0; t < T.numTets(); ++t) {
      TetVolumeConstraint c;
      for (int i = 0; i < 4; ++i) c.p[i] = T.T(t, i);
      c.restVolume = tm.tetVolume[t];
      c.compliance = xpbd ? (std::isinf(extraK) ? 0.0 : c.restVolume / extraK) : 0.0;
      m_tet.push_back(c);
    }
  }
  for (Eigen::Index e = 0; e < tm.edges.rows(); ++e) {
    DistanceConstraint c;
    c.a = tm.edges(e, 0);
    c.b = tm.edges(e, 1);
    c.rest = (T.V.row(c.a) - T.V.row(c.b)).norm();
    c.compliance = xpbd ? c.rest * c.rest / (gamma * tm.edgeVolume[e]) : 0.0;
    m_distance.push_back(c);
  }
}

void PbdModel::reset() {
  m_x = m_rest;
  m_v.setZero(m_rest.rows(), 3);
  m_p = m_rest;
  m_w = m_w0;
  m_hotDt = -1;
  m_hotGrasped.clear();
  m_hotSliding.clear();
  m_sliding.clear();
  std::fill(m_graspMask.begin(), m_graspMask.end(), 0);
  m_lambdaVolume = 0;
  m_volumeGrad4.assign(4 * static_cast<size_t>(m_rest.rows()), 0.0);
  m_volumeGrad4F.assign(m_f32 ? 4 * static_cast<size_t>(m_rest.rows()) : 0, 0.0f);
  m_degenerate = 0;
  m_graspForces.clear();
  m_phase.clear();
  if (!m_surfaceIdentity) {
    m_surface.resize(static_cast<Eigen::Index>(m_surfaceRows.size()), 3);
    for (size_t i = 0; i < m_surfaceRows.size(); ++i) m_surface.row(i) = m_x.row(m_surfaceRows[i]);
  }
}

void PbdModel::refreshHotData(Real dt) {
  const Real invDt2 = 1.0 / (dt * dt);
  for (size_t i = 0; i < m_distance.size(); ++i) {
    const DistanceConstraint& c = m_distance[i];
    m_distAlphaTilde[i] = c.compliance * invDt2;
    const Real denom = m_w[c.a] + m_w[c.b] + m_distAlphaTilde[i];
    m_distScale[i] = denom > 0 ? m_kStretch / denom : 0.0;
    m_distWa[i] = m_w[c.a];
    m_distWb[i] = m_w[c.b];
  }
  if (m_f32) {
    for (size_t i = 0; i < m_distance.size(); ++i) {
      m_distAlphaTildeF[i] = static_cast<float>(m_distAlphaTilde[i]);
      m_distScaleF[i] = static_cast<float>(m_distScale[i]);
      m_distWaF[i] = static_cast<float>(m_distWa[i]);
      m_distWbF[i] = static_cast<float>(m_distWb[i]);
    }
  }
  refreshIsometricHotData(dt);
  refreshTetHotData(dt);
  m_hotDt = dt;
}

void PbdModel::packPositions() {
  const Real* P = m_p.data();
  const Eigen::Index n = m_p.rows();
  if (m_f32) {
    float* x = p4f();
    const Real c[3] = {m_boxCenter[0], m_boxCenter[1], m_boxCenter[2]};
    for (Eigen::Index i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) x[4 * i + k] = static_cast<float>(P[3 * i + k] - c[k]);
    return;
  }
  Real* m_p4 = p4();
  for (Eigen::Index i = 0; i < n; ++i) {
    m_p4[4 * i] = P[3 * i];
    m_p4[4 * i + 1] = P[3 * i + 1];
    m_p4[4 * i + 2] = P[3 * i + 2];
  }
}

void PbdModel::unpackPositions() {
  Real* P = m_p.data();
  const Eigen::Index n = m_p.rows();
  if (m_f32) {
    // Only the float solver's change is added: P += (x - x0) with x0 = float(P - c) as packed
    // (recomputed here rather than stored). A particle the solver did not move (fixed, grasped,
    // or at rest) keeps its double position bit for bit, and the rounding to float does not
    // accumulate from step to step.
    const float* x = p4f();
    const Real c[3] = {m_boxCenter[0], m_boxCenter[1], m_boxCenter[2]};
    for (Eigen::Index i = 0; i < n; ++i)
      for (int k = 0; k < 3; ++k) {
        const float x0 = static_cast<float>(P[3 * i + k] - c[k]);
        P[3 * i + k] += static_cast<Real>(x[4 * i + k] - x0);
      }
    return;
  }
  const Real* m_p4 = p4();
  for (Eigen::Index i = 0; i < n; ++i) {
    P[3 * i] = m_p4[4 * i];
    P[3 * i + 1] = m_p4[4 * i + 1];
    P[3 * i + 2] = m_p4[4 * i + 2];
  }
}

void PbdModel::projectVolume(Real dt) {
  const Real at = m_volumeCompliance / (dt * dt);
  const bool ok =
      m_f32 ? projectSurfaceVolumePaddedF(p4f(), m_p.rows(), m_w.data(), m_surfaceF, m_restVolumeF,
                                          at, m_kVolume, m_lambdaVolume, m_volumeGrad4F.data())
            : projectSurfaceVolumePadded(p4(), m_p.rows(), m_w.data(), m_surfaceF, m_restVolume, at,
                                         m_kVolume, m_lambdaVolume, m_volumeGrad4.data());
  if (!ok) ++m_degenerate;
}

Vec3 PbdModel::volumeGradient(int node) const {
  const size_t i = 4 * static_cast<size_t>(node);
  if (m_f32) return Vec3(m_volumeGrad4F[i], m_volumeGrad4F[i + 1], m_volumeGrad4F[i + 2]);
  return Vec3(m_volumeGrad4[i], m_volumeGrad4[i + 1], m_volumeGrad4[i + 2]);
}

void PbdModel::projectAll(Real dt) {
  const Real invDt2 = 1.0 / (dt * dt);
  const Real* W = m_w.data();
  const DistanceBatch batch{m_distA.data(),          m_distB.data(),     m_distRest.data(),
                            m_distAlphaTilde.data(), m_distScale.data(), m_lambdaDist.data(),
                            m_distWa.data(),         m_distWb.data()};
  const DistanceBatchF batchF{m_distA4.data(),          m_distB4.data(),     m_distRestF.data(),
                              m_distAlphaTildeF.data(), m_distScaleF.data(), m_lambdaDistF.data(),
                              m_distWaF.data(),         m_distWbF.data()};
  Real* x4 = p4();
  float* x4f = p4f();
  const auto project = [&](size_t b, size_t e) {
    return m_f32 ? projectDistanceColourPaddedF(x4f, batchF, b, e)
                 : projectDistanceColourPadded(x4, batch, b, e);
  };
  bool packed = false;
  if (m_f32)
    std::fill(m_lambdaIsoF.begin(), m_lambdaIsoF.end(), 0.0f);
  else
    std::fill(m_lambdaIso.begin(), m_lambdaIso.end(), 0.0);
  for (int it = 0; it < m_config.iterations; ++it) {
    if (!packed) packPositions();
    packed = true;
    forEachIndependentRun(m_distColours,
                          [&](size_t i, size_t e) { m_degenerate += project(i, e); });
    if (!m_iso.empty()) projectIsometric();
    const bool volumeNow =
        m_hasVolume && (m_config.volumeEverySweep || it + 1 == m_config.iterations);
    if (!m_dihedral.empty()) {
      unpackPositions();
      m_degenerate += projectFourPoint(
          m_dihedral, W, m_lambdaBend, m_p,
          [&](const DihedralConstraint& c, const Vec3* x, const Real* w, Real& lambda, Vec3* dx) {
            return projectDihedral(x, w, c.restAngle, c.compliance * invDt2, m_kBend, lambda, dx);
          });
      packed = false;
    }
    if (!m_tet.empty()) {
      if (!packed) packPositions();
      packed = true;
      projectTets();
    }
    if (volumeNow) {
      if (!packed) packPositions();
      packed = true;
      projectVolume(dt);
    }
    holdSliding(packed);
  }
  if (packed) unpackPositions();
}

void PbdModel::holdSliding(bool packed) {
  if (m_sliding.empty()) return;
  if (!packed) {
    for (const SlidingHold& h : m_sliding) {
      const Vec3 p = m_p.row(h.node).transpose();
      m_p.row(h.node) = (p - (h.normal.dot(p) - h.offset) * h.normal).transpose();
    }
    return;
  }
  if (m_f32) {  // packed relative to the box centre, in float
    float* x = p4f();
    for (const SlidingHold& h : m_sliding) {
      const Real d = h.offset - h.normal.dot(m_boxCenter);
      float* q = x + 4 * size_t(h.node);
      const Real miss = h.normal.x() * q[0] + h.normal.y() * q[1] + h.normal.z() * q[2] - d;
      for (int k = 0; k < 3; ++k) q[k] = static_cast<float>(q[k] - miss * h.normal[k]);
    }
    return;
  }
  Real* x = p4();
  for (const SlidingHold& h : m_sliding) {
    Real* q = x + 4 * size_t(h.node);
    const Real miss = h.normal.x() * q[0] + h.normal.y() * q[1] + h.normal.z() * q[2] - h.offset;
    for (int k = 0; k < 3; ++k) q[k] -= miss * h.normal[k];
  }
}

StepStatus PbdModel::step(const StepInput& in) {
  using Clock = std::chrono::steady_clock;
  const auto t0 = Clock::now();
  const Real dt = in.dt;
  const int N = static_cast<int>(m_x.rows());

  // Grasped surface vertices are particles (J a selection): kinematic this step, inverse mass 0,
  // position = target.
  // Sliding plates hold their particles on the plate's plane only: those stay free (inverse
  // mass kept) and are projected back onto the plane after every iteration (holdSliding); the
  // constraints touching them are listed with the grasped ones for the plate's force.
  graspsOnNodes(in.grasps, m_surfaceRows, m_nodeGrasps);
  std::vector<int>& grasped = m_graspedScratch;
  grasped.clear();
  m_sliding.clear();
  for (const NodeGrasp& g : m_nodeGrasps)
    if (!g.sliding()) grasped.insert(grasped.end(), g.nodes.begin(), g.nodes.end());
  std::sort(grasped.begin(), grasped.end());
  grasped.erase(std::unique(grasped.begin(), grasped.end()), grasped.end());
  std::vector<int>& sliding = m_slidingScratch;
  sliding.clear();
  for (const NodeGrasp& g : m_nodeGrasps) {
    if (!g.sliding()) continue;
    const Vec3 n = g.slideNormal.normalized();
    for (size_t k = 0; k < g.nodes.size(); ++k) {
      const int i = g.nodes[k];
      if (std::binary_search(grasped.begin(), grasped.end(), i)) continue;
      m_sliding.push_back({i, n, n.dot(g.targets.row(Eigen::Index(k)).transpose())});
      sliding.push_back(i);
    }
  }
  std::sort(sliding.begin(), sliding.end());
  if (grasped != m_hotGrasped || sliding != m_hotSliding || dt != m_hotDt) {
    for (int i : m_hotGrasped) m_graspMask[i] = 0;
    for (int i : m_hotSliding) m_graspMask[i] = 0;
    m_w = m_w0;
    for (int i : grasped) {
      m_w[i] = 0.0;
      m_graspMask[i] = 1;
    }
    for (int i : sliding) m_graspMask[i] = 1;
    m_hotGrasped = grasped;
    m_hotSliding = sliding;
    refreshHotData(dt);
    listGraspConstraints();
  }

  // Prediction with gravity and point loads (explicit in the external forces only).
  m_v.rowwise() += dt * in.gravity.transpose();
  loadsOnNodes(in.loads, m_surfaceRows, m_nodeForces);
  for (const auto& [node, force] : m_nodeForces)
    m_v.row(node) += (dt * m_w[node]) * force.transpose();
  for (int i = 0; i < N; ++i) {
    if (m_w[i] == 0.0) m_v.row(i).setZero();
  }
  m_p = m_x + dt * m_v;
  for (const NodeGrasp& g : m_nodeGrasps)
    if (!g.sliding())
      for (size_t k = 0; k < g.nodes.size(); ++k) m_p.row(g.nodes[k]) = g.targets.row(k);
  holdSliding(false);
  const auto t1 = Clock::now();

  if (m_f32)
    m_lambdaDistF.assign(m_distance.size(), 0.0f);
  else
    std::fill(m_lambdaDist.begin(), m_lambdaDist.end(), 0.0);
  std::fill(m_lambdaBend.begin(), m_lambdaBend.end(), 0.0);
  if (m_f32)
    std::fill(m_lambdaTetF.begin(), m_lambdaTetF.end(), 0.0f);
  else
    std::fill(m_lambdaTet.begin(), m_lambdaTet.end(), 0.0);
  m_lambdaVolume = 0;
  projectAll(dt);
  // Contact last, on the surface triangles, so that no surface point ends the step inside an
  // instrument; the correction (friction included, measured from the step's start m_x) enters
  // the velocity like any other projection (w = 0 for fixed and grasped nodes).
  if (in.contact) {
    const ContactProxy proxy{
        .nodes = &m_p, .invMass = &m_w, .atStepStart = &m_x, .faces = &m_contactF, .embedding = {}};
    respondToContact(*in.contact, proxy, ContactResponse::Project, dt);
  }
  const auto t2 = Clock::now();

  // Velocity update with damping, and the divergence check (NaN/Inf or leaving the box).
  const Real invDt = 1.0 / dt;
  const Real decay = std::exp(-m_config.damping * dt);
  // |p - c| <= half is false for NaN and Inf too, so one flag covers both checks; it is an
  // integer AND, not a floating-point reduction, so the loop vectorises.
  const Real* P = m_p.data();
  Real* X = m_x.data();
  Real* V = m_v.data();
  const Real scale = invDt * decay, half = m_boxHalf;
  const Real c[3] = {m_boxCenter[0], m_boxCenter[1], m_boxCenter[2]};
  int inside = 1;
  for (int i = 0; i < N; ++i) {
    for (int k = 0; k < 3; ++k) {
      const Real p = P[3 * i + k];
      V[3 * i + k] = (p - X[3 * i + k]) * scale;
      X[3 * i + k] = p;
      inside &= static_cast<int>(std::abs(p - c[k]) <= half);
    }
  }
  if (!m_surfaceIdentity)
    for (size_t i = 0; i < m_surfaceRows.size(); ++i) m_surface.row(i) = m_x.row(m_surfaceRows[i]);
  computeGraspForces(in, dt);
  const auto t3 = Clock::now();
  auto ms = [](auto a, auto b) { return std::chrono::duration<double, std::milli>(b - a).count(); };
  m_phase["predict"] = ms(t0, t1);
  m_phase["solve"] = ms(t1, t2);
  m_phase["update"] = ms(t2, t3);
  if (!inside) return StepStatus::Diverged;
  return StepStatus::Ok;
}

void PbdModel::listGraspConstraints() {
  const auto touches = [&](const int* p, int n) {
    for (int k = 0; k < n; ++k)
      if (m_graspMask[p[k]]) return true;
    return false;
  };
  m_graspDist.clear();
  m_graspBend.clear();
  m_graspTet.clear();
  m_graspIso.clear();
  for (size_t i = 0; i < m_iso.size(); ++i)
    if (touches(m_iso[i].p, 4)) m_graspIso.push_back(static_cast<int>(i));
  for (size_t i = 0; i < m_distance.size(); ++i)
    if (m_graspMask[m_distA[i]] | m_graspMask[m_distB[i]])
      m_graspDist.push_back(static_cast<int>(i));
  for (size_t i = 0; i < m_dihedral.size(); ++i)
    if (touches(m_dihedral[i].p, 4)) m_graspBend.push_back(static_cast<int>(i));
  for (size_t i = 0; i < m_tet.size(); ++i)
    if (touches(m_tet[i].p, 4)) m_graspTet.push_back(static_cast<int>(i));
}

// Force the tissue exerts on each grasp: sum over constraints touching grasped nodes of
// g_j lambda / dt^2 (the constraint force of XPBD, Macklin et al. 2016, Eq. (9); in classic mode
// lambda is the same accumulated multiplier, so this is the impulse the free particles received
// divided by dt, with the sign of Newton's third law).
void PbdModel::computeGraspForces(const StepInput& in, Real dt) {
  m_graspForces.assign(in.grasps.size(), Vec3::Zero());
  if (in.grasps.empty()) return;
  // Only the rows of grasped nodes are zeroed, accumulated and read.
  MatX3& nodeForce = m_nodeForce;
  if (nodeForce.rows() != m_x.rows()) nodeForce.setZero(m_x.rows(), 3);
  for (int i : m_hotGrasped) nodeForce.row(i).setZero();
  for (int i : m_hotSliding) nodeForce.row(i).setZero();
  const auto add = [&](int node, const Vec3& f) {
    if (m_graspMask[node]) nodeForce.row(node) += f.transpose();
  };
  const Real invDt2 = 1.0 / (dt * dt);
  for (int i : m_graspDist) {
    const int a = m_distA[i], b = m_distB[i];
    const Vec3 d = m_x.row(a) - m_x.row(b);
    const Real len = d.norm();
    if (len <= tol::kDegenerateLength) continue;
    const Vec3 f = (lambdaDist(i) * invDt2 / len) * d;
    add(a, f);
    add(b, -f);
  }
  for (int i : m_graspBend) {
    const DihedralConstraint& c = m_dihedral[i];
    Vec3 x[4], g[4];
    for (int k = 0; k < 4; ++k) x[k] = m_x.row(c.p[k]);
    Real theta;
    if (!dihedralAngle(x[0], x[1], x[2], x[3], theta, g)) continue;
    for (int k = 0; k < 4; ++k) add(c.p[k], (m_lambdaBend[i] * invDt2) * g[k]);
  }
  for (int i : m_graspTet) {
    const TetVolumeConstraint& c = m_tet[i];
    const Vec3 x0 = m_x.row(c.p[0]);
    const Vec3 e1 = Vec3(m_x.row(c.p[1])) - x0, e2 = Vec3(m_x.row(c.p[2])) - x0,
               e3 = Vec3(m_x.row(c.p[3])) - x0;
    Vec3 g[4];
    g[1] = e2.cross(e3) / 6.0;
    g[2] = e3.cross(e1) / 6.0;
    g[3] = e1.cross(e2) / 6.0;
    g[0] = -(g[1] + g[2] + g[3]);
    for (int k = 0; k < 4; ++k) add(c.p[k], (lambdaTet(i) * invDt2) * g[k]);
  }
  addIsometricGraspForces(invDt2, nodeForce);
  if (m_hasVolume) {
    for (int i : m_hotGrasped)
      nodeForce.row(i) += (m_lambdaVolume * invDt2) * volumeGradient(i).transpose();
    for (int i : m_hotSliding)
      nodeForce.row(i) += (m_lambdaVolume * invDt2) * volumeGradient(i).transpose();
  }
  for (size_t g = 0; g < in.grasps.size(); ++g) {
    for (int node : m_nodeGrasps[g].nodes) m_graspForces[g] += nodeForce.row(node).transpose();
    // A sliding plate takes the normal component only (the tangential is left to the tissue).
    if (m_nodeGrasps[g].sliding()) {
      const Vec3 n = m_nodeGrasps[g].slideNormal.normalized();
      m_graspForces[g] = n * n.dot(m_graspForces[g]);
    }
  }
}

Counts PbdModel::counts() const {
  const long long nVol = m_hasVolume ? 1 : 0;
  return {{"nodes", m_x.rows()},
          {"elements", m_elements},
          {"constraints", static_cast<long long>(m_distance.size() + m_dihedral.size() +
                                                 m_iso.size() + m_tet.size()) +
                              nVol},
          {"distance_constraints", static_cast<long long>(m_distance.size())},
          {"bending_constraints", static_cast<long long>(m_dihedral.size() + m_iso.size())},
          {"volume_constraints", static_cast<long long>(m_tet.size()) + nVol}};
}

NumericCounters PbdModel::numericCounters() const {
  NumericCounters c{{"degenerate_constraints", m_degenerate},
                    {"degenerate_hinges_at_init", m_degenerateAtInit}};
  if (m_tets.rows() > 0) c["inverted_tets"] = invertedTets(m_tets, m_x);
  return c;
}

}  // namespace deform::pbd
