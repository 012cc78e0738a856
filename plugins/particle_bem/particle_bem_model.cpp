#include "particle_bem_model.h"

#include <deform/sdk/contact.h>
#include <deform/sdk/sliding_plate.h>
#include "conforming_surface.h"
#include "distance_field.h"
#include "physics_points.h"
#include "surface_decimation.h"

#include <Eigen/QR>
#include <Eigen/SVD>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <numeric>

namespace deform::particle_bem {

namespace {

constexpr const char* kMatrixVersion = "particle_bem.M/4";  // 4: with the numeric counters

using Clock = std::chrono::steady_clock;
double ms(Clock::time_point a, Clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

/// The wall times (ms) of a step's three phases: phases[k] from t[k] to t[k + 1].
void recordPhases(PhaseTimes& times, const std::array<const char*, 3>& phases,
                  const std::array<Clock::time_point, 4>& t) {
  for (size_t k = 0; k < phases.size(); ++k) times[phases[k]] = ms(t[k], t[k + 1]);
}

// The k (<= 8) rows of P nearest to p, nearest first; unused slots get index -1.
void nearest8(const MatX3& P, const Vec3& p, std::array<int, 8>& idx, std::array<Real, 8>& dist) {
  std::vector<std::pair<Real, int>> d(P.rows());
  for (Eigen::Index j = 0; j < P.rows(); ++j) d[j] = {(P.row(j).transpose() - p).norm(), int(j)};
  const size_t k = std::min<size_t>(8, d.size());
  std::partial_sort(d.begin(), d.begin() + k, d.end());
  for (size_t a = 0; a < 8; ++a) {
    idx[a] = a < k ? d[a].second : -1;
    dist[a] = a < k ? d[a].first : 0;
  }
}

// Damped least-squares inverse of A (m x n): V diag(s / (s^2 + mu)) U^T, mu = 1e-3 s_max^2. For
// the pure model's grasp: its skinning also moves with F_j, so the rows of nearly dependent
// particles would turn small changes of F into large particle motions (as in metaballs).
MatX dampedInverse(const MatX& A) {
  if (A.size() == 0) return MatX(A.cols(), A.rows());
  const Eigen::JacobiSVD<MatX> svd(A, Eigen::ComputeThinU | Eigen::ComputeThinV);
  const VecX& s = svd.singularValues();
  const Real mu = 1e-3 * s(0) * s(0);
  const VecX gain = s.array() / (s.array().square() + mu).max(1e-300);
  return svd.matrixV() * gain.asDiagonal() * svd.matrixU().transpose();
}

// Inverse-distance weights, normalised; a coincident point takes all the weight.
std::array<Real, 8> shepard(const std::array<int, 8>& idx, const std::array<Real, 8>& dist,
                            Real eps) {
  std::array<Real, 8> w{};
  Real sum = 0;
  for (int a = 0; a < 8; ++a) {
    if (idx[a] < 0) continue;
    w[a] = 1 / (dist[a] * dist[a] + eps * eps);
    sum += w[a];
  }
  for (Real& x : w) x /= sum;
  return w;
}

}  // namespace

void ParticleBemModel::init(const ModelSetup& setup) {
  const SurfaceMesh& S = setup.organ.surface;
  m_source = setup.organ.source;
  if (S.numVertices() < 4 || S.numFaces() < 4)
    throw InputError(m_source, "organ.mesh", "particle_bem needs a closed surface");
  const Real volume = signedVolume(S.V, S.F);
  if (!(volume > 0))
    throw InputError(m_source, "organ.mesh",
                     "particle_bem needs a closed, outward-oriented surface (volume <= 0)");
  m_guided = setup.params.flag("guidance");
  m_dt = setup.dt;
  m_material = setup.organ.material;
  m_fineRest = S.V;
  m_numeric.clear();
  const TriangleGrid fineGrid(S.V, S.F);
  const SignedDistanceField sdf(fineGrid, 40, 0.05 * boundingBox(S.V).diagonal());
  m_numeric["distance_field_nodes"] = sdf.nodeCount();
  if (m_guided)
    initGuided(setup, sdf, volume);
  else
    initParticles(setup, sdf, volume);
  m_fixedMask.assign(m_rest.rows(), 0);
  for (int i : m_fixed) m_fixedMask[i] = 1;
  reset();
}

void ParticleBemModel::initGuided(const ModelSetup& setup, const SignedDistanceField& sdf,
                                  Real volume) {
  const SurfaceMesh& S = setup.organ.surface;
  const ParamValues& p = setup.params;
  DecimationStats st;
  const std::vector<Box>& boxes = setup.organ.fixed.boxes;
  const bool conforming = p.flag("conforming_support");
  const bool singular = conforming && p.flag("singular_support");
  if (conforming && !boxes.empty()) {
    ConformStats cs;
    m_coarse = decimateQuadric(conformToBoxes(S, boxes, &cs), int(p.integer("coarse_vertices")),
                               boxes, &st);
    m_numeric["conforming_split_edges"] = cs.splitEdges;
  } else {
    m_coarse = decimateQuadric(S, int(p.integer("coarse_vertices")), &st);
  }
  m_numeric["decimation_refused_collapses"] = st.refusedTopology + st.refusedGeometry;
  const int nc = m_coarse.numVertices();
  const PhysicsPoints interior =
      sampleLatticeInside(sdf, S.V, volume, int(p.integer("points")), 0.5);
  m_spacing = interior.spacing;
  m_rest.resize(nc + interior.points.rows(), 3);
  m_rest.topRows(nc) = m_coarse.V;
  m_rest.bottomRows(interior.points.rows()) = interior.points;
  m_restCoarse = m_coarse.V;
  m_fixed = fixedNodeIndices(m_rest, setup.organ.fixed, S);
  std::vector<int> coarseFixed;
  for (int i : m_fixed)
    if (i < nc) coarseFixed.push_back(i);

  m_loadResponses.clear();
  m_patchTraction = p.choiceAs<PatchTraction>(
      "patch_traction",
      {{"consistent", PatchTraction::Consistent}, {"lumped", PatchTraction::Lumped}});
  m_springK = p.real("spring_stiffness");
  m_springC = p.real("spring_damping");
  m_repulsion = p.flag("repulsion");
  m_bemGravity = p.flag("bem_gravity");
  BemQuadrature quad;
  quad.duffyOrder = int(p.integer("duffy_order"));

  // The cache key names every input of M: the coarse surface, the material, the fixed set and
  // the quadrature.
  CacheKey key;
  key.add(kMatrixVersion).add(m_coarse.V).add(m_coarse.F).add(m_material.young);
  key.add(m_material.poisson).add(m_material.density).add(int(coarseFixed.size()));
  for (int i : coarseFixed) key.add(i);
  key.add(quad.duffyOrder).add(quad.nearFactor).add(quad.maxLevel).add(int(conforming));
  key.add(int(singular));
  bool loaded = false;
  if (auto bytes = setup.cache.get("particle_bem.M", key)) {
    try {
      ByteReader r(*bytes);
      if (r.string() != kMatrixVersion) throw std::runtime_error("version");
      r.matrix(m_bem.M);
      r.matrix(m_bem.gravity);
      m_bem.bordered = r.pod<char>() != 0;
      m_bem.fixed = coarseFixed;
      // The counters the assembly counted: a run that reads M reports what the one that
      // assembled it did.
      NumericCounters counted;
      for (long long i = 0, n = r.pod<long long>(); i < n; ++i) {
        std::string k = r.string();
        counted[k] = r.pod<long long>();
      }
      loaded = r.atEnd() && m_bem.M.rows() == 3 * nc && m_bem.M.cols() == 3 * nc &&
               m_bem.gravity.rows() == 3 * nc;
      if (loaded)
        for (const auto& [k, v] : counted) m_numeric[k] = v;
    } catch (const std::exception&) {
      loaded = false;
    }
    if (!loaded) setup.cache.reject("particle_bem.M", key);
  }
  if (!loaded) {
    BemMatrices bem = assembleBem(m_coarse, m_material.young, m_material.poisson, quad);
    m_numeric["bem_degenerate_triangles"] = bem.degenerateTriangles;
    SupportColumns support;
    if (conforming) {
      support = supportColumns(m_coarse, m_material.young, m_material.poisson, coarseFixed, quad);
      if (singular) {
        const SingularSupport corr =
            singularSupport(m_coarse, m_material.young, m_material.poisson, coarseFixed);
        support = withSingularSupport(support, bem.G, corr);
        addToColumns(bem.G, corr);  // keeps the boundary nodes' free-face part G_j - Gs_j
        m_numeric["singular_support_faces"] = corr.edgeFaces + corr.vertexFaces;
      }
    }
    m_bem = computeDeformationMatrix(
        std::move(bem), m_coarse, vertexNormals(m_coarse.V, m_coarse.F), coarseFixed,
        m_material.young, m_material.poisson, m_material.density, conforming ? &support : nullptr);
    if (!m_bem.M.allFinite())
      throw InputError(m_source, "organ.mesh",
                       "the BEM system of the coarse surface is singular (degenerate surface?)");
    ByteWriter w;
    w.string(kMatrixVersion);
    w.matrix(m_bem.M);
    w.matrix(m_bem.gravity);
    w.pod<char>(m_bem.bordered ? 1 : 0);
    NumericCounters counted;
    for (const char* k : {"bem_degenerate_triangles", "singular_support_faces"})
      if (const auto it = m_numeric.find(k); it != m_numeric.end()) counted[k] = it->second;
    w.pod(static_cast<long long>(counted.size()));
    for (const auto& [k, v] : counted) {
      w.string(k);
      w.pod(v);
    }
    setup.cache.put("particle_bem.M", key, w.bytes());
  }
  m_nodalArea = nodalAreas(m_coarse);
  m_patchProjection = PatchProjection();
  if (m_patchTraction == PatchTraction::Consistent) {
    m_patchProjection = PatchProjection(m_coarse);
    if (!m_patchProjection.ok()) ++m_numeric["singular_mass_matrix"];  // lumped fallback
  }

  const TriangleGrid coarseGrid(m_coarse.V, m_coarse.F);
  m_map = mapToSurface(coarseGrid, S.V);
  m_transfer = p.choiceAs<SurfaceTransfer>(
      "surface_transfer",
      {{"gradient", SurfaceTransfer::Gradient}, {"linear", SurfaceTransfer::Linear}});
  if (m_transfer == SurfaceTransfer::Gradient)
    m_gradient = makeGradientTransfer(m_coarse.V, m_coarse.F, m_map);

  const Real meanEdge = [&] {
    Real sum = 0;
    for (int f = 0; f < m_coarse.numFaces(); ++f)
      for (int k = 0; k < 3; ++k)
        sum +=
            (m_coarse.V.row(m_coarse.F(f, k)) - m_coarse.V.row(m_coarse.F(f, (k + 1) % 3))).norm();
    return sum / (3.0 * m_coarse.numFaces());
  }();
  m_repulsionDistance = 0.5 * meanEdge;
  m_repulsionStiffness = m_material.young * m_repulsionDistance;

  m_interiorNodes.resize(interior.points.rows());
  m_interiorWeights.resize(interior.points.rows());
  for (Eigen::Index q = 0; q < interior.points.rows(); ++q) {
    std::array<Real, 8> dist;
    nearest8(m_coarse.V, interior.points.row(q).transpose(), m_interiorNodes[q], dist);
    m_interiorWeights[q] = shepard(m_interiorNodes[q], dist, 1e-6 * meanEdge);
  }
  m_U.resize(3 * nc);
}

void ParticleBemModel::initParticles(const ModelSetup& setup, const SignedDistanceField& sdf,
                                     Real volume) {
  const SurfaceMesh& S = setup.organ.surface;
  const ParamValues& p = setup.params;
  const PhysicsPoints pts = sampleLatticeInside(sdf, S.V, volume, int(p.integer("points")), 0.0);
  if (pts.points.rows() < 4)
    throw InputError(m_source, "params.points", "fewer than 4 lattice points fit in the organ");
  m_spacing = pts.spacing;
  m_rest = pts.points;
  const int n = int(m_rest.rows());
  const VecX vol = VecX::Constant(n, volume / n);
  m_mass = m_material.density * vol;
  long long degenerate = 0;
  m_mls = initMlsElasticity(m_rest, p.real("kernel_radius") * m_spacing, vol, m_material.young,
                            m_material.poisson, &degenerate);
  m_numeric["degenerate_particles"] = degenerate;
  m_particleDamping = p.real("particle_damping");
  m_fixed = fixedNodeIndices(m_rest, setup.organ.fixed, S);
  m_skinNodes.resize(S.numVertices());
  m_skinWeights.resize(S.numVertices());
  for (int v = 0; v < S.numVertices(); ++v) {
    std::array<Real, 8> dist;
    nearest8(m_rest, S.V.row(v).transpose(), m_skinNodes[v], dist);
    m_skinWeights[v] = shepard(m_skinNodes[v], dist, 1e-6 * m_spacing);
  }
}

void ParticleBemModel::bindMarkers(const MatX3& rest) {
  m_markerRest = rest;
  m_markerNodes.resize(size_t(rest.rows()));
  m_markerWeights.resize(size_t(rest.rows()));
  const Real eps = 1e-6 * std::max<Real>(boundingBox(m_rest).diagonal(), 1e-30);
  for (Eigen::Index q = 0; q < rest.rows(); ++q) {
    std::array<Real, 8> dist;
    nearest8(m_rest, rest.row(q).transpose(), m_markerNodes[size_t(q)], dist);
    m_markerWeights[size_t(q)] = shepard(m_markerNodes[size_t(q)], dist, eps);
  }
}

MatX3 ParticleBemModel::markers() const {
  MatX3 out = m_markerRest;
  for (Eigen::Index q = 0; q < out.rows(); ++q)
    for (int a = 0; a < 8; ++a) {
      const int j = m_markerNodes[size_t(q)][size_t(a)];
      if (j >= 0)
        out.row(q) += m_markerWeights[size_t(q)][size_t(a)] * (m_x.row(j) - m_rest.row(j));
    }
  return out;
}

void ParticleBemModel::reset() {
  m_x = m_rest;
  m_v = MatX3::Zero(m_rest.rows(), 3);
  m_target = m_rest;
  m_surface = m_fineRest;
  m_kinematic = m_fixedMask;
  m_times.clear();
  m_graspSolver = GraspSolver();
  m_F.assign(m_rest.rows(), Mat3::Identity());
  m_verletValid = false;
  m_verlet.clear();
  m_mapVerts.clear();
  m_carry.clear();
  m_carryCol.assign(size_t(m_rest.rows()), -1);
  m_sliding.clear();
  m_graspForces.clear();
  m_slidingMask.assign(size_t(m_rest.rows()), 0);
}

Counts ParticleBemModel::counts() const {
  Counts c;
  c["particles"] = m_x.rows();
  if (m_guided) {
    c["points"] = m_x.rows() - m_coarse.numVertices();
    c["coarse_vertices"] = m_coarse.numVertices();
    c["elements"] = m_coarse.numFaces();
    c["deformation_matrix_bytes"] = (long long)m_bem.bytes();
  } else {
    c["points"] = m_x.rows();
    c["neighbours"] = (long long)m_mls.nbr.size();
  }
  c["fixed"] = (long long)m_fixed.size();
  return c;
}

StepStatus ParticleBemModel::step(const StepInput& in) {
  const StepStatus s = m_guided ? stepGuided(in) : stepParticles(in);
  if (s != StepStatus::Ok) return s;
  return (m_x.allFinite() && m_surface.allFinite()) ? StepStatus::Ok : StepStatus::Diverged;
}

std::vector<std::pair<int, Real>> ParticleBemModel::surfaceRow(int v) const {
  if (m_guided)
    return transferRow(m_map, m_coarse.F,
                       m_transfer == SurfaceTransfer::Gradient ? &m_gradient : nullptr, v);
  std::vector<std::pair<int, Real>> row;
  for (int a = 0; a < 8; ++a)
    if (m_skinNodes[size_t(v)][a] >= 0 && m_skinWeights[size_t(v)][a] != 0)
      row.emplace_back(m_skinNodes[size_t(v)][a], m_skinWeights[size_t(v)][a]);
  std::sort(row.begin(), row.end());
  return row;
}

void ParticleBemModel::prescribeGrasps(const StepInput& in) {
  flattenGrasps(bondedGrasps(in.grasps, m_bondedScratch), m_fineRest.rows(), m_graspVerts,
                m_graspTargets);
  m_bondedChanged = m_graspVerts != m_mapVerts;
  if (m_graspVerts != m_mapVerts) {
    // The grasped set changed (a grasp closed or opened): the carrying set and J_C^+.
    m_mapVerts = m_graspVerts;
    for (int i : m_carry) m_carryCol[size_t(i)] = -1;
    m_carry.clear();
    std::vector<std::vector<std::pair<int, Real>>> rowsJ;
    for (int v : m_graspVerts) {
      rowsJ.push_back(surfaceRow(v));
      for (const auto& [node, w] : rowsJ.back())
        if (!m_fixedMask[size_t(node)]) m_carry.push_back(node);
    }
    std::sort(m_carry.begin(), m_carry.end());
    m_carry.erase(std::unique(m_carry.begin(), m_carry.end()), m_carry.end());
    for (size_t c = 0; c < m_carry.size(); ++c) m_carryCol[size_t(m_carry[c])] = int(c);
    MatX Jc = MatX::Zero(Eigen::Index(m_graspVerts.size()), Eigen::Index(m_carry.size()));
    for (size_t r = 0; r < rowsJ.size(); ++r)
      for (const auto& [node, w] : rowsJ[r])
        if (m_carryCol[size_t(node)] >= 0) Jc(Eigen::Index(r), m_carryCol[size_t(node)]) += w;
    // Guided: the transfer is linear and the targets reachable, the plain pseudo-inverse is
    // exact; pure: damped (see dampedInverse).
    m_JcPinv = m_carry.empty() ? MatX(0, Jc.rows())
               : m_guided ? MatX(Eigen::CompleteOrthogonalDecomposition<MatX>(Jc).pseudoInverse())
                          : dampedInverse(Jc);
  }
  if (m_carry.empty()) return;
  // dx_C = J_C^+ (t - x_s), from the surface at the step's start.
  const Eigen::Index m = Eigen::Index(m_graspVerts.size());
  m_graspGap.resize(m, 3);
  for (Eigen::Index r = 0; r < m; ++r)
    m_graspGap.row(r) = m_graspTargets.row(r) - m_surface.row(m_graspVerts[size_t(r)]);
  m_graspDx.resize(Eigen::Index(m_carry.size()), 3);
  m_graspDx.noalias() = m_JcPinv * m_graspGap;
  m_carryTarget.resize(Eigen::Index(m_carry.size()), 3);
  for (size_t c = 0; c < m_carry.size(); ++c)
    m_carryTarget.row(Eigen::Index(c)) = m_x.row(m_carry[c]) + m_graspDx.row(Eigen::Index(c));
}

void ParticleBemModel::collectGraspForces(const StepInput& in,
                                          const std::function<Vec3(int)>& nodeForce) {
  m_graspForces.assign(in.grasps.size(), Vec3::Zero());
  std::vector<char> counted(size_t(m_x.rows()), 0);
  size_t slidingIndex = 0;
  for (size_t g = 0; g < in.grasps.size(); ++g) {
    const GraspInput& grasp = in.grasps[g];
    Vec3& f = m_graspForces[g];
    if (grasp.sliding()) {
      if (slidingIndex >= m_sliding.size()) continue;
      const SlidingSet& s = m_sliding[slidingIndex++];
      for (int i : s.carry) f(s.axis) += nodeForce(i)(s.axis);
      continue;
    }
    for (int v : grasp.vertices) {
      if (v < 0 || v >= m_fineRest.rows()) continue;
      for (const auto& [node, w] : surfaceRow(v))
        if (m_carryCol[size_t(node)] >= 0 && !counted[size_t(node)]) {
          counted[size_t(node)] = 1;
          f += nodeForce(node);
        }
    }
  }
}

void ParticleBemModel::prescribeSliding(const StepInput& in) {
  size_t count = 0;
  std::vector<int> bonded = m_graspVerts;
  std::sort(bonded.begin(), bonded.end());
  for (const GraspInput& g : in.grasps) {
    if (!g.sliding()) continue;
    const SlidingPick pick = slidingPick(g, m_fineRest.rows(), bonded, "particle_bem");
    const int axis = pick.axis;
    const std::vector<int>& verts = pick.verts;
    if (m_sliding.size() <= count) m_sliding.emplace_back();
    SlidingSet& s = m_sliding[count++];
    if (verts != s.verts || axis != s.axis || m_bondedChanged) {
      s.verts = verts;
      s.axis = axis;
      s.carry.clear();
      std::vector<std::vector<std::pair<int, Real>>> rowsJ;
      for (int v : verts) {
        rowsJ.push_back(surfaceRow(v));
        for (const auto& [node, w] : rowsJ.back())
          if (!m_fixedMask[size_t(node)] && m_carryCol[size_t(node)] < 0) s.carry.push_back(node);
      }
      std::sort(s.carry.begin(), s.carry.end());
      s.carry.erase(std::unique(s.carry.begin(), s.carry.end()), s.carry.end());
      s.col.assign(size_t(m_rest.rows()), -1);
      for (size_t c = 0; c < s.carry.size(); ++c) s.col[size_t(s.carry[c])] = int(c);
      MatX Jc = MatX::Zero(Eigen::Index(verts.size()), Eigen::Index(s.carry.size()));
      for (size_t r = 0; r < rowsJ.size(); ++r)
        for (const auto& [node, w] : rowsJ[r])
          if (s.col[size_t(node)] >= 0) Jc(Eigen::Index(r), s.col[size_t(node)]) += w;
      s.pinv = s.carry.empty() ? MatX(0, Jc.rows())
               : m_guided ? MatX(Eigen::CompleteOrthogonalDecomposition<MatX>(Jc).pseudoInverse())
                          : dampedInverse(Jc);
    }
    s.targets = pick.targets;
    // dx_C,a = J_C^+ (t_a - x_s,a), from the surface at the step's start.
    VecX gap(Eigen::Index(s.verts.size()));
    for (Eigen::Index r = 0; r < gap.size(); ++r)
      gap[r] = s.targets[r] - m_surface(s.verts[size_t(r)], s.axis);
    const VecX dx = s.pinv * gap;
    s.carryStart.resize(Eigen::Index(s.carry.size()));
    for (size_t c = 0; c < s.carry.size(); ++c)
      s.carryStart[Eigen::Index(c)] = m_x(s.carry[c], s.axis);
    s.carryTarget = s.carryStart + dx;
  }
  m_sliding.resize(count);
  m_slidingMask.assign(size_t(m_rest.rows()), 0);
  for (const SlidingSet& s : m_sliding)
    for (int i : s.carry) m_slidingMask[size_t(i)] = 1;
}

void ParticleBemModel::applySliding(const StepInput& in) {
  for (const SlidingSet& s : m_sliding)
    for (size_t c = 0; c < s.carry.size(); ++c) {
      const int i = s.carry[c];
      if (m_guided) {
        m_v.row(i) = (m_target.row(i) - m_x.row(i)) / in.dt;
        m_x.row(i) = m_target.row(i);
      } else {
        m_x(i, s.axis) = s.carryTarget[Eigen::Index(c)];
        m_v(i, s.axis) = (s.carryTarget[Eigen::Index(c)] - s.carryStart[Eigen::Index(c)]) / in.dt;
      }
    }
}

const MatX& ParticleBemModel::loadResponse(const PointLoad& load) {
  std::vector<int> verts = load.vertices;
  std::vector<Real> weights = load.weights;
  if (verts.empty()) {  // a load without a spread acts on its vertex alone
    verts = {load.surfaceVertex};
    weights = {1.0};
  }
  weights.resize(verts.size(), 0.0);
  for (const LoadResponse& r : m_loadResponses)
    if (r.vertices == verts && r.weights == weights) return r.W;
  // Nodal shares of a unit force: J^T w.
  const int nc = m_coarse.numVertices();
  std::vector<std::pair<int, Real>> shares;
  {
    VecX c = VecX::Zero(nc);
    for (size_t k = 0; k < verts.size(); ++k) {
      if (verts[k] < 0 || verts[k] >= m_fineRest.rows()) continue;
      for (const auto& [node, w] : surfaceRow(verts[k])) c[node] += weights[k] * w;
    }
    for (int k = 0; k < nc; ++k)
      if (c[k] != 0) shares.emplace_back(k, c[k]);
  }
  VecX q = VecX::Zero(nc);
  if (m_patchProjection.ok()) {
    q = m_patchProjection.tractionPerForce(shares);
  } else {
    for (const auto& [node, c] : shares) q[node] = c / m_nodalArea[node];
  }
  MatX W = MatX::Zero(3 * nc, 3);
  for (int k = 0; k < nc; ++k)
    if (q[k] != 0 && !m_fixedMask[size_t(k)]) W.noalias() += q[k] * m_bem.M.middleCols(3 * k, 3);
  m_loadResponses.push_back({std::move(verts), std::move(weights), std::move(W)});
  return m_loadResponses.back().W;
}

void ParticleBemModel::applyGrasps(const StepInput& in) {
  for (size_t c = 0; c < m_carry.size(); ++c) {
    const int i = m_carry[c];
    m_v.row(i) = (m_carryTarget.row(Eigen::Index(c)) - m_x.row(i)) / in.dt;
    m_x.row(i) = m_carryTarget.row(Eigen::Index(c));
  }
}

void ParticleBemModel::resolveParticleContacts(const StepInput& in) {
  // Every interior particle is a sphere of half the particle spacing, the guided model's surface
  // particles (the coarse surface's vertices) spheres of the contact thickness; fixed and grasped
  // ones stay. Mass of a particle: its share of the organ (guided particles have none).
  const Eigen::Index n = m_x.rows();
  VecX invMass(n);
  const Real share = m_material.density * m_spacing * m_spacing * m_spacing;
  for (Eigen::Index i = 0; i < n; ++i) {
    const Real m = (!m_guided && i < m_mass.size()) ? m_mass[i] : share;
    invMass[i] = (m_fixedMask[i] || !(m > 0)) ? 0.0 : 1.0 / m;
  }
  for (int i : m_carry) invMass[i] = 0;
  for (const SlidingSet& s : m_sliding)
    for (int i : s.carry) invMass[i] = 0;
  VecX radii = VecX::Constant(n, 0.5 * m_spacing);
  if (m_guided) radii.head(m_coarse.numVertices()).setConstant(in.contact->params().thickness);
  ContactProxy proxy;
  proxy.nodes = &m_x;
  proxy.invMass = &invMass;
  proxy.velocity = m_v.data();
  proxy.radii = &radii;
  respondToContact(*in.contact, proxy, ContactResponse::Project, in.dt);
}

void ParticleBemModel::projectSurfaceOut(const StepInput& in) {
  ContactProxy surface;
  surface.nodes = &m_surface;
  respondToContact(*in.contact, surface, ContactResponse::Display, in.dt);
}

StepStatus ParticleBemModel::stepGuided(const StepInput& in) {
  const auto t0 = Clock::now();
  const int nc = m_coarse.numVertices();
  m_P.clear();
  m_patchU.setZero(3 * nc);  // displacement of the patch loads (their precomputed responses)
  for (const PointLoad& l : in.loads) m_patchU.noalias() += loadResponse(l) * l.force;
  if (m_repulsion) {
    // Surface particles closer than the repulsion distance d that were at least 2d apart at
    // rest (mesh neighbours excluded) push each other apart. Candidate pairs come from a Verlet
    // list: pairs within d + skin (skin = d) found with the spatial hash, rebuilt only when a
    // particle has moved more than skin / 2 since the last build, so no pair closer than d is
    // ever missed.
    const Real skin = m_repulsionDistance;
    Real maxMove2 = 0;
    for (int i = 0; m_verletValid && i < nc && maxMove2 <= 0.25 * skin * skin; ++i)
      maxMove2 = std::max(maxMove2, (m_x.row(i) - m_verletRef.row(i)).squaredNorm());
    if (!m_verletValid || maxMove2 > 0.25 * skin * skin) {
      m_verletRef = m_x.topRows(nc);
      m_hash.setCellSize(m_repulsionDistance + skin);
      m_hash.build(m_verletRef);
      m_pairs.clear();
      m_hash.pairsWithin(m_repulsionDistance + skin, m_pairs);
      m_verlet.clear();
      for (const auto& [i, j] : m_pairs)
        if ((m_restCoarse.row(i) - m_restCoarse.row(j)).norm() >= 2 * m_repulsionDistance)
          m_verlet.emplace_back(i, j);
      m_verletValid = true;
      ++m_numeric["repulsion_list_builds"];
    }
    for (const auto& [i, j] : m_verlet) {
      const Vec3 d = (m_x.row(i) - m_x.row(j)).transpose();
      const Real len = d.norm();
      if (!(len > 0) || len >= m_repulsionDistance) continue;
      const Vec3 f = m_repulsionStiffness * (m_repulsionDistance - len) * d / len;
      if (!m_fixedMask[i] && !m_slidingMask[i]) m_P.add(i, f / m_nodalArea[i]);
      if (!m_fixedMask[j] && !m_slidingMask[j]) m_P.add(j, -f / m_nodalArea[j]);
      ++m_numeric["repulsion_pairs"];
    }
  }
  m_U = m_patchU;
  accumulateDisplacement(m_bem.M, m_P, m_U);
  if (m_bemGravity) m_U.noalias() += m_bem.gravity * in.gravity;

  // Grasped coarse nodes: tractions so that their displacement is the prescribed one.
  std::vector<int> graspNodes;
  std::vector<Vec3> graspTargets;
  if (in.contact) {
    // Contact: surface particles inside an instrument are prescribed onto its surface through
    // the same traction solve as a grasp, so the whole BEM surface answers the push.
    const MatX3 surfaceParticles = m_x.topRows(nc);
    for (const Contact& c : in.contact->query(surfaceParticles)) {
      if (m_fixedMask[c.proxy]) continue;
      graspNodes.push_back(c.proxy);
      graspTargets.push_back(surfaceParticles.row(c.proxy).transpose() + c.depth * c.normal);
    }
  }
  prescribeGrasps(in);
  prescribeSliding(in);
  for (size_t c = 0; c < m_carry.size(); ++c) {
    const int i = m_carry[c];
    if (std::find(graspNodes.begin(), graspNodes.end(), i) != graspNodes.end()) continue;
    graspNodes.push_back(i);
    graspTargets.push_back(m_carryTarget.row(Eigen::Index(c)).transpose());
  }
  // The prescribed components: three per grasped or contact node, then the normal one of each
  // node under a sliding plate (not already held in full; one per node and axis).
  std::vector<int> dofs;
  std::vector<Real> dofTargets;  // m, the prescribed coordinate
  for (size_t a = 0; a < graspNodes.size(); ++a)
    for (int k = 0; k < 3; ++k) {
      dofs.push_back(3 * graspNodes[a] + k);
      dofTargets.push_back(graspTargets[a][k]);
    }
  for (const SlidingSet& s : m_sliding)
    for (size_t c = 0; c < s.carry.size(); ++c) {
      const int i = s.carry[c], d = 3 * i + s.axis;
      if (std::find(graspNodes.begin(), graspNodes.end(), i) != graspNodes.end() ||
          std::find(dofs.begin(), dofs.end(), d) != dofs.end())
        continue;
      dofs.push_back(d);
      dofTargets.push_back(s.carryTarget[Eigen::Index(c)]);
    }
  if (!dofs.empty()) {
    m_graspRhs.resize(Eigen::Index(dofs.size()));
    for (size_t a = 0; a < dofs.size(); ++a)
      m_graspRhs[Eigen::Index(a)] =
          dofTargets[a] - m_restCoarse(dofs[a] / 3, dofs[a] % 3) - m_U[dofs[a]];
    if (m_graspSolver.solve(m_bem.M, dofs, m_graspRhs, m_graspP)) {
      SparseTraction Pg;
      std::map<int, Vec3> traction;  // Pa, the grasp solve's traction at each held node
      for (size_t a = 0; a < dofs.size(); ++a) {
        const Vec3 t = m_graspP[Eigen::Index(a)] * Vec3::Unit(dofs[a] % 3);
        Pg.add(dofs[a] / 3, t);
        traction.emplace(dofs[a] / 3, Vec3::Zero()).first->second += t;
      }
      accumulateDisplacement(m_bem.M, Pg, m_U);
      // The plate's traction field is linear on the coarse triangles (nodal values t_i): its
      // resultant is sum_i A_i t_i (A_i the node's third of its triangles' area), and the
      // tissue pushes the tool with the opposite.
      collectGraspForces(in, [&](int i) -> Vec3 {
        const auto it = traction.find(i);
        return it == traction.end() ? Vec3::Zero() : Vec3(-m_nodalArea[i] * it->second);
      });
    } else {
      ++m_numeric["singular_grasp_systems"];
      m_graspForces.clear();
    }
  } else {
    collectGraspForces(in, [](int) { return Vec3::Zero(); });
  }
  const auto t1 = Clock::now();

  for (int i = 0; i < nc; ++i)
    m_target.row(i) = m_restCoarse.row(i) + m_U.segment<3>(3 * i).transpose();
  for (size_t q = 0; q < m_interiorNodes.size(); ++q) {
    Vec3 u = Vec3::Zero();
    for (int a = 0; a < 8; ++a)
      if (m_interiorNodes[q][a] >= 0)
        u += m_interiorWeights[q][a] * m_U.segment<3>(3 * m_interiorNodes[q][a]);
    m_target.row(nc + Eigen::Index(q)) = m_rest.row(nc + Eigen::Index(q)) + u.transpose();
  }
  m_kinematic = m_fixedMask;
  for (int i : m_carry) m_kinematic[i] = 1;
  for (const SlidingSet& s : m_sliding)
    for (int i : s.carry) m_kinematic[size_t(i)] = 1;
  springCorrection(m_x, m_v, m_target, m_springK, m_springC, in.dt, m_kinematic);
  applyGrasps(in);
  applySliding(in);
  if (in.contact) resolveParticleContacts(in);
  const auto t2 = Clock::now();

  m_coarseDisp = m_x.topRows(nc) - m_restCoarse;
  if (m_transfer == SurfaceTransfer::Gradient)
    interpolateDisplacement(m_map, m_coarse.F, m_fineRest, m_coarseDisp, m_gradient, m_surface);
  else
    interpolateDisplacement(m_map, m_coarse.F, m_fineRest, m_coarseDisp, m_surface);
  if (in.contact) projectSurfaceOut(in);
  recordPhases(m_times, {"surface", "correction", "interpolation"}, {t0, t1, t2, Clock::now()});
  return StepStatus::Ok;
}

StepStatus ParticleBemModel::stepParticles(const StepInput& in) {
  const auto t0 = Clock::now();
  mlsDeformationGradients(m_mls, m_rest, m_x, m_F);
  mlsForces(m_mls, m_F, m_forces);
  // Loads: J^T f, every per-vertex share over the vertex's particles by the skinning weights.
  auto addVertexForce = [&](int v, const Vec3& f) {
    if (v < 0 || v >= int(m_skinNodes.size())) return;
    for (int a = 0; a < 8; ++a) {
      const int j = m_skinNodes[size_t(v)][a];
      if (j >= 0) m_forces.row(j) += m_skinWeights[size_t(v)][a] * f.transpose();
    }
  };
  for (const PointLoad& l : in.loads) {
    if (l.vertices.empty()) addVertexForce(l.surfaceVertex, l.force);
    for (size_t k = 0; k < l.vertices.size() && k < l.weights.size(); ++k)
      addVertexForce(l.vertices[k], l.weights[k] * l.force);
  }
  prescribeGrasps(in);
  prescribeSliding(in);
  // A carried particle's force on the tool: the elastic force of its neighbours on it, the loads
  // on it and its weight, which the tool balances (as reference_fem's minus the energy gradient),
  // at the step's start.
  collectGraspForces(
      in, [&](int i) -> Vec3 { return m_forces.row(i).transpose() + m_mass[i] * in.gravity; });
  const auto t1 = Clock::now();
  const Real damp = 1 / (1 + in.dt * m_particleDamping);
  for (Eigen::Index i = 0; i < m_x.rows(); ++i) {
    if (m_fixedMask[i]) continue;
    m_v.row(i) =
        (m_v.row(i) + in.dt * (m_forces.row(i) / m_mass[i] + in.gravity.transpose())) * damp;
    m_x.row(i) += in.dt * m_v.row(i);
  }
  applyGrasps(in);
  applySliding(in);
  if (in.contact) resolveParticleContacts(in);
  const auto t2 = Clock::now();
  mlsDeformationGradients(m_mls, m_rest, m_x, m_F);
  for (Eigen::Index v = 0; v < m_fineRest.rows(); ++v) {
    Vec3 x = Vec3::Zero();
    for (int a = 0; a < 8; ++a) {
      const int j = m_skinNodes[v][a];
      if (j < 0) continue;
      x += m_skinWeights[v][a] *
           (m_x.row(j).transpose() + m_F[j] * (m_fineRest.row(v) - m_rest.row(j)).transpose());
    }
    m_surface.row(v) = x.transpose();
  }
  if (!m_carry.empty() && !m_graspVerts.empty()) {
    // F_j changed in the step: correct the carrying particles again; with F kept, the skinned
    // surface moves by exactly J dx.
    const Eigen::Index m = Eigen::Index(m_graspVerts.size());
    for (Eigen::Index r = 0; r < m; ++r)
      m_graspGap.row(r) = m_graspTargets.row(r) - m_surface.row(m_graspVerts[size_t(r)]);
    m_graspDx.noalias() = m_JcPinv * m_graspGap;
    for (size_t c = 0; c < m_carry.size(); ++c) {
      m_x.row(m_carry[c]) += m_graspDx.row(Eigen::Index(c));
      m_v.row(m_carry[c]) += m_graspDx.row(Eigen::Index(c)) / in.dt;
    }
    for (Eigen::Index v = 0; v < m_fineRest.rows(); ++v)
      for (int a = 0; a < 8; ++a) {
        const int j = m_skinNodes[size_t(v)][a];
        if (j >= 0 && m_carryCol[size_t(j)] >= 0)
          m_surface.row(v) += m_skinWeights[size_t(v)][a] * m_graspDx.row(m_carryCol[size_t(j)]);
      }
  }
  // The same along a sliding plate's axis alone.
  for (const SlidingSet& s : m_sliding) {
    if (s.carry.empty()) continue;
    VecX gap(Eigen::Index(s.verts.size()));
    for (Eigen::Index r = 0; r < gap.size(); ++r)
      gap[r] = s.targets[r] - m_surface(s.verts[size_t(r)], s.axis);
    const VecX dx = s.pinv * gap;
    for (size_t c = 0; c < s.carry.size(); ++c) {
      m_x(s.carry[c], s.axis) += dx[Eigen::Index(c)];
      m_v(s.carry[c], s.axis) += dx[Eigen::Index(c)] / in.dt;
    }
    for (Eigen::Index v = 0; v < m_fineRest.rows(); ++v)
      for (int a = 0; a < 8; ++a) {
        const int j = m_skinNodes[size_t(v)][a];
        if (j >= 0 && s.col[size_t(j)] >= 0)
          m_surface(v, s.axis) += m_skinWeights[size_t(v)][a] * dx[s.col[size_t(j)]];
      }
  }
  if (in.contact) projectSurfaceOut(in);
  recordPhases(m_times, {"forces", "integration", "skinning"}, {t0, t1, t2, Clock::now()});
  return StepStatus::Ok;
}

}  // namespace deform::particle_bem
