#include "metaballs_model.h"

#include <deform/contact.h>
#include "pbd_constraints.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace deform::metaballs {

namespace {
using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t).count();
}
}  // namespace

std::vector<ParamSpec> metaballsParams() {
  return {
      ParamSpec::integer("spheres", 900, 8, 20000,
                         "sphere budget of the medial-axis packing (stage 1); the final count "
                         "changes by filling and merging"),
      ParamSpec::integer("voxel_resolution", 48, 8, 256,
                         "voxels along the organ's longest side (packing samples, Algorithm 2)"),
      ParamSpec::integer("fill_neighbours", 6, 1, 32, "k nearest neighbours of Algorithm 1"),
      ParamSpec::real("fill_min_radius", "1", 0.5, 0.0, 1.0,
                      "smallest filling sphere, as a fraction of the median radius"),
      ParamSpec::real("attraction_range", "1", 2.0, 0.5, 10.0,
                      "Algorithm 2: reach of a hollow voxel beyond a sphere's surface, in voxels"),
      ParamSpec::integer("optimisation_max_moves", 20000, 0, 10000000,
                         "Algorithm 2: most accepted one-voxel moves"),
      ParamSpec::integer("topology_neighbours", 9, 1, 64, "N of eq. (5)"),
      ParamSpec::integer("iterations", 10, 1, 1000, "PBD solver iterations per step"),
      ParamSpec::choice("stiffness_mode", "xpbd", {"xpbd", "classic"},
                        "xpbd: compliance from Young's modulus; classic: stiffness coefficient"),
      ParamSpec::real("stiffness", "1", 1.0, 0.0, 1.0, "classic PBD stretching stiffness"),
      ParamSpec::flag("laplacian", true, "Laplacian coordinate constraints (eqs. 9-11)"),
      ParamSpec::real("laplacian_stiffness", "1", 0.5, 0.0, 1.0,
                      "classic: coefficient; xpbd: fraction of E r_m used as stiffness (N/m)"),
      ParamSpec::choice("laplacian_frame", "rotated", {"rotated", "fixed"},
                        "rotated: L_m follows the local rotation; fixed: the paper's world frame"),
      ParamSpec::flag("volume_preservation", true, "local volume preservation by radii (eq. 12)"),
      ParamSpec::choice("skinning_frame", "rotated", {"rotated", "fixed"},
                        "rotated: disp follows the blended sphere rotations; fixed: eq. (16)"),
      ParamSpec::real("skin_threshold", "1", 0.2, 1e-6, 1.0,
                      "T: a sphere is attached when f(d, r) >= T (eq. 13, c = 1)"),
      ParamSpec::integer("skin_max_spheres", 6, 1, 16, "most attached spheres per vertex"),
      ParamSpec::real("damping", "1/s", 5.0, 0.0, 1000.0, "velocity damping rate"),
  };
}

ModelInfo metaballsModelInfo() {
  ModelInfo info;
  info.name = "metaballs";
  info.description =
      "Metaballs (overlapping spheres) + PBD with Laplacian and local volume constraints, "
      "skinned surface";
  info.citation =
      "Pan, Zhao, Zhao, Hao, Qin 2015, Metaballs-based physical modeling and deformation of "
      "organs for virtual surgery, The Visual Computer 31, doi:10.1007/s00371-015-1092-2";
  info.version = "1.0";
  info.capabilities = {Capability::Grasp, Capability::PointForce, Capability::Gravity,
                       Capability::NeedsPrecompute, Capability::Contact};
  info.params = metaballsParams();
  info.create = [] { return std::make_unique<MetaballsModel>(); };
  return info;
}

ConstructionParams constructionParams(const ParamValues& p) {
  ConstructionParams c;
  c.targetSpheres = int(p.integer("spheres"));
  c.voxelResolution = int(p.integer("voxel_resolution"));
  c.fillNeighbours = int(p.integer("fill_neighbours"));
  c.fillMinRadiusRatio = p.real("fill_min_radius");
  c.attractionRangeVoxels = p.real("attraction_range");
  c.maxOptimisationMoves = int(p.integer("optimisation_max_moves"));
  c.topologyNeighbours = int(p.integer("topology_neighbours"));
  return c;
}

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
  m_skin = buildSkinning(organ.surface.V, s, p.real("skin_threshold"),
                         int(p.integer("skin_max_spheres")));

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

  m_fixedList = fixedNodeIndices(m_x0, organ.fixed, organ.surface);
  m_fixed.assign(size_t(n), 0);
  for (int i : m_fixedList) m_fixed[size_t(i)] = 1;

  m_p.resize(n, 3);
  m_f.resize(n, 3);
  m_kin.assign(size_t(n), 0);
  m_wEff.assign(size_t(n), 0);
  m_lambda.assign(size_t(nl), 0);
  m_lapLambda.assign(size_t(n), Vec3::Zero());
  m_volFactorSum.assign(size_t(n), 0);
  m_volCount.assign(size_t(n), 0);
  m_rot.assign(size_t(n) * 9, 0);
  reset();
}

void MetaballsModel::reset() {
  const int n = m_mb.spheres.size();
  m_x = m_x0;
  m_v.setZero(n, 3);
  m_r = m_mb.spheres.radii;
  m_q.assign(size_t(n), Eigen::Quaternion<Real>::Identity());
  for (int i = 0; i < n; ++i)
    for (int q = 0; q < 9; ++q) m_rot[size_t(9 * i + q)] = (q % 4 == 0) ? 1.0 : 0.0;
  m_surface = m_restSurface;
  m_phase.clear();
  m_degenerate = 0;
}

void MetaballsModel::computeRotations() {
  const int n = m_mb.spheres.size();
  for (int m = 0; m < n; ++m) {
    const int b = m_adjStart[size_t(m)], e = m_adjStart[size_t(m) + 1];
    if (e == b) continue;
    Mat3 A = Mat3::Zero();
    const Vec3 xm = m_x.row(m).transpose(), x0m = m_x0.row(m).transpose();
    for (int k = b; k < e; ++k) {
      const int i = m_adj[size_t(k)];
      A += (m_x.row(i).transpose() - xm) * (m_x0.row(i).transpose() - x0m).transpose();
    }
    // Warm-started from the previous step: a few iterations track the rotation.
    extractRotation(A, m_q[size_t(m)], 3);
    const Mat3 R = m_q[size_t(m)].toRotationMatrix();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) m_rot[size_t(9 * m + 3 * r + c)] = R(r, c);
  }
}

StepStatus MetaballsModel::step(const StepInput& in) {
  const int n = m_mb.spheres.size();
  const Real dt = in.dt;
  if (!(dt > 0)) return StepStatus::Ok;
  const MatX2i& L = m_mb.topology.links;
  const int nl = int(L.rows());
  auto t0 = Clock::now();

  // External forces: point loads spread over the loaded vertex's spheres by skinning weight.
  m_f.setZero();
  m_contacted.clear();
  const int K = m_skin.slots;
  for (const PointLoad& load : in.loads) {
    if (load.surfaceVertex < 0 || load.surfaceVertex >= m_skin.numVertices) continue;
    for (int s = 0; s < K; ++s) {
      const size_t slot = size_t(load.surfaceVertex) * K + s;
      if (m_skin.weight[slot] <= 0) continue;
      m_f.row(m_skin.sphere[slot]) += m_skin.weight[slot] * load.force.transpose();
      m_contacted.push_back(m_skin.sphere[slot]);
    }
  }
  // Kinematic spheres: fixed ones stay at rest, grasped ones reach their targets.
  std::copy(m_fixed.begin(), m_fixed.end(), m_kin.begin());
  for (int i : m_fixedList) m_p.row(i) = m_x0.row(i);
  for (const GraspInput& g : in.grasps) {
    for (size_t k = 0; k < g.nodes.size(); ++k) {
      const int i = g.nodes[k];
      if (i < 0 || i >= n || m_fixed[size_t(i)]) continue;
      m_kin[size_t(i)] = 1;
      m_p.row(i) = g.targets.row(Eigen::Index(k));
      m_contacted.push_back(i);
    }
  }
  // Algorithm 3, lines 8-13: prediction with damping.
  const Real keep = std::max(Real(0), 1 - m_damping * dt);
  for (int i = 0; i < n; ++i) {
    if (m_kin[size_t(i)]) {
      m_wEff[size_t(i)] = 0;
      continue;
    }
    m_wEff[size_t(i)] = m_invMass(i);
    m_v.row(i) = keep * (m_v.row(i) + dt * (in.gravity.transpose() + m_invMass(i) * m_f.row(i)));
    m_p.row(i) = m_x.row(i) + dt * m_v.row(i);
  }
  std::fill(m_lambda.begin(), m_lambda.end(), 0.0);
  std::fill(m_lapLambda.begin(), m_lapLambda.end(), Vec3::Zero());
  const Real dt2 = dt * dt;
  const bool lapRot = m_lapFrame == Frame::Rotated;
  double tStretch = msSince(t0), tLap = 0;
  long long degenerate = 0;
  for (int it = 0; it < m_iterations; ++it) {
    auto ts = Clock::now();
    Real* P = m_p.data();
    const int* LL = L.data();
    for (int l = 0; l < nl; ++l) {
      const int a = LL[2 * l], b = LL[2 * l + 1];
      const Real wa = m_wEff[size_t(a)], wb = m_wEff[size_t(b)];
      if (wa + wb == 0) continue;
      Real* pa = P + 3 * a;
      Real* pb = P + 3 * b;
      const Real dx = pa[0] - pb[0], dy = pa[1] - pb[1], dz = pa[2] - pb[2];
      const Real len = std::sqrt(dx * dx + dy * dy + dz * dz);
      if (!(len > 1e-12)) {
        ++degenerate;
        continue;
      }
      // Eqs. (7)-(8) (classic) or their XPBD form; same maths as projectStretch*, inlined on raw
      // arrays for speed.
      const Real C = len - m_linkRest[size_t(l)];
      Real s;
      if (m_mode == StiffnessMode::Xpbd) {
        const Real at = m_linkAlpha[size_t(l)] / dt2;
        const Real dl = (-C - at * m_lambda[size_t(l)]) / (wa + wb + at);
        m_lambda[size_t(l)] += dl;
        s = -dl;
      } else {
        s = m_stiffness * C / (wa + wb);
      }
      const Real f = s / len;
      pa[0] -= wa * f * dx;
      pa[1] -= wa * f * dy;
      pa[2] -= wa * f * dz;
      pb[0] += wb * f * dx;
      pb[1] += wb * f * dy;
      pb[2] += wb * f * dz;
    }
    tStretch += msSince(ts);
    if (!m_laplacian) continue;
    ts = Clock::now();
    for (int m = 0; m < n; ++m) {
      const int b = m_adjStart[size_t(m)], e = m_adjStart[size_t(m) + 1];
      const int cnt = e - b;
      if (cnt == 0) continue;
      Vec3 centre = Vec3::Zero();
      Real wsum = 0;
      for (int k = b; k < e; ++k) {
        const int i = m_adj[size_t(k)];
        centre += m_p.row(i).transpose();
        wsum += m_wEff[size_t(i)];
      }
      const Real wm = m_wEff[size_t(m)];
      if (wm + wsum == 0) continue;
      centre /= Real(cnt);
      Vec3 Lm = m_lapRest.row(m).transpose();
      if (lapRot)
        Lm = Eigen::Map<const Eigen::Matrix<Real, 3, 3, Eigen::RowMajor>>(&m_rot[size_t(9 * m)]) *
             Lm;
      const Vec3 C = m_p.row(m).transpose() - centre - Lm;
      Vec3 dl;
      if (m_mode == StiffnessMode::Xpbd) {
        dl = laplacianXpbd(C, wm, wsum, cnt, m_lapAlpha(m) / dt2, m_lapLambda[size_t(m)]);
      } else {
        dl = -laplacianScale(wm, wsum, cnt, m_lapStiffness) * C;
      }
      // dc_m = w_m dl, dc_i = -(w_i / n) dl
      m_p.row(m) += wm * dl.transpose();
      for (int k = b; k < e; ++k) {
        const int i = m_adj[size_t(k)];
        m_p.row(i) -= (m_wEff[size_t(i)] / Real(cnt)) * dl.transpose();
      }
    }
    tLap += msSince(ts);
  }
  // Contact: the spheres (current radii) are projected out of the instruments after the sweeps,
  // like any other position constraint; kinematic spheres do not move.
  if (in.contact) {
    const VecX w = Eigen::Map<const VecX>(m_wEff.data(), n);
    resolveContacts(*in.contact, m_p, w, dt, nullptr, &m_r);
  }
  // Algorithm 3, lines 18-21.
  auto ts = Clock::now();
  const Real invDt = 1.0 / dt;
  for (int i = 0; i < n; ++i) {
    m_v.row(i) = m_fixed[size_t(i)] ? Eigen::RowVector3d::Zero().eval()
                                    : ((m_p.row(i) - m_x.row(i)) * invDt).eval();
  }
  m_x = m_p;
  tStretch += msSince(ts);
  m_degenerate += degenerate;

  // Eq. (12) on the spheres under interaction and their linked spheres.
  ts = Clock::now();
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
        m_r(i) = m_mb.spheres.radii(i) * m_volFactorSum[size_t(i)] / m_volCount[size_t(i)];
        m_volFactorSum[size_t(i)] = 0;
        m_volCount[size_t(i)] = 0;
      }
    }
  }
  const double tVol = msSince(ts);

  ts = Clock::now();
  if (m_lapFrame == Frame::Rotated || m_skinFrame == Frame::Rotated) computeRotations();
  const double tRot = msSince(ts);
  ts = Clock::now();
  applySkinning(m_skin, m_x, m_r, m_skinFrame == Frame::Rotated ? m_rot.data() : nullptr,
                m_surface);
  // The skinned surface can bulge past the spheres: keep it out of the instruments too (display
  // level, no force: the spheres carried it).
  if (in.contact) projectPointsOut(*in.contact, m_surface);
  const double tSkin = msSince(ts);

  m_phase["pbd"] = tStretch;
  m_phase["laplacian"] = tLap;
  m_phase["volume"] = tVol;
  m_phase["rotations"] = tRot;
  m_phase["skinning"] = tSkin;
  if (!m_x.allFinite() || !m_surface.allFinite() || !m_r.allFinite()) return StepStatus::Diverged;
  return StepStatus::Ok;
}

Counts MetaballsModel::counts() const {
  const long long s = m_mb.spheres.size(), l = m_mb.topology.links.rows();
  return {{"spheres", s},
          {"nodes", s},
          {"links", l},
          {"constraints", l + (m_laplacian ? s : 0)},
          {"surface_vertices", m_skin.numVertices}};
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

}  // namespace deform::metaballs
