#include "hybrid_model.h"

#include <deform/geometry/tet_mesher.h>
#include <deform/sdk/cache.h>
#include <deform/sdk/error.h>

#include <chrono>
#include <cmath>

namespace deform::hybrid_fem_pbd {

namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}

Real meanEdgeLength(const SurfaceMesh& s) {
  const MatX2i E = uniqueEdges(s.F);
  Real sum = 0;
  for (Eigen::Index e = 0; e < E.rows(); ++e) sum += (s.V.row(E(e, 0)) - s.V.row(E(e, 1))).norm();
  return E.rows() > 0 ? sum / E.rows() : 0;
}

}  // namespace

HybridMesh buildHybridMesh(const SurfaceMesh& fine, const HybridConfig& cfg,
                           const std::string& source, Cache* cache) {
  const auto t0 = Clock::now();
  CacheKey key;
  key.add("hybrid_fem_pbd.mesh/1").add(fine.V).add(fine.F).add(cfg.simplificationLevels);
  key.add(cfg.minCollapseQuality).add(cfg.tetEdgeFactor);
  HybridMesh m;
  if (cache) {
    if (auto bytes = cache->get("hybrid_fem_pbd.mesh", key)) {
      try {
        ByteReader r(*bytes);
        Eigen::Matrix<int, Eigen::Dynamic, 1> c2f;
        r.matrix(m.coarseSurface.V);
        r.matrix(m.coarseSurface.F);
        r.matrix(c2f);
        r.matrix(m.volume.V);
        r.matrix(m.volume.T);
        m.collapsed = r.pod<long long>();
        m.rejected = r.pod<long long>();
        m.coarseToFine.assign(c2f.data(), c2f.data() + c2f.size());
        m.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
        return m;
      } catch (const std::exception&) {
        m = HybridMesh();  // unreadable entry: rebuild
      }
    }
  }
  SimplificationOptions so;
  so.levels = cfg.simplificationLevels;
  so.minQuality = cfg.minCollapseQuality;
  SimplificationResult sr = simplifyByVertexCover(fine, so);
  m.coarseSurface = std::move(sr.coarse);
  m.coarseToFine = std::move(sr.coarseToFine);
  m.collapsed = sr.collapsed;
  m.rejected = sr.rejected;
  TetMeshOptions to;
  to.edgeLength = cfg.tetEdgeFactor * meanEdgeLength(m.coarseSurface);
  to.refineSurface = false;  // the coarse surface vertices must stay exactly the control nodes
  to.source = source;
  TetMeshResult tr = tetrahedralize(m.coarseSurface, to);
  m.volume = std::move(tr.mesh);
  if (tr.inputVertices != m.coarseSurface.numVertices() ||
      m.volume.numVertices() < m.coarseSurface.numVertices())
    throw InputError(source, "hybrid coarse volume mesh", "the tet mesher changed the surface");
  m.seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  if (cache) {
    ByteWriter w;
    Eigen::Matrix<int, Eigen::Dynamic, 1> c2f =
        Eigen::Map<const Eigen::Matrix<int, Eigen::Dynamic, 1>>(
            m.coarseToFine.data(), static_cast<Eigen::Index>(m.coarseToFine.size()));
    w.matrix(m.coarseSurface.V);
    w.matrix(m.coarseSurface.F);
    w.matrix(c2f);
    w.matrix(m.volume.V);
    w.matrix(m.volume.T);
    w.pod<long long>(m.collapsed);
    w.pod<long long>(m.rejected);
    cache->put("hybrid_fem_pbd.mesh", key, w.bytes());
  }
  return m;
}

void HybridModel::init(const ModelSetup& setup) {
  init(setup.organ, configFromParams(setup.params), &setup.cache);
}

void HybridModel::init(const Organ& organ, const HybridConfig& config, Cache* cache) {
  m_cfg = config;
  m_source = organ.source;
  m_density = organ.material.density;
  const Material& mat = organ.material;
  if (!(mat.young > 0) || !(mat.density > 0) || !(mat.poisson > -1.0 && mat.poisson < 0.5))
    throw InputError(organ.source, "organ.material",
                     "hybrid_fem_pbd needs young > 0, density > 0 and poisson in (-1, 0.5)");
  const SurfaceMesh& fine = organ.surface;
  m_mesh = buildHybridMesh(fine, m_cfg, organ.source, cache);

  const std::vector<int> fixedVolume = fixedNodeIndices(m_mesh.volume.V, organ.fixed, fine);
  m_fem.init(m_mesh.volume, mat, fixedVolume, organ.source);
  // The surface reads MV at the control nodes only (the coarse surface, MV nodes 0..#Vc-1).
  m_fem.setOutputNodes(m_mesh.coarseSurface.numVertices());
  m_fem.setSinglePrecisionResponse(m_cfg.precision == HybridPrecision::Float32);
  m_origin = boundingBox(fine.V).center();
  m_fixedFine = fixedNodeIndices(fine.V, organ.fixed, fine);

  m_surf0 = CuttableSurface::fromMesh(fine.V, fine.V, fine.F);
  m_numeric.clear();
  long long skipped = 0;
  m_constraints0 = buildSurfaceConstraints(fine.V, fine.F, &skipped);
  m_numeric["degenerate_hinges"] = skipped;
  m_numeric["rejected_merges"] = m_mesh.rejected;
  if (m_fem.regularised()) m_numeric["unpinned_volume"] = 1;
  m_controlOf0.assign(fine.numVertices(), -1);
  for (size_t c = 0; c < m_mesh.coarseToFine.size(); ++c)
    m_controlOf0[m_mesh.coarseToFine[c]] = static_cast<int>(c);
  reset();
}

void HybridModel::rebuildMasses() {
  // Organ mass (density x enclosed rest volume) lumped to the vertices by a third of the rest
  // area of each incident triangle.
  const MatX3i F = m_surf.faces();
  const int n = m_surf.numVertices();
  const Real total =
      m_surf0.x.rows() > 0 ? std::abs(signedVolume(m_surf0.rest, m_surf0.originalF)) : 0;
  VecX area = VecX::Zero(n);
  Real areaSum = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Vec3 a = m_surf.rest.row(F(f, 0)), b = m_surf.rest.row(F(f, 1)),
               c = m_surf.rest.row(F(f, 2));
    const Real A = 0.5 * (b - a).cross(c - a).norm();
    for (int k = 0; k < 3; ++k) area[F(f, k)] += A / 3;
    areaSum += A;
  }
  const Real density = m_density;
  m_mass = VecX::Zero(n);
  for (int i = 0; i < n; ++i) m_mass[i] = areaSum > 0 ? density * total * area[i] / areaSum : 0;
}

void HybridModel::reset() {
  m_surf = m_surf0;
  m_constraints = m_constraints0;
  m_controlOf = m_controlOf0;
  const int n = m_surf.numVertices();
  m_v = MatX3::Zero(n, 3);
  m_p = m_surf.x;
  m_volumeX = m_mesh.volume.V;
  m_volumeU = MatX3::Zero(m_volumeX.rows(), 3);
  m_isFixedFine.assign(n, 0);
  for (int i : m_fixedFine) m_isFixedFine[i] = 1;
  m_attach.clear();
  m_immovable.clear();
  m_activeValid = false;
  m_graspForces.clear();
  m_lastCut = CutReport();
  m_cut = false;
  m_phase.clear();
  rebuildMasses();
}

const CoarseAttachment& HybridModel::attachment(int i) {
  auto it = m_attach.find(i);
  if (it != m_attach.end()) return it->second;
  const CoarseAttachment a =
      attachToCoarseSurface(m_surf.rest.row(i).transpose(), m_mesh.coarseSurface.V,
                            m_mesh.coarseSurface.F, m_controlOf[i]);
  return m_attach.emplace(i, a).first->second;
}

StepStatus HybridModel::step(const StepInput& in) {
  if (in.contact && !m_inContactStep) return stepWithContact(in);
  if (!in.nodeConstraints.empty()) {
    // Contact constraints name fine surface vertices, which are this model's nodes: they act
    // as grasps (their forces follow the scene's grasps in graspForces()).
    StepInput merged = in;
    merged.nodeConstraints.clear();
    for (const NodeGrasp& c : in.nodeConstraints)
      merged.grasps.push_back({c.tool, c.nodes, c.targets});
    return step(merged);
  }
  auto t = Clock::now();
  // 1. Load processing.
  gatherLoads(in.loads);
  gatherGrasps(in.grasps);
  m_phase["load"] = msSince(t);

  // 2. Coarse FEM.
  t = Clock::now();
  solveCoarse(in.gravity, in.grasps.size());
  m_phase["fem"] = msSince(t);

  // 3.-5. Fine surface PBD.
  t = Clock::now();
  refreshActiveConstraints();
  predictSurface(in.dt, in.gravity);
  m_numeric["degenerate_constraints"] += projectPrediction();
  const Real damp = std::exp(-m_cfg.damping * in.dt);
  const Real invDt = in.dt > 0 ? 1 / in.dt : 0;
  m_v = (m_p - m_surf.x) * (invDt * damp);
  m_surf.x.swap(m_p);
  m_phase["pbd"] = msSince(t);
  if (!m_surf.x.allFinite() || !m_volumeX.allFinite()) return StepStatus::Diverged;
  return StepStatus::Ok;
}

void HybridModel::gatherLoads(const std::vector<PointLoad>& loads) {
  const int n = m_surf.numVertices();
  m_nodal.clear();
  m_surfaceForces.clear();
  // Each share of the harness's pressure patch acts on the fine vertex that takes it and, through
  // the vertex's attachment to the coarse surface, on the coarse FEM.
  for (const PointLoad& l : loads) {
    if (l.force.isZero()) continue;
    for (size_t s = 0; s < l.vertices.size(); ++s) {
      const int v = l.vertices[s];
      if (v < 0 || v >= n) continue;
      const Vec3 share = l.weights[s] * l.force;
      const CoarseAttachment& a = attachment(v);
      const std::array<Vec3, 3> f = equivalentNodalForces(a, share);
      for (int k = 0; k < a.count; ++k) m_nodal.push_back({a.nodes[k], f[k]});
      if (m_cfg.surfaceLoad && m_controlOf[v] < 0) m_surfaceForces.emplace_back(v, share);
    }
  }
}

void HybridModel::gatherGrasps(const std::vector<GraspInput>& grasps) {
  const int n = m_surf.numVertices();
  m_prescribed.clear();
  m_prescribedGrasp.clear();
  std::vector<char>& immovable = m_immovableStep;
  immovable.assign(n, 0);
  m_graspTargets.clear();
  m_graspTargetAxis.clear();
  for (size_t gi = 0; gi < grasps.size(); ++gi) {
    const GraspInput& g = grasps[gi];
    // A sliding plate: its normal component only, in the coarse FEM and on the fine surface.
    const int axis = slideAxis(g);
    if (g.sliding() && axis < 0)
      throw InputError("hybrid_fem_pbd", "grasp of tool " + std::to_string(g.tool),
                       "a sliding plate's normal must lie along x, y or z");
    bool anyControl = false;
    for (int i : g.vertices)
      if (i >= 0 && i < n && m_controlOf[i] >= 0) anyControl = true;
    for (size_t k = 0; k < g.vertices.size(); ++k) {
      const int i = g.vertices[k];
      if (i < 0 || i >= n || static_cast<Eigen::Index>(k) >= g.targets.rows()) continue;
      const Vec3 target = g.targets.row(k).transpose();
      m_graspTargets.emplace_back(i, target);
      m_graspTargetAxis.push_back(axis);
      immovable[i] = 1;
      if (m_controlOf[i] >= 0 || !anyControl) {
        CoarseLinearFem::Prescribed p;
        p.at = attachment(i);
        p.displacement = target - m_surf.rest.row(i).transpose();
        if (axis >= 0) p.axes = 1 << axis;
        m_prescribed.push_back(p);
        m_prescribedGrasp.push_back(static_cast<int>(gi));
      }
    }
  }
}

void HybridModel::solveCoarse(const Vec3& gravity, size_t numGrasps) {
  m_fem.solve(m_nodal, gravity, m_prescribed, m_volumeU, &m_reactions);
  // Only the control nodes (MV's rows 0..#Vc-1) are computed; the interior rows stay at rest.
  const Eigen::Index nc = m_mesh.coarseSurface.numVertices();
  m_volumeX.topRows(nc) = m_mesh.volume.V.topRows(nc) + m_volumeU.topRows(nc);
  // With markers, every node is solved (bindMarkers) and kept.
  if (m_markersBound && m_volumeU.rows() == m_volumeX.rows())
    m_volumeX = m_mesh.volume.V + m_volumeU;
  // Newton's third law: the multipliers are the forces the grasps apply to the tissue.
  m_graspForces.assign(numGrasps, Vec3::Zero());
  for (size_t e = 0; e < m_prescribed.size(); ++e)
    m_graspForces[static_cast<size_t>(m_prescribedGrasp[e])] -= m_reactions[e];
  // A sliding plate's fine vertices follow the coarse surface along the plate (their attachment's
  // displacement) and the plate along its normal.
  for (size_t k = 0; k < m_graspTargets.size(); ++k) {
    const int axis = m_graspTargetAxis[k];
    if (axis < 0) continue;
    auto& [i, target] = m_graspTargets[k];
    const CoarseAttachment& a = attachment(i);
    Vec3 x = m_surf.rest.row(i).transpose();
    for (int c = 0; c < a.count; ++c)
      x += a.weights[size_t(c)] * m_volumeU.row(a.nodes[size_t(c)]).transpose();
    x[axis] = target[axis];
    target = x;
  }
}

void HybridModel::refreshActiveConstraints() {
  const int n = m_surf.numVertices();
  std::vector<char>& immovable = m_immovableStep;
  for (int i = 0; i < n; ++i)
    if (m_controlOf[i] >= 0 || m_isFixedFine[i]) immovable[i] = 1;
  if (m_activeValid && immovable == m_immovable) return;
  m_immovable = immovable;
  m_w.resize(n);
  for (int i = 0; i < n; ++i) m_w[i] = immovable[i] || !(m_mass[i] > 0) ? 0 : 1 / m_mass[i];
  m_active = activeConstraints(m_constraints, m_w);
  m_batches = buildSurfaceBatches(m_constraints, m_active, m_w, m_cfg.stretchStiffness,
                                  m_cfg.bendingStiffness, m_cfg.iterations);
  if (m_cfg.bending == HybridBending::Isometric) {
    addIsometricBending(m_batches, m_surf.rest);
    if (m_cfg.precision == HybridPrecision::Float32 &&
        m_cfg.projection != SurfaceProjection::Reference)
      addSinglePrecision(m_batches, m_surf.rest, m_origin,
                         m_cfg.projection == SurfaceProjection::Batched);
  }
  m_activeValid = true;
}

void HybridModel::predictSurface(Real dt, const Vec3& g) {
  const int n = m_surf.numVertices();
  for (const auto& [i, f] : m_surfaceForces) m_v.row(i) += (dt * m_w[i] * f).transpose();
  m_p.resize(n, 3);
  for (int i = 0; i < n; ++i) {
    if (m_controlOf[i] >= 0 && !m_isFixedFine[i]) {
      m_p.row(i) = m_volumeX.row(m_controlOf[i]);
    } else if (m_isFixedFine[i]) {
      m_p.row(i) = m_surf.rest.row(i);
    } else if (m_w[i] > 0) {
      m_v.row(i) += dt * g.transpose();
      m_p.row(i) = m_surf.x.row(i) + dt * m_v.row(i);
    } else {
      m_p.row(i) = m_surf.x.row(i);
    }
  }
  for (const auto& [i, target] : m_graspTargets)
    if (!m_isFixedFine[i]) m_p.row(i) = target.transpose();
}

long long HybridModel::projectPrediction() {
  const int n = m_surf.numVertices();
  if (m_cfg.projection == SurfaceProjection::Reference)
    return projectSurfaceConstraints(m_p, m_w, m_constraints, m_active, m_cfg.stretchStiffness,
                                     m_cfg.bendingStiffness, m_cfg.iterations);
  const bool simd = m_cfg.projection == SurfaceProjection::Batched;
  long long degenerate = 0;
  if (m_batches.singlePrecision) {
    // Projected in float relative to the organ's centre; the result is taken back as the float
    // correction added to the double prediction, so an unmoved particle keeps its double value.
    m_x4f.resize(4 * static_cast<size_t>(n));
    for (int i = 0; i < n; ++i) {
      for (int a = 0; a < 3; ++a)
        m_x4f[4 * size_t(i) + a] = static_cast<float>(m_p(i, a) - m_origin[a]);
      m_x4f[4 * size_t(i) + 3] = 0.0f;
    }
    degenerate = projectSurfaceBatchesF(m_x4f.data(), m_batches, m_cfg.iterations, simd);
    for (int i = 0; i < n; ++i)
      for (int a = 0; a < 3; ++a)
        m_p(i, a) += static_cast<Real>(m_x4f[4 * size_t(i) + a] -
                                       static_cast<float>(m_p(i, a) - m_origin[a]));
  } else {
    m_x4.resize(4 * static_cast<size_t>(n));
    for (int i = 0; i < n; ++i)
      for (int a = 0; a < 4; ++a) m_x4[4 * size_t(i) + a] = a < 3 ? m_p(i, a) : 0.0;
    degenerate = projectSurfaceBatches(m_x4.data(), m_batches, m_cfg.iterations, simd);
    for (int i = 0; i < n; ++i)
      for (int a = 0; a < 3; ++a) m_p(i, a) = m_x4[4 * size_t(i) + a];
  }
  return degenerate;
}

void HybridModel::cut(const CutPath& path) {
  CutReport r = cutSurface(m_surf, path, CutOptions{m_cfg.cutSnap});
  m_lastCut = r;
  if (!r.applied) {
    ++m_numeric["rejected_cuts"];
    return;
  }
  ++m_numeric["cuts"];
  m_cut = true;
  const int n = m_surf.numVertices();
  const int old = static_cast<int>(m_controlOf.size());
  m_controlOf.resize(n, -1);
  m_isFixedFine.resize(n, 0);
  m_v.conservativeResize(n, 3);
  for (int i = old; i < n; ++i) m_v.row(i).setZero();
  // A control point on the cut is duplicated; both copies become ordinary points (paper Sec. 7).
  for (const auto& [v, copy] : r.duplicates) {
    m_controlOf[v] = -1;
    m_controlOf[copy] = -1;
    m_isFixedFine[copy] = m_isFixedFine[v];
    m_v.row(copy) = m_v.row(v);
  }
  m_constraints = constraintsAfterCut(m_surf, m_constraints0);
  m_attach.clear();
  m_activeValid = false;
  rebuildMasses();
}

MatX3i HybridModel::surfaceFaces() const {
  return m_cut ? m_surf.faces() : MatX3i();
}

Counts HybridModel::counts() const {
  Counts c;
  c["nodes"] = m_surf.numVertices();
  c["coarse_vertices"] = m_mesh.coarseSurface.numVertices();
  c["coarse_faces"] = m_mesh.coarseSurface.numFaces();
  c["volume_nodes"] = m_mesh.volume.numVertices();
  c["tets"] = m_mesh.volume.numTets();
  c["stretch_constraints"] = static_cast<long long>(m_constraints.stretch.size());
  c["bending_constraints"] = static_cast<long long>(m_constraints.bending.size());
  c["constraints"] = c["stretch_constraints"] + c["bending_constraints"];
  long long control = 0;
  for (int v : m_controlOf) control += v >= 0;
  c["control_nodes"] = control;
  c["faces"] = static_cast<long long>(m_surf.F.size());
  return c;
}

void HybridModel::bindMarkers(const MatX3& rest) {
  m_markerEmbedding = embedInTets(m_mesh.volume.V, m_mesh.volume.T, rest);
  m_fem.setOutputNodes(-1);
  m_markersBound = true;
}

MatX3 HybridModel::markers() const {
  return embeddedPositions(m_markerEmbedding, m_volumeX, m_mesh.volume.T);
}

}  // namespace deform::hybrid_fem_pbd
