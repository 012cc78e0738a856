// FemSystem (fem_solver.h): the P1/P2 tet mesh, its materials, energy, gradient and stiffness;
// the parameter parsers of its choices.
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

std::array<Vec3, 4> gather(const VecX& x, const Vec4i& t) {
  std::array<Vec3, 4> p;
  for (int k = 0; k < 4; ++k) p[k] = x.segment<3>(3 * t(k));
  return p;
}

}  // namespace

MaterialModel parseMaterialModel(const std::string& name) {
  if (name == "linear") return MaterialModel::Linear;
  if (name == "corotational") return MaterialModel::Corotational;
  if (name == "neo_hookean") return MaterialModel::NeoHookean;
  throw InputError("", "params.material",
                   "unknown material '" + name + "' (linear | corotational | neo_hookean)");
}

const char* materialModelName(MaterialModel m) {
  switch (m) {
    case MaterialModel::Linear:
      return "linear";
    case MaterialModel::Corotational:
      return "corotational";
    case MaterialModel::NeoHookean:
      return "neo_hookean";
  }
  return "?";
}

// ---- FemSystem ------------------------------------------------------------------------------

VolumetricChoice parseVolumetricChoice(const std::string& name) {
  if (name == "auto") return VolumetricChoice::Auto;
  if (name == "displacement") return VolumetricChoice::Displacement;
  if (name == "mean_dilatation") return VolumetricChoice::MeanDilatation;
  throw InputError(
      "", "params.volumetric",
      "unknown volumetric formulation '" + name + "' (auto | displacement | mean_dilatation)");
}

VolumetricFormulation resolveVolumetricFormulation(VolumetricChoice choice, MaterialModel model,
                                                   ElementOrder order, Real poisson) {
  const bool applies = model == MaterialModel::NeoHookean && order == ElementOrder::Quadratic;
  switch (choice) {
    case VolumetricChoice::Displacement:
      return VolumetricFormulation::Displacement;
    case VolumetricChoice::MeanDilatation:
      if (!applies)
        throw InputError("", "params.volumetric",
                         "mean_dilatation needs material neo_hookean and element_order 2 (got " +
                             std::string(materialModelName(model)) + ", element_order " +
                             std::to_string(int(order)) + ")");
      return VolumetricFormulation::MeanDilatation;
    case VolumetricChoice::Auto:
      break;
  }
  return applies && poisson >= kNearlyIncompressiblePoisson ? VolumetricFormulation::MeanDilatation
                                                            : VolumetricFormulation::Displacement;
}

const char* volumetricFormulationName(VolumetricFormulation f) {
  return f == VolumetricFormulation::MeanDilatation ? "mean_dilatation" : "displacement";
}

ElementOrder parseElementOrder(long long order) {
  if (order == 1) return ElementOrder::Linear;
  if (order == 2) return ElementOrder::Quadratic;
  throw InputError(
      "", "params.element_order",
      "element order must be 1 (4-node tets) or 2 (10-node tets), got " + std::to_string(order));
}

FemSystem::FemSystem(TetMesh rest, const Material& material, MaterialModel model,
                     CorotationalTangent corotationalTangent)
    : FemSystem(std::move(rest), material, model, ElementOrder::Linear, corotationalTangent) {}

FemSystem::FemSystem(TetMesh rest, const Material& material, MaterialModel model,
                     ElementOrder order, VolumetricFormulation volumetric)
    : FemSystem(std::move(rest), material, model, order, CorotationalTangent::Exact) {
  if (volumetric == VolumetricFormulation::MeanDilatation)
    resolveVolumetricFormulation(VolumetricChoice::MeanDilatation, model, order,
                                 material.poisson);  // throws unless Neo-Hookean P2
  m_volumetric = volumetric;
  m_meanDilatation = MeanDilatationNeoHookean::fromLame(m_lame);
}

void FemSystem::addMidsideNodes() {
  QuadraticTetNodes q = deform::addMidsideNodes(m_rest);  // deform/geometry/organ_tets.h
  m_edges = std::move(q.edges);
  m_rest.V = std::move(q.V);
  for (int t = 0; t < m_rest.numTets(); ++t)
    for (int a = 4; a < 10; ++a) m_elemNodes[size_t(10 * t + a)] = q.elements(t, a);
}

int FemSystem::edgeNode(int a, int b) const {
  const std::pair<int, int> key(std::min(a, b), std::max(a, b));
  const auto it = std::lower_bound(m_edges.begin(), m_edges.end(), key);
  if (it == m_edges.end() || *it != key) return -1;
  return m_numCorners + int(it - m_edges.begin());
}

FemSystem::FemSystem(TetMesh rest, const Material& material, MaterialModel model,
                     ElementOrder order, CorotationalTangent corotationalTangent)
    : m_rest(std::move(rest)),
      m_material(material),
      m_model(model),
      m_order(order),
      m_lame(LameParameters::fromYoungPoisson(material.young, material.poisson)),
      m_corotationalTangent(corotationalTangent),
      m_numCorners(m_rest.numVertices()) {
  const int nt = m_rest.numTets(), nen = nodesPerElement();
  m_elemNodes.resize(size_t(nt * nen));
  for (int t = 0; t < nt; ++t)
    for (int a = 0; a < 4; ++a) m_elemNodes[size_t(nen * t + a)] = m_rest.T(t, a);
  if (order == ElementOrder::Quadratic) addMidsideNodes();
  const int n = m_rest.numVertices();
  m_elements.resize(size_t(nt));
  if (order == ElementOrder::Quadratic) m_quadElements.resize(size_t(nt));
  m_mass = VecX::Zero(n);
  m_gravityWeight = VecX::Zero(n);
  std::vector<std::vector<int>> nbrs(static_cast<size_t>(n));
  for (int t = 0; t < nt; ++t) {
    const Vec4i tet = m_rest.T.row(t).transpose();
    TetRest& r = m_elements[size_t(t)];
    if (!makeTetRest(m_rest.V.row(tet(0)), m_rest.V.row(tet(1)), m_rest.V.row(tet(2)),
                     m_rest.V.row(tet(3)), r)) {
      ++m_degenerate;
      continue;
    }
    const Real m = material.density * r.volume;
    if (order == ElementOrder::Quadratic) m_quadElements[size_t(t)] = makeQuadraticTetRest(r);
    for (int a = 0; a < nen; ++a) {
      const int na = m_elemNodes[size_t(nen * t + a)];
      if (order == ElementOrder::Quadratic) {
        m_mass(na) += m * (a < 4 ? kQuadraticCornerMass : kQuadraticMidsideMass);
        m_gravityWeight(na) += m * (a < 4 ? kQuadraticCornerShare : kQuadraticMidsideShare);
      } else {
        m_mass(na) += m / 4.0;
        m_gravityWeight(na) += m / 4.0;
      }
      for (int b = 0; b < nen; ++b) nbrs[size_t(na)].push_back(m_elemNodes[size_t(nen * t + b)]);
    }
  }
  for (int i = 0; i < n; ++i) {  // every node couples to itself (isolated nodes too)
    auto& v = nbrs[size_t(i)];
    v.push_back(i);
    std::sort(v.begin(), v.end());
    v.erase(std::unique(v.begin(), v.end()), v.end());
  }
  // Full symmetric 3N x 3N pattern: column (3 b + kb) holds rows 3 a + ka for a in nbrs[b].
  m_pattern.resize(3 * n, 3 * n);
  long long nnz = 0;
  for (int i = 0; i < n; ++i) nnz += 9LL * nbrs[size_t(i)].size();
  m_pattern.resizeNonZeros(Eigen::Index(nnz));
  int* outer = m_pattern.outerIndexPtr();
  int* inner = m_pattern.innerIndexPtr();
  int pos = 0;
  for (int b = 0; b < n; ++b)
    for (int kb = 0; kb < 3; ++kb) {
      outer[3 * b + kb] = pos;
      for (int a : nbrs[size_t(b)])
        for (int ka = 0; ka < 3; ++ka) inner[pos++] = 3 * a + ka;
    }
  outer[3 * n] = pos;
  std::fill(m_pattern.valuePtr(), m_pattern.valuePtr() + nnz, 0.0);
  const int nd = 3 * nen;  // element dofs
  m_slots.assign(size_t(nt) * size_t(nd * nd), 0);
  for (int t = 0; t < nt; ++t) {
    if (!(m_elements[size_t(t)].volume > 0)) continue;
    int* slot = m_slots.data() + size_t(t) * size_t(nd * nd);
    for (int bj = 0; bj < nen; ++bj) {
      const int nb = m_elemNodes[size_t(nen * t + bj)];
      const auto& col = nbrs[size_t(nb)];
      for (int ai = 0; ai < nen; ++ai) {
        const int na = m_elemNodes[size_t(nen * t + ai)];
        const int off = int(std::lower_bound(col.begin(), col.end(), na) - col.begin());
        for (int kb = 0; kb < 3; ++kb)
          for (int ka = 0; ka < 3; ++ka)
            slot[(3 * bj + kb) * nd + 3 * ai + ka] = outer[3 * nb + kb] + 3 * off + ka;
      }
    }
  }
}

template <class Fn>
void FemSystem::forEachMaterial(Fn&& fn) const {
  switch (m_model) {
    case MaterialModel::Linear:
      fn(LinearMaterial{m_lame});
      break;
    case MaterialModel::Corotational:
      fn(CorotationalMaterial{m_lame, m_corotationalTangent});
      break;
    case MaterialModel::NeoHookean:
      fn(NeoHookeanMaterial{m_lame});
      break;
  }
}

VecX FemSystem::restPositions() const {
  return Eigen::Map<const VecX>(MatX3(m_rest.V).data(), 3 * numNodes());
}

namespace {

Mat3x10 gatherQuadratic(const VecX& x, const int* nodes) {
  Mat3x10 p;
  for (int a = 0; a < 10; ++a) p.col(a) = x.segment<3>(3 * nodes[a]);
  return p;
}

}  // namespace

template <class Mat>
void FemSystem::evaluateQuadratic(const Mat& mat, int t, const VecX& x, TetEvalMode mode,
                                  QuadraticTetEvaluation& e, bool projectSpd) const {
  const Mat3x10 xe = gatherQuadratic(x, &m_elemNodes[size_t(10 * t)]);
  if (m_volumetric == VolumetricFormulation::MeanDilatation)
    evaluateMeanDilatationTet(m_meanDilatation, m_quadElements[size_t(t)], xe, mode, e, projectSpd);
  else
    evaluateQuadraticTet(mat, m_quadElements[size_t(t)], xe, mode, e, projectSpd);
}

Real FemSystem::stiffestModulus() const {
  if (m_material.poisson >= kNearlyIncompressiblePoisson)
    return std::max(m_material.young, m_lame.bulk());
  return m_material.young;
}

Real FemSystem::elasticEnergy(const VecX& x) const {
  Real W = 0;
  forEachMaterial([&](const auto& mat) {
    if (m_order == ElementOrder::Quadratic) {
      QuadraticTetEvaluation e;
      for (int t = 0; t < m_rest.numTets(); ++t) {
        if (!(m_elements[size_t(t)].volume > 0)) continue;
        evaluateQuadratic(mat, t, x, TetEvalMode::Energy, e, false);
        W += e.energy;
      }
      return;
    }
    TetEvaluation e;
    for (int t = 0; t < m_rest.numTets(); ++t) {
      const TetRest& r = m_elements[size_t(t)];
      if (!(r.volume > 0)) continue;
      evaluateTet(mat, r, gather(x, m_rest.T.row(t).transpose()), TetEvalMode::Energy, e);
      W += e.energy;
    }
  });
  return W;
}

Real FemSystem::elasticGradient(const VecX& x, VecX& g) const {
  g.setZero(3 * numNodes());
  Real W = 0;
  forEachMaterial([&](const auto& mat) {
    if (m_order == ElementOrder::Quadratic) {
      QuadraticTetEvaluation e;
      for (int t = 0; t < m_rest.numTets(); ++t) {
        if (!(m_elements[size_t(t)].volume > 0)) continue;
        const int* nodes = &m_elemNodes[size_t(10 * t)];
        evaluateQuadratic(mat, t, x, TetEvalMode::Gradient, e, false);
        if (!std::isfinite(e.energy)) {  // inverted at a quadrature point: no stress defined
          g.setConstant(std::numeric_limits<Real>::quiet_NaN());
          W = std::numeric_limits<Real>::infinity();
          return;
        }
        W += e.energy;
        for (int a = 0; a < 10; ++a) g.segment<3>(3 * nodes[a]) += e.gradient.segment<3>(3 * a);
      }
      return;
    }
    TetEvaluation e;
    for (int t = 0; t < m_rest.numTets(); ++t) {
      const TetRest& r = m_elements[size_t(t)];
      if (!(r.volume > 0)) continue;
      const Vec4i tet = m_rest.T.row(t).transpose();
      evaluateTet(mat, r, gather(x, tet), TetEvalMode::Gradient, e);
      W += e.energy;
      if (!std::isfinite(e.energy)) continue;  // inverted: no stress (e.gradient is not set)
      for (int a = 0; a < 4; ++a) g.segment<3>(3 * tet(a)) += e.gradient.segment<3>(3 * a);
    }
  });
  return W;
}

void FemSystem::stiffnessValues(const VecX& x, VecX& values, bool projectSpd) const {
  values.setZero(m_pattern.nonZeros());
  const int nd = 3 * nodesPerElement(), nn = nd * nd;
  forEachElementStiffness(
      x, projectSpd,
      [&](int t, const Real* k) {
        const int* slot = m_slots.data() + size_t(t) * size_t(nn);
        for (int i = 0; i < nn; ++i) values(slot[i]) += k[i];
      },
      [](int) { return true; });
}

void FemSystem::stiffnessValues(const VecX& x, Eigen::Ref<VecX> values, bool projectSpd,
                                const int* slots) const {
  values.setZero();
  const int nd = 3 * nodesPerElement(), np = nd * (nd + 1) / 2;
  forEachElementStiffness(
      x, projectSpd,
      [&](int t, const Real* k) {
        const int* slot = slots + size_t(t) * size_t(np);
        for (int c = 0; c < nd; ++c, k += nd)
          for (int r = c; r < nd; ++r, ++slot)
            if (*slot >= 0) values(*slot) += k[r];
      },
      [](int) { return true; });
}

void FemSystem::stiffnessTimes(const VecX& x, const VecX& v, VecX& out) const {
  out.setZero(3 * numNodes());
  const int nen = nodesPerElement(), nd = 3 * nen;
  VecX ve(nd), ke(nd);
  forEachElementStiffness(
      x, false,
      [&](int t, const Real* k) {
        for (int a = 0; a < nen; ++a) ve.segment<3>(3 * a) = v.segment<3>(3 * elementNode(t, a));
        ke.noalias() = Eigen::Map<const MatX>(k, nd, nd) * ve;
        for (int a = 0; a < nen; ++a) out.segment<3>(3 * elementNode(t, a)) += ke.segment<3>(3 * a);
      },
      [&](int t) {
        for (int a = 0; a < nen; ++a)
          if ((v.segment<3>(3 * elementNode(t, a)).array() != 0).any()) return true;
        return false;
      });
}

template <class Sink, class Want>
void FemSystem::forEachElementStiffness(const VecX& x, bool projectSpd, Sink&& sink,
                                        Want&& want) const {
  forEachMaterial([&](const auto& mat) {
    if (m_order == ElementOrder::Quadratic) {
      QuadraticTetEvaluation e;
      for (int t = 0; t < m_rest.numTets(); ++t) {
        if (!(m_elements[size_t(t)].volume > 0) || !want(t)) continue;
        evaluateQuadratic(mat, t, x, TetEvalMode::Stiffness, e, projectSpd);
        if (!std::isfinite(e.energy)) continue;  // inverted: contributes nothing
        sink(t, e.stiffness.data());             // column-major, matches the slot order
      }
      return;
    }
    TetEvaluation e;
    for (int t = 0; t < m_rest.numTets(); ++t) {
      const TetRest& r = m_elements[size_t(t)];
      if (!(r.volume > 0) || !want(t)) continue;
      evaluateTet(mat, r, gather(x, m_rest.T.row(t).transpose()), TetEvalMode::Stiffness, e,
                  projectSpd);
      sink(t, e.stiffness.data());
    }
  });
}

VecX FemSystem::externalForce(const LoadCase& loads) const {
  VecX f(3 * numNodes());
  for (int i = 0; i < numNodes(); ++i) f.segment<3>(3 * i) = m_gravityWeight(i) * loads.gravity;
  for (const auto& [node, force] : loads.nodeForces) f.segment<3>(3 * node) += force;
  return f;
}

}  // namespace deform::reference_fem
