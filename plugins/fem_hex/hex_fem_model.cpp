#include "hex_fem_model.h"

#include "element_product.h"
#include "rotation_batch.h"

#include <deform/sdk/contact.h>

#include <deform/sdk/error.h>

#include <Eigen/QR>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

namespace deform::fem_hex {

namespace {

using Clock = std::chrono::steady_clock;
double msSince(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

/// Calls fn(local, row, col) for each entry of an element's 24 x 24 stiffness that lands in the
/// lower triangle of the reduced matrix (both nodes free, row >= col): local = 24 (3a + i) +
/// 3b + j for nodes a, b and axes i, j, row and col the reduced dofs.
template <class Fn>
void forEachLowerEntry(const std::array<int, 8>& hex, const std::vector<int>& dofOfNode, Fn&& fn) {
  for (int a = 0; a < 8; ++a) {
    for (int b = 0; b < 8; ++b) {
      const int da = dofOfNode[hex[a]], db = dofOfNode[hex[b]];
      if (da < 0 || db < 0) continue;
      for (int i = 0; i < 3; ++i)
        for (int j = 0; j < 3; ++j)
          if (da + i >= db + j) fn((3 * a + i) * 24 + 3 * b + j, da + i, db + j);
    }
  }
}

/// An element's 24-vector u = a in - b rest at its eight nodes, rotated back by R^T when R is
/// given (corotational); b = 0 skips the rest term.
template <class Local>
void gatherElement(const std::array<int, 8>& hex, const Mat3* R, const VecX& in, const MatX3& rest,
                   Real a, Real b, Local&& u) {
  if (R) {
    const Mat3 Rt = R->transpose();
    for (int i = 0; i < 8; ++i) {
      u.template segment<3>(3 * i).noalias() = Rt * (a * in.segment<3>(3 * hex[i]));
      if (b != 0) u.template segment<3>(3 * i) -= b * rest.row(hex[i]).transpose();
    }
  } else {
    for (int i = 0; i < 8; ++i) {
      u.template segment<3>(3 * i) = a * in.segment<3>(3 * hex[i]);
      if (b != 0) u.template segment<3>(3 * i) -= b * rest.row(hex[i]).transpose();
    }
  }
}

}  // namespace

std::vector<Real> cellFillFractions(const SurfaceMesh& surface, const VoxelGrid& voxels,
                                    const HexGrid& grid, int n) {
  std::vector<Real> fill(size_t(grid.numHexes()), 1.0);
  if (n < 1) return fill;
  // The finer grid stays within ~50M cells (its states and flags are two bytes a cell).
  while (n > 1 && static_cast<double>(voxels.dims.prod()) * n * n * n > 5e7) --n;
  const VoxelGrid fine = voxelizeGrid(surface, voxels.origin, voxels.cellSize / n, voxels.dims * n,
                                      static_cast<long long>(5e7) + 1);
  for (int e = 0; e < grid.numHexes(); ++e) {
    const Vec3i c = grid.cells[size_t(e)];
    if (voxels.at(c) == CellState::Inside) continue;
    int inside = 0;
    for (int k = 0; k < n; ++k)
      for (int j = 0; j < n; ++j)
        for (int i = 0; i < n; ++i)
          inside += fine.centreInside[fine.linearIndex(n * c + Vec3i(i, j, k))];
    fill[size_t(e)] = std::max(kMinCellFill, Real(inside) / (n * n * n));
  }
  return fill;
}

namespace {

// InputError for unusable input (where: the organ's source).
void checkInput(const std::string& where, const Organ& organ, const HexFemConfig& config, Real dt) {
  const Material& mat = organ.material;
  if (!(dt > 0)) throw InputError(where, "dt", "time step must be positive");
  if (!(mat.young > 0)) throw InputError(where, "material.young", "must be positive");
  if (!(mat.poisson > -1 && mat.poisson < 0.5)) {
    throw InputError(where, "material.poisson", "must be in (-1, 0.5)");
  }
  if (!(mat.density > 0)) throw InputError(where, "material.density", "must be positive");
  if (organ.surface.numVertices() == 0 || organ.surface.numFaces() == 0) {
    throw InputError(where, "surface", "empty surface mesh");
  }
  if (config.cellSize <= 0 && config.elements < 1) {
    throw InputError(where, "params.elements", "must be >= 1 when cell_size is 0");
  }
}

// The clamped surface vertices: inside a fixed box or listed by index (sorted, once each).
std::vector<int> clampedSurfaceVertices(const Organ& organ) {
  std::vector<int> clamped;
  for (Eigen::Index v = 0; v < organ.surface.V.rows(); ++v) {
    const Vec3 p = organ.surface.V.row(v).transpose();
    for (const Box& b : organ.fixed.boxes)
      if (b.contains(p)) {
        clamped.push_back(static_cast<int>(v));
        break;
      }
  }
  for (int v : organ.fixed.surfaceVertices)
    if (v >= 0 && v < organ.surface.numVertices()) clamped.push_back(v);
  std::sort(clamped.begin(), clamped.end());
  clamped.erase(std::unique(clamped.begin(), clamped.end()), clamped.end());
  return clamped;
}

}  // namespace

void HexFemModel::init(const ModelSetup& setup) {
  const Organ& organ = setup.organ;
  initialize(organ, configFromParams(setup.params), setup.dt, [&](const MatX3& nodes) {
    return organ.fixed.empty() ? std::vector<int>{}
                               : fixedNodeIndices(nodes, organ.fixed, organ.surface);
  });
}

void HexFemModel::initialize(const Organ& organ, const HexFemConfig& config, Real dt,
                             const std::function<std::vector<int>(const MatX3&)>& fixedNodesOf) {
  const std::string where = organ.source.empty() ? std::string("<organ>") : organ.source;
  const Material& mat = organ.material;
  checkInput(where, organ, config, dt);
  m_config = config;
  m_dt = dt;

  const Real h =
      config.cellSize > 0 ? config.cellSize : cellSizeForCount(organ.surface, config.elements);
  try {
    m_voxels = voxelize(organ.surface, h, 20000000);
  } catch (const InputError& e) {
    throw InputError(where, "params.cell_size", e.problem());
  }
  m_grid = hexGridFromVoxels(m_voxels);
  m_embedding = embedPoints(m_grid, m_voxels, organ.surface.V);
  m_K0 = config.element == HexElement::IncompatibleModes
             ? hexStiffnessIncompatible(Vec3::Constant(h), mat.young, mat.poisson)
             : hexStiffness(Vec3::Constant(h), mat.young, mat.poisson);
  m_rest = m_grid.nodes;
  m_restRows = Eigen::Map<const VecX>(MatX(m_rest.transpose()).data(), 3 * m_rest.rows());
  const int N = m_grid.numNodes();
  const int E = m_grid.numHexes();

  m_fill = cellFillFractions(organ.surface, m_voxels, m_grid, config.fillSamples);
  m_mass = VecX::Zero(3 * N);
  const Real nodeMass = mat.density * h * h * h / 8.0;
  for (int e = 0; e < E; ++e) {
    for (int a = 0; a < 8; ++a)
      m_mass.segment<3>(3 * m_grid.hexes[e][a]).array() += m_fill[e] * nodeMass;
  }

  m_fixedList = fixedNodesOf(m_rest);
  std::sort(m_fixedList.begin(), m_fixedList.end());
  m_fixedList.erase(std::unique(m_fixedList.begin(), m_fixedList.end()), m_fixedList.end());
  m_fixedInRegion = static_cast<long long>(m_fixedList.size());
  const std::vector<int> clamped = clampedSurfaceVertices(organ);
  if (config.clamp == Clamp::Cells) {
    // Pin every node carrying a clamped vertex: the clamp reaches up to a cell beyond the region.
    for (int v : clamped)
      for (int a = 0; a < 8; ++a)
        if (m_embedding.weights(v, a) > 1e-12) m_fixedList.push_back(m_embedding.nodeIds(v, a));
    std::sort(m_fixedList.begin(), m_fixedList.end());
    m_fixedList.erase(std::unique(m_fixedList.begin(), m_fixedList.end()), m_fixedList.end());
  }
  m_isFixed.assign(N, 0);
  for (int n : m_fixedList) {
    if (n < 0 || n >= N) throw InputError(where, "fixed", "fixed node index out of range");
    m_isFixed[n] = 1;
  }
  m_dofOfNode.assign(N, -1);
  m_numDofs = 0;
  for (int n = 0; n < N; ++n) {
    if (!m_isFixed[n]) {
      m_dofOfNode[n] = m_numDofs;
      m_numDofs += 3;
    }
  }

  // The grid sticks out of the organ by up to a cell, so the nodes inside the fixed region may
  // be few (or none) and the clamped surface vertices hang from free nodes (on the OpenHELP
  // kidney, bottom 15 mm fixed, 967 hexahedra, that surface moved 2.1 mm under a 10 mm lift).
  // Clamp::Points holds those vertices at their embedded rest positions by the penalty, as a
  // grasp holds its vertices (a vertex all of whose nodes are pinned needs nothing).
  m_kp = config.holdStiffness * m_K0.diagonal().maxCoeff();
  m_clampVerts.clear();
  if (config.clamp == Clamp::Points) {
    for (int v : clamped) {
      bool free = false;
      for (int a = 0; a < 8; ++a)
        free = free || (m_embedding.weights(v, a) > 1e-12 && !m_isFixed[m_embedding.nodeIds(v, a)]);
      if (free) m_clampVerts.push_back(v);
    }
  }
  m_clampTargets.resize(Eigen::Index(m_clampVerts.size()), 3);
  for (size_t k = 0; k < m_clampVerts.size(); ++k) {
    Vec3 p = Vec3::Zero();
    for (int a = 0; a < 8; ++a)
      p += m_embedding.weights(m_clampVerts[k], a) *
           m_rest.row(m_embedding.nodeIds(m_clampVerts[k], a)).transpose();
    m_clampTargets.row(Eigen::Index(k)) = p.transpose();
  }

  // Node -> element adjacency.
  m_nodeElemStart.assign(N + 1, 0);
  for (const auto& hex : m_grid.hexes) {
    for (int a = 0; a < 8; ++a) ++m_nodeElemStart[hex[a] + 1];
  }
  for (int n = 0; n < N; ++n) m_nodeElemStart[n + 1] += m_nodeElemStart[n];
  m_nodeElems.assign(m_nodeElemStart[N], 0);
  {
    std::vector<int> fill(m_nodeElemStart.begin(), m_nodeElemStart.end() - 1);
    for (int e = 0; e < E; ++e) {
      for (int a = 0; a < 8; ++a) m_nodeElems[fill[m_grid.hexes[e][a]]++] = e;
    }
  }

  m_c1 = 1 + dt * config.rayleighMass;
  m_c2 = dt * config.rayleighStiffness + dt * dt;
  m_R.assign(E, Mat3::Identity());
  m_q.assign(E, Quat::Identity());
  buildPattern();
  assembleValues(false);
  m_baseValues = Eigen::Map<const VecX>(m_A.valuePtr(), m_A.nonZeros());
  installCholmodAllocator();  // the factor on cached blocks (see sparse.h)
  m_chol.setKind(config.cholesky);
  if (m_numDofs > 0) {
    // Analysed once per model: worth trying every ordering CHOLMOD has (AMD, METIS, nested
    // dissection, ...) and keeping the one with the least fill, since every step solves with it.
    m_chol.cholmod().nmethods = config.tryAllOrderings ? 9 : 0;
    const SerialOpenMpScope serial;  // CHOLMOD's own OpenMP threads: see sparse.h
    m_chol.analyzePattern(m_A);
    if (m_chol.info() != Eigen::Success) {
      throw InputError(where, "fem_hex", "CHOLMOD could not analyse the system matrix");
    }
    // CHOLMOD's auto switch compares this ratio with supernodal_switch (history note).
    const cholmod_common& cc = m_chol.cholmod();
    m_flopsPerFactorNonZero = cc.lnz > 0 ? cc.fl / cc.lnz : 0.0;
  }

  m_isGrasped.assign(N, 0);
  m_carryCol.assign(N, -1);
  m_grasped.reserve(N);
  m_touched.reserve(E);
  m_elemMark.assign(E, 0);
  for (VecX* v : {&m_v0, &m_vOld, &m_dv, &m_r, &m_z, &m_p, &m_w, &m_fext}) v->setZero(3 * N);
  m_U.setZero(24, E);
  m_KU.setZero(24, E);
  m_rd.setZero(m_numDofs);
  m_zd.setZero(m_numDofs);
  m_totalMass = m_mass.sum() / 3.0;
  updateInverseDiagonal();
  const Box restBox = boundingBox(m_rest);
  m_restCenter = restBox.center();
  m_divergenceRadius = tol::kDivergenceBoxFactor * restBox.diagonal();
  m_surface.resize(organ.surface.numVertices(), 3);
  m_surfaceF = organ.surface.F;
  reset();
}

Counts HexFemModel::counts() const {
  return {{"elements", m_grid.numHexes()},
          {"nodes", m_grid.numNodes()},
          {"fixed_nodes", m_fixedInRegion},
          {"clamped_nodes", static_cast<long long>(m_fixedList.size())},
          {"held_clamped_vertices", static_cast<long long>(m_clampVerts.size())},
          {"dofs", m_numDofs},
          {"cholesky_factor_nonzeros", m_factorNonZeros},
          {"cholesky_flops_per_factor_nonzero", std::llround(m_flopsPerFactorNonZero)},
          {"cholesky_supernodal", m_chol.isSupernodal() ? 1 : 0},
          {"preconditioner_float32", m_chol.hasFloatFactor() && !m_chol.floatFactorIsHalf()},
          {"preconditioner_float16", m_chol.floatFactorIsHalf() ? 1 : 0}};
}

PhaseTimes HexFemModel::phaseTimes() const {
  return {{"assembly", m_msAssembly}, {"solve", m_msSolve}, {"surface", m_msSurface}};
}

NumericCounters HexFemModel::numericCounters() const {
  return {{"unconverged_steps", m_unconvergedSteps},
          {"rotation_not_converged", m_rotationNotConverged},
          {"rotation_svd_fallbacks", m_rotationSvd},
          {"rotation_iterations", m_rotationIterations},
          {"pcg_not_converged", m_pcgNotConverged},
          {"pcg_iterations", m_pcgIterations},
          {"preconditioner_refreshes", m_preconditionerRefreshes},
          {"ignored_grasp_nodes", m_ignoredGraspNodes},
          {"surface_vertices_outside_grid", m_embedding.outsidePoints}};
}

void HexFemModel::buildPattern() {
  const int E = m_grid.numHexes();
  std::vector<Triplet> trip;
  trip.reserve(static_cast<size_t>(E) * 300);
  for (const auto& hex : m_grid.hexes)
    forEachLowerEntry(hex, m_dofOfNode,
                      [&](int, int row, int col) { trip.emplace_back(row, col, 1.0); });
  m_A.resize(m_numDofs, m_numDofs);
  m_A.setFromTriplets(trip.begin(), trip.end());
  m_A.makeCompressed();
  auto position = [&](int row, int col) {
    const int* begin = m_A.innerIndexPtr() + m_A.outerIndexPtr()[col];
    const int* end = m_A.innerIndexPtr() + m_A.outerIndexPtr()[col + 1];
    const int* it = std::lower_bound(begin, end, row);
    return static_cast<int>(it - m_A.innerIndexPtr());
  };
  m_valueIndex.assign(static_cast<size_t>(E) * 576, -1);
  for (int e = 0; e < E; ++e)
    forEachLowerEntry(m_grid.hexes[e], m_dofOfNode, [&](int local, int row, int col) {
      m_valueIndex[static_cast<size_t>(e) * 576 + local] = position(row, col);
    });
  m_diagIndex.resize(m_numDofs);
  m_nodeOfDof.resize(m_numDofs);
  for (int n = 0; n < m_grid.numNodes(); ++n) {
    if (m_dofOfNode[n] < 0) continue;
    for (int i = 0; i < 3; ++i) {
      m_diagIndex[m_dofOfNode[n] + i] = position(m_dofOfNode[n] + i, m_dofOfNode[n] + i);
      m_nodeOfDof[m_dofOfNode[n] + i] = n;
    }
  }
}

int HexFemModel::valuePosition(int row, int col) const {
  const int* begin = m_A.innerIndexPtr() + m_A.outerIndexPtr()[col];
  const int* end = m_A.innerIndexPtr() + m_A.outerIndexPtr()[col + 1];
  return static_cast<int>(std::lower_bound(begin, end, row) - m_A.innerIndexPtr());
}

void HexFemModel::addHeldValues(const std::vector<int>& verts, Real s,
                                const std::vector<int>& axes) {
  // The nodes of one vertex are the corners of one hexahedron: every pair is in the pattern.
  Real* val = m_A.valuePtr();
  for (size_t q = 0; q < verts.size(); ++q) {
    const int v = verts[q];
    const int axis = axes.empty() ? -1 : axes[q];
    for (int a = 0; a < 8; ++a) {
      const int da = m_dofOfNode[m_embedding.nodeIds(v, a)];
      const Real wa = m_embedding.weights(v, a);
      if (da < 0 || wa == 0) continue;
      for (int b = 0; b < 8; ++b) {
        const int db = m_dofOfNode[m_embedding.nodeIds(v, b)];
        const Real wb = m_embedding.weights(v, b);
        if (db < 0 || wb == 0 || da < db) continue;  // lower triangle (da == db: the diagonal)
        for (int i = 0; i < 3; ++i)
          if (axis < 0 || i == axis) val[valuePosition(da + i, db + i)] += s * wa * wb;
      }
    }
  }
}

void HexFemModel::applyHeld(const VecX& in, Real scale, VecX& out) const {
  // axis >= 0: a sliding plate's vertex, penalised along that axis only.
  auto one = [&](int v, int axis) {
    Vec3 p = Vec3::Zero();
    for (int a = 0; a < 8; ++a)
      p += m_embedding.weights(v, a) * in.segment<3>(3 * m_embedding.nodeIds(v, a));
    if (axis >= 0) p = Vec3::Unit(axis) * p[axis];
    for (int a = 0; a < 8; ++a)
      out.segment<3>(3 * m_embedding.nodeIds(v, a)) += (scale * m_embedding.weights(v, a)) * p;
  };
  for (int v : m_clampVerts) one(v, -1);
  for (size_t k = 0; k < m_graspVerts.size(); ++k) one(m_graspVerts[k], m_graspVertAxis[k]);
}

void HexFemModel::addHeldResidual(const VecX& v0, VecX& out) const {
  const Real h = m_dt;
  auto one = [&](int v, const Vec3& t, int axis) {
    Vec3 p = Vec3::Zero();
    for (int a = 0; a < 8; ++a) {
      const int n = m_embedding.nodeIds(v, a);
      p += m_embedding.weights(v, a) * (m_x.row(n).transpose() + h * v0.segment<3>(3 * n));
    }
    Vec3 g = (h * m_kp) * (t - p);
    if (axis >= 0) g = Vec3::Unit(axis) * g[axis];
    for (int a = 0; a < 8; ++a)
      out.segment<3>(3 * m_embedding.nodeIds(v, a)) += m_embedding.weights(v, a) * g;
  };
  for (size_t k = 0; k < m_clampVerts.size(); ++k)
    one(m_clampVerts[k], m_clampTargets.row(Eigen::Index(k)).transpose(), -1);
  for (size_t k = 0; k < m_graspVerts.size(); ++k)
    one(m_graspVerts[k], m_graspVertTargets.row(Eigen::Index(k)).transpose(), m_graspVertAxis[k]);
}

void HexFemModel::assembleValues(bool rotated) {
  Real* val = m_A.valuePtr();
  std::fill(val, val + m_A.nonZeros(), 0.0);
  for (int d = 0; d < m_numDofs; ++d) val[m_diagIndex[d]] += m_c1 * m_mass[3 * m_nodeOfDof[d]];
  Mat24 Ke;
  for (int e = 0; e < m_grid.numHexes(); ++e) {
    if (rotated) {
      const Mat3& R = m_R[e];
      for (int a = 0; a < 8; ++a) {
        for (int b = 0; b < 8; ++b) {
          Ke.block<3, 3>(3 * a, 3 * b).noalias() =
              (m_c2 * m_fill[e]) * R * m_K0.block<3, 3>(3 * a, 3 * b) * R.transpose();
        }
      }
    } else {
      Ke = (m_c2 * m_fill[e]) * m_K0;
    }
    const int* idx = m_valueIndex.data() + static_cast<size_t>(e) * 576;
    for (int i = 0; i < 24; ++i) {
      for (int j = 0; j < 24; ++j) {
        const int p = idx[i * 24 + j];
        if (p >= 0) val[p] += Ke(i, j);
      }
    }
  }
  addHeldValues(m_clampVerts, m_dt * m_dt * m_kp);
}

void HexFemModel::factorize(bool withGrasps) {
  // The grasped points' penalty joins the values (the caller restored the grasp-free ones).
  if (withGrasps) addHeldValues(m_graspVerts, m_dt * m_dt * m_kp, m_graspVertAxis);
  {
    const SerialOpenMpScope serial;
    m_chol.factorize(m_A);
  }
  m_factorOk = m_chol.info() == Eigen::Success;
  const bool pcg =
      m_config.elastic == ElasticModel::Corotational && m_config.solver == CorotationalSolver::Pcg;
  if (pcg && m_config.preconditionerPrecision != PreconditionerPrecision::Float64) {
    m_chol.buildFloatFactor(m_config.preconditionerPrecision == PreconditionerPrecision::Float16
                                ? CholeskySolver::Precision::Float16
                                : CholeskySolver::Precision::Float32);  // none if it failed
  }
  m_factorNonZeros = static_cast<long long>(m_chol.cholmod().lnz);
  m_factorVerts = withGrasps ? m_graspVerts : std::vector<int>{};
}

bool HexFemModel::precondition(const VecX& r, VecX& z, bool approximate) {
  const int N = m_grid.numNodes();
  for (int n = 0; n < N; ++n) {
    const int d = m_dofOfNode[n];
    if (d >= 0) m_rd.segment<3>(d) = r.segment<3>(3 * n);
  }
  if (approximate && m_chol.hasFloatFactor()) {  // built only when the config asks for it
    m_chol.solveFloatInto(m_rd, m_zd);
  } else if (!m_chol.solveInto(m_rd, m_zd)) {
    return false;
  }
  for (int n = 0; n < N; ++n) {
    const int d = m_dofOfNode[n];
    if (d >= 0) {
      z.segment<3>(3 * n) = m_zd.segment<3>(d);
    } else {
      z.segment<3>(3 * n).setZero();
    }
  }
  return true;
}

void HexFemModel::filter(VecX& r) const {
  for (int n : m_fixedList) r.segment<3>(3 * n).setZero();
}

void HexFemModel::applyElements(const std::vector<int>* elems, const VecX& in, Real a, Real b,
                                Real scale, VecX& out) const {
  const bool rotated = m_config.elastic == ElasticModel::Corotational;
  if (!elems) {
    applyAllElements(in, a, b, scale, out, rotated);
    return;
  }
  const int count = static_cast<int>(elems->size());
  Vec24 local, f;
  for (int k = 0; k < count; ++k) {
    const int e = elems ? (*elems)[k] : k;
    const auto& hex = m_grid.hexes[e];
    gatherElement(hex, rotated ? &m_R[e] : nullptr, in, m_rest, a, b, local);
    f.noalias() = m_fill[e] * (m_K0 * local);
    if (rotated) {
      const Mat3& R = m_R[e];
      for (int i = 0; i < 8; ++i)
        out.segment<3>(3 * hex[i]).noalias() += scale * (R * f.segment<3>(3 * i));
    } else {
      for (int i = 0; i < 8; ++i) out.segment<3>(3 * hex[i]) += scale * f.segment<3>(3 * i);
    }
  }
}

void HexFemModel::applyAllElements(const VecX& in, Real a, Real b, Real scale, VecX& out,
                                   bool rotated) const {
  // Same as the per-element loop, but K0 is applied to all elements at once as one matrix product
  // (24 x 24 times 24 x E), several times faster than E matrix-vector products; the rotations'
  // gather and scatter on the same vector lanes (element_product.h).
  const int E = m_grid.numHexes();
  static_assert(sizeof(std::array<int, 8>) == 8 * sizeof(int) && sizeof(Mat3) == 9 * sizeof(Real));
  const int* hexes = E > 0 ? m_grid.hexes[0].data() : nullptr;
  const Real* R = E > 0 ? m_R[0].data() : nullptr;
  if (rotated) {
    gatherRotated(hexes, R, in.data(), m_restRows.data(), a, b, m_U.data(), E);
  } else {
    for (int e = 0; e < E; ++e)
      gatherElement(m_grid.hexes[e], nullptr, in, m_rest, a, b, m_U.col(e));
  }
  multiplyElements(m_K0.data(), m_U.data(), m_KU.data(), E);
  if (rotated) {
    scatterRotated(hexes, R, m_KU.data(), m_fill.data(), scale, out.data(), E);
    return;
  }
  for (int e = 0; e < E; ++e) {
    const auto& hex = m_grid.hexes[e];
    const auto f = m_KU.col(e);
    const Real s = scale * m_fill[e];
    for (int i = 0; i < 8; ++i) out.segment<3>(3 * hex[i]) += s * f.segment<3>(3 * i);
  }
}

void HexFemModel::updateInverseDiagonal() {
  m_invDiag = m_mass.cwiseInverse();
  for (int d = 0; d < m_numDofs; ++d) {
    m_invDiag[3 * m_nodeOfDof[d] + d % 3] = 1.0 / m_baseValues[m_diagIndex[d]];
  }
}

bool HexFemModel::updateRotations() {
  bool converged = true;
  const Mat38 G = hexShapeGradients(Vec3::Constant(m_grid.cellSize), Vec3::Zero());
  const int E = m_grid.numHexes();
  // F = sum_a x_a (grad N_a)^T into f (column-major), summed over the nodes in order.
  const auto gradientInto = [&](int e, double* f, int stride) {
    const auto& hex = m_grid.hexes[e];
    double sum[9] = {};  // summed in registers, then stored: the compiler cannot tell f from m_x
    for (int a = 0; a < 8; ++a) {
      const double* x = m_x.data() + 3 * hex[a];
      for (int j = 0; j < 3; ++j)
        for (int i = 0; i < 3; ++i) sum[i + 3 * j] += x[i] * G(j, a);
    }
    for (int k = 0; k < 9; ++k) f[k * stride] = sum[k];
  };
  const auto gradient = [&](int e) {
    Mat3 F;
    gradientInto(e, F.data(), 1);
    return F;
  };
  const auto extract = [&](int e, const Mat3& F) {
    const RotationExtraction r = extractRotationInfo(F, m_q[e], m_config.rotationIterations, 1e-9);
    m_rotationIterations += r.iterations;
    m_rotationSvd += r.svd ? 1 : 0;
    if (!r.converged) {
      ++m_rotationNotConverged;
      converged = false;
    }
    m_R[e] = rotationMatrixOf(m_q[e]);
  };
  // Blocks of L elements iterate on vector lanes (rotation_batch.h); an element that needs a
  // large step starts again on the scalar path, which gives the same bits.
  const int L = m_config.rotationIterations >= 1 ? rotationBatchLanes() : 1;
  int e0 = 0;
  if (L > 1) {
    constexpr int kMaxLanes = 8;
    double F[9 * kMaxLanes], q[4 * kMaxLanes], R[9 * kMaxLanes];
    signed char outcome[kMaxLanes];
    for (; e0 + L <= E; e0 += L) {
      for (int l = 0; l < L; ++l) {
        gradientInto(e0 + l, F + l, L);
        const Quat& ql = m_q[e0 + l];
        q[l] = ql.w(), q[L + l] = ql.x(), q[2 * L + l] = ql.y(), q[3 * L + l] = ql.z();
      }
      const bool finite = Eigen::Map<const Eigen::VectorXd>(F, 9 * L).allFinite() &&
                          Eigen::Map<const Eigen::VectorXd>(q, 4 * L).allFinite();
      if (finite) rotationSteps(F, q, R, outcome, 1e-9, m_config.rotationIterations);
      for (int l = 0; l < L; ++l) {
        const int e = e0 + l;
        if (!finite || outcome[l] == 0) {
          Mat3 Fl;
          for (int k = 0; k < 9; ++k) Fl.data()[k] = F[k * L + l];
          extract(e, Fl);
          continue;
        }
        m_rotationIterations += outcome[l] - 1;
        m_q[e] = Quat(q[l], q[L + l], q[2 * L + l], q[3 * L + l]);
        for (int k = 0; k < 9; ++k) m_R[e].data()[k] = R[k * L + l];
      }
    }
  }
  for (int e = e0; e < E; ++e) extract(e, gradient(e));
  return converged;
}

void HexFemModel::reset() {
  m_x = m_rest;
  m_v.setZero(3 * m_grid.numNodes());
  m_vOld.setZero(3 * m_grid.numNodes());  // no last change of velocity (step's projected start)
  m_firstReduction2 = 0;
  std::fill(m_q.begin(), m_q.end(), Quat::Identity());
  std::fill(m_R.begin(), m_R.end(), Mat3::Identity());
  for (int n : m_grasped) {
    m_isGrasped[n] = 0;
    m_carryCol[n] = -1;
  }
  m_grasped.clear();
  for (int e : m_touched) m_elemMark[e] = 0;
  m_touched.clear();
  m_touchedGrasped.clear();
  m_graspVerts.clear();
  m_graspVertOwner.clear();
  m_graspVertTargets.resize(0, 3);
  m_graspVertAxis.clear();
  m_graspForces.clear();
  m_lastIterations = 0;
  m_rotationNotConverged = m_pcgNotConverged = m_ignoredGraspNodes = m_pcgIterations = 0;
  m_rotationSvd = m_rotationIterations = m_unconvergedSteps = m_preconditionerRefreshes = 0;
  m_msAssembly = m_msSolve = m_msSurface = 0;
  if (m_numDofs > 0) {
    Eigen::Map<VecX>(m_A.valuePtr(), m_A.nonZeros()) = m_baseValues;
    factorize(false);
  }
  evaluateEmbedding(m_embedding, m_x, m_surface);
}

void HexFemModel::collectGrasps(const StepInput& in) {
  for (int n : m_grasped) {
    m_isGrasped[n] = 0;
    m_carryCol[n] = -1;
  }
  m_grasped.clear();
  // The grasped surface vertices (a vertex held by two grasps belongs to the first).
  m_graspVerts.clear();
  m_graspVertOwner.clear();
  m_graspVertAxis.clear();
  const Eigen::Index numVerts = m_embedding.nodeIds.rows();
  Eigen::Index rows = 0;
  for (const GraspInput& g : in.grasps) rows += Eigen::Index(g.vertices.size());
  m_graspVertTargets.resize(rows, 3);
  for (int g = 0; g < static_cast<int>(in.grasps.size()); ++g) {
    const GraspInput& grasp = in.grasps[size_t(g)];
    const int axis = slideAxis(grasp);
    if (grasp.sliding() && axis < 0)
      throw InputError("fem_hex", "grasp of tool " + std::to_string(grasp.tool),
                       "a sliding plate's normal must lie along x, y or z");
    for (size_t k = 0; k < grasp.vertices.size(); ++k) {
      const int v = grasp.vertices[k];
      if (v < 0 || v >= numVerts || static_cast<Eigen::Index>(k) >= grasp.targets.rows() ||
          std::find(m_graspVerts.begin(), m_graspVerts.end(), v) != m_graspVerts.end()) {
        ++m_ignoredGraspNodes;
        continue;
      }
      m_graspVertTargets.row(Eigen::Index(m_graspVerts.size())) =
          grasp.targets.row(Eigen::Index(k));
      m_graspVerts.push_back(v);
      m_graspVertOwner.push_back(g);
      m_graspVertAxis.push_back(axis);
    }
  }
  m_graspVertTargets.conservativeResize(Eigen::Index(m_graspVerts.size()), 3);
  // The nodes carrying them (contact leaves these alone, as the grasp holds them).
  for (int v : m_graspVerts)
    for (int a = 0; a < 8; ++a) {
      const int n = m_embedding.nodeIds(v, a);
      if (m_embedding.weights(v, a) > 1e-12 && !m_isFixed[n] && !m_isGrasped[n]) {
        m_isGrasped[n] = 1;
        m_grasped.push_back(n);
      }
    }
  std::sort(m_grasped.begin(), m_grasped.end());
  // Each carrying node's share of its reaction per grasp: the grasps' weights on it.
  for (size_t c = 0; c < m_grasped.size(); ++c) m_carryCol[m_grasped[c]] = int(c);
  m_carryShare.setZero(Eigen::Index(m_grasped.size()), Eigen::Index(in.grasps.size()));
  for (size_t k = 0; k < m_graspVerts.size(); ++k)
    for (int a = 0; a < 8; ++a) {
      const int c = m_carryCol[m_embedding.nodeIds(m_graspVerts[k], a)];
      if (c >= 0) m_carryShare(c, m_graspVertOwner[k]) += m_embedding.weights(m_graspVerts[k], a);
    }
  for (Eigen::Index c = 0; c < m_carryShare.rows(); ++c) {
    const Real sum = m_carryShare.row(c).sum();
    if (sum > 0) m_carryShare.row(c) /= sum;
  }
}

void HexFemModel::applyLoads(const StepInput& in) {
  const int N = m_grid.numNodes();
  // External forces: gravity on the lumped masses, point loads as J^T f: every per-vertex share
  // of the harness's patch through its vertex's trilinear weights (a load without a spread acts
  // on its vertex alone).
  for (int n = 0; n < N; ++n) m_fext.segment<3>(3 * n) = m_mass[3 * n] * in.gravity;
  const Eigen::Index numVerts = m_embedding.nodeIds.rows();
  auto addVertexForce = [&](int v, const Vec3& f) {
    if (v < 0 || v >= numVerts) return;
    for (int a = 0; a < 8; ++a)
      m_fext.segment<3>(3 * m_embedding.nodeIds(v, a)) += m_embedding.weights(v, a) * f;
  };
  for (const PointLoad& load : in.loads) {
    if (load.vertices.empty()) {
      addVertexForce(load.surfaceVertex, load.force);
      continue;
    }
    for (size_t k = 0; k < load.vertices.size() && k < load.weights.size(); ++k)
      addVertexForce(load.vertices[k], load.weights[k] * load.force);
  }
}

void HexFemModel::graspReactions(const StepInput& in, Real h) {
  const int N = m_grid.numNodes();
  Eigen::Map<const VecX> x(m_x.data(), 3 * N);
  // Reaction of each grasp on the tool: the residual of the tissue's own rows (inertia, elastic
  // and external forces, without the penalty) at the nodes carrying its vertices,
  // (b - A v+)_C / h, each node's share split between the grasps by their weights on it. For an
  // exact solve this is sum_v kp (J_v x+ - t_v); computed so, the CG solve's residual at the held
  // rows would reach the tool multiplied by kp (an ODE-driven grasper in
  // scenes/liver_instruments.json was flung 2 m away on closing).
  m_graspForces.assign(in.grasps.size(), Vec3::Zero());
  if (!m_grasped.empty()) {
    if (m_grasped != m_touchedGrasped) {
      m_touchedGrasped = m_grasped;
      for (int e : m_touched) m_elemMark[e] = 0;
      m_touched.clear();
      for (int n : m_grasped)
        for (int k = m_nodeElemStart[n]; k < m_nodeElemStart[n + 1]; ++k)
          if (!m_elemMark[m_nodeElems[k]]) {
            m_elemMark[m_nodeElems[k]] = 1;
            m_touched.push_back(m_nodeElems[k]);
          }
      std::sort(m_touched.begin(), m_touched.end());
    }
    m_w = h * x + m_c2 * m_v;
    for (int n : m_grasped) {
      m_z.segment<3>(3 * n) = m_mass.segment<3>(3 * n).cwiseProduct(m_vOld.segment<3>(3 * n) -
                                                                    m_c1 * m_v.segment<3>(3 * n)) +
                              h * m_fext.segment<3>(3 * n);
    }
    applyElements(&m_touched, m_w, 1.0, h, -1.0, m_z);
    for (int n : m_grasped) {
      const int c = m_carryCol[n];
      for (Eigen::Index g = 0; g < m_carryShare.cols(); ++g)
        m_graspForces[size_t(g)] += m_carryShare(c, g) * m_z.segment<3>(3 * n) / h;
    }
    // A sliding plate feels the normal component only (its carrying nodes are free along it).
    for (size_t g = 0; g < in.grasps.size(); ++g)
      if (const int axis = slideAxis(in.grasps[g]); axis >= 0)
        m_graspForces[g] = Vec3::Unit(axis) * m_graspForces[g][axis];
  }
}

StepStatus HexFemModel::step(const StepInput& in) {
  const auto t0 = Clock::now();
  const int N = m_grid.numNodes();
  const Real h = m_dt;
  if (in.dt != m_dt && in.dt > 0) {
    // A different step size changes the system matrix: rebuild its constant part.
    m_dt = in.dt;
    m_c1 = 1 + m_dt * m_config.rayleighMass;
    m_c2 = m_dt * m_config.rayleighStiffness + m_dt * m_dt;
    assembleValues(false);
    m_baseValues = Eigen::Map<const VecX>(m_A.valuePtr(), m_A.nonZeros());
    updateInverseDiagonal();
    m_factorVerts.assign(1, -1);  // force a refactorisation
    return step(in);
  }

  // The last step's change of velocity: CG's start is corrected along it (see below).
  m_dv = m_v - m_vOld;
  m_vOld = m_v;
  m_v0 = m_v;
  collectGrasps(in);

  applyLoads(in);

  const bool penalty = in.contact && in.contact->params().method == ContactMethod::Penalty;
  if (penalty)
    respondToContact(*in.contact, contactProxy(), ContactResponse::Penalty, h, m_fext.data());
  if (in.contact) m_stepStart = m_x;

  const bool corot = m_config.elastic == ElasticModel::Corotational;
  const bool rotationsOk = !corot || updateRotations();

  // The scale of the right-hand side for the CG stopping test: its inertia and load part
  // M v + h f_ext, filtered, in the D^-1 norm (see below).
  m_z = m_mass.cwiseProduct(m_vOld) + h * m_fext;
  filter(m_z);
  const Real loadScale2 = m_z.cwiseAbs2().cwiseProduct(m_invDiag).sum();

  // r = b - A v0 = M (v - c1 v0) + h f_ext - K_R (h x + c2 v0 - h X)
  //               + h kp J_H^T (t - J_H (x + h v0)), filtered.
  Eigen::Map<const VecX> x(m_x.data(), 3 * N);
  m_r = m_mass.cwiseProduct(m_vOld - m_c1 * m_v0) + h * m_fext;
  m_w = h * x + m_c2 * m_v0;
  applyElements(nullptr, m_w, 1.0, h, -1.0, m_r);
  addHeldResidual(m_v0, m_r);
  filter(m_r);
  const bool refactorEveryStep = corot && m_config.solver == CorotationalSolver::Refactor;
  if (refactorEveryStep && m_numDofs > 0) assembleValues(true);
  m_msAssembly = msSince(t0);

  const auto t1 = Clock::now();
  bool ok = true, solveConverged = true;
  m_v = m_v0;
  m_lastIterations = 0;
  if (m_numDofs > 0) {
    // The factor holds the grasped points' penalty: refactorised when the grasped set changes
    // (a grasp closing or opening), every step by the refactoring solver.
    if (refactorEveryStep) {
      factorize(true);
    } else if (m_graspVerts != m_factorVerts) {
      Eigen::Map<VecX>(m_A.valuePtr(), m_A.nonZeros()) = m_baseValues;
      factorize(true);
    }
    ok = m_factorOk;
    if (ok && (!corot || refactorEveryStep)) {
      ok = precondition(m_r, m_z);
      m_v += m_z;
    } else if (ok) {
      // CG on the filtered system, preconditioned by the rest (linear) system's Cholesky factor.
      // Relative stopping test, so it does not depend on units, stiffness or mass:
      //   r^T D^-1 r <= tol^2 max(b_l^T D^-1 b_l, r0^T D^-1 r0)
      // with D the diagonal of the rest system, b_l = M v + h f_ext the inertia and load part of
      // the right-hand side and r0 the warm start's residual. (b_l, not the whole right-hand
      // side, whose load and elastic parts cancel at equilibrium.) At least one iteration is
      // always taken: a warm start never passes for a solve.
      auto residual2 = [&] { return m_r.cwiseAbs2().cwiseProduct(m_invDiag).sum(); };
      Real res2 = residual2();
      if (!std::isfinite(res2)) ok = false;
      const Real tol2 = m_config.pcgTolerance * m_config.pcgTolerance * std::max(loadScale2, res2);
      bool converged = false;
      // w = A p on the filtered system: inertia, elasticity at the current rotations, the held
      // points' penalty.
      const auto applySystem = [&](const VecX& p, VecX& w) {
        w = m_c1 * m_mass.cwiseProduct(p);
        applyElements(nullptr, p, 1.0, 0.0, m_c2, w);
        applyHeld(p, h * h * m_kp, w);
        filter(w);
      };
      // Where one preconditioned iteration from v0 (the last step's velocity) would not reach
      // the tolerance (the last step's first iteration reduced the residual by this factor), v0
      // is corrected along the last step's change of velocity dv by the step that minimises the
      // error's energy norm, gamma = dv^T r / dv^T A dv: in a smooth motion (gamma near 1, a
      // linear extrapolation) one iteration then reaches the tolerance where two were needed;
      // where the motion is not smooth gamma shrinks, and the start is never worse than v0 in
      // that norm. It costs one product with A, so it is skipped where one iteration suffices.
      // The stopping test stays relative to v0's residual: the accuracy asked is the same.
      if (ok && m_config.pcgProjectedStart && res2 * m_firstReduction2 > tol2) {
        filter(m_dv);
        applySystem(m_dv, m_w);
        const Real dAd = m_dv.dot(m_w);
        if (dAd > 0 && std::isfinite(dAd)) {
          const Real gamma = m_dv.dot(m_r) / dAd;
          m_v += gamma * m_dv;
          m_r -= gamma * m_w;
          res2 = residual2();
        }
      }
      // Conjugate gradients from the current m_v and residual m_r, up to pcg_max_iterations.
      const auto cg = [&] {
        Real rz = 0;
        for (int it = 0; ok && !converged && it < m_config.pcgMaxIterations; ++it) {
          ok = precondition(m_r, m_z, true);
          const Real rzNew = m_r.dot(m_z);
          if (it == 0) {
            m_p = m_z;
          } else {
            m_p = m_z + (rzNew / rz) * m_p;
          }
          rz = rzNew;
          applySystem(m_p, m_w);
          const Real pq = m_p.dot(m_w);
          if (!(pq > 0) || !std::isfinite(pq)) {
            ok = std::isfinite(pq);
            converged = res2 == 0;  // nothing to solve (no load, at rest)
            break;
          }
          const Real alpha = rz / pq;
          m_v += alpha * m_p;
          m_r -= alpha * m_w;
          ++m_lastIterations;
          const Real before = res2;
          res2 = residual2();
          if (it == 0 && before > 0) m_firstReduction2 = res2 / before;
          converged = res2 <= tol2;
        }
      };
      cg();
      if (ok && !converged) {
        // The factor is of a system whose element rotations are far from the current ones
        // (nearly incompressible tissue makes CG sensitive to small rotations: the truth cube
        // at nu 0.4999 failed 198 of 1065 steps with the rest factor). Refactorise the system
        // at the current rotations, continue from where CG stopped, and keep that factor for
        // the next steps (until a grasp changes or CG gives up again).
        assembleValues(true);
        factorize(true);
        ++m_preconditionerRefreshes;
        ok = m_factorOk;
        cg();
      }
      if (ok && !converged) {
        ++m_pcgNotConverged;
        solveConverged = false;
      }
      m_pcgIterations += m_lastIterations;
    }
  }

  // A step whose rotations or CG solve gave up is not the step the scene asked for: the harness
  // reads unconverged_steps into validity.
  if (!rotationsOk || !solveConverged) ++m_unconvergedSteps;

  graspReactions(in, h);

  // Advance positions.
  Eigen::Map<VecX>(m_x.data(), 3 * N) += h * m_v;
  if (in.contact && !penalty) {
    // Contact on the embedded surface triangles, spread to the grid nodes by the barycentric and
    // trilinear weights; fixed and grasped nodes do not move.
    m_contactInvMass.resize(N);
    for (int n = 0; n < N; ++n)
      m_contactInvMass[n] =
          (m_isFixed[n] || m_isGrasped[n] || !(m_mass[3 * n] > 0)) ? 0.0 : 1.0 / m_mass[3 * n];
    respondToContact(*in.contact, contactProxy(), ContactResponse::Project, h);
  }
  m_msSolve = msSince(t1);

  const auto t2 = Clock::now();
  evaluateEmbedding(m_embedding, m_x, m_surface);
  m_msSurface = msSince(t2);

  if (!ok || !m_x.allFinite()) return StepStatus::Diverged;
  for (int n = 0; n < N; ++n) {
    if ((m_x.row(n).transpose() - m_restCenter).norm() > m_divergenceRadius) {
      return StepStatus::Diverged;
    }
  }
  return StepStatus::Ok;
}

}  // namespace deform::fem_hex
