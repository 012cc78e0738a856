#include "coarse_fem.h"

#include <deform/kernels/fem_tet.h>
#include <deform/sdk/error.h>

#include <algorithm>

namespace deform::hybrid_fem_pbd {

void CoarseLinearFem::init(const TetMesh& mesh, const Material& material,
                           const std::vector<int>& fixed, const std::string& source) {
  m_numNodes = mesh.numVertices();
  m_dof.assign(3 * m_numNodes, -1);
  std::vector<char> pinned(m_numNodes, 0);
  for (int v : fixed)
    if (v >= 0 && v < m_numNodes) pinned[v] = 1;
  m_numFree = 0;
  for (int v = 0; v < m_numNodes; ++v)
    if (!pinned[v])
      for (int a = 0; a < 3; ++a) m_dof[3 * v + a] = m_numFree++;
  m_columns.clear();
  m_gravityU.resize(0);
  m_gravity.setZero();
  m_rowKey.clear();
  m_degenerate = 0;
  m_nodeMass = VecX::Zero(m_numNodes);

  const LinearMaterial lin{LameParameters::fromYoungPoisson(material.young, material.poisson)};
  std::vector<Triplet> trip;
  trip.reserve(static_cast<size_t>(mesh.numTets()) * 78);
  for (int t = 0; t < mesh.numTets(); ++t) {
    std::array<Vec3, 4> X;
    for (int k = 0; k < 4; ++k) X[k] = mesh.V.row(mesh.T(t, k)).transpose();
    TetRest rest;
    if (!makeTetRest(X[0], X[1], X[2], X[3], rest)) {
      ++m_degenerate;
      continue;
    }
    for (int k = 0; k < 4; ++k) m_nodeMass[mesh.T(t, k)] += material.density * rest.volume / 4;
    TetEvaluation e;
    evaluateTet(lin, rest, X, TetEvalMode::Stiffness, e);
    for (int i = 0; i < 12; ++i) {
      const int di = m_dof[3 * mesh.T(t, i / 3) + i % 3];
      if (di < 0) continue;
      for (int j = 0; j < 12; ++j) {
        const int dj = m_dof[3 * mesh.T(t, j / 3) + j % 3];
        if (dj < 0 || dj > di) continue;  // lower triangle only
        trip.emplace_back(di, dj, e.stiffness(i, j));
      }
    }
  }
  if (m_degenerate > 0) {
    throw InputError(source, "hybrid coarse volume mesh",
                     std::to_string(m_degenerate) + " degenerate or inverted tetrahedra");
  }
  m_K.resize(m_numFree, m_numFree);
  m_K.setFromTriplets(trip.begin(), trip.end());
  m_regularised = fixed.empty();
  if (m_regularised && m_numFree > 0) {
    const Real eps = 1e-8 * m_K.diagonal().mean();
    for (int i = 0; i < m_numFree; ++i) m_K.coeffRef(i, i) += eps;
  }
  installCholmodAllocator();  // the factor on cached blocks (see sparse.h)
  m_chol = std::make_unique<SparseCholesky>();
  if (m_numFree > 0) {
    const SerialOpenMpScope serial;  // CHOLMOD's own OpenMP threads: see sparse.h
    m_chol->compute(m_K);
    if (m_chol->info() != Eigen::Success)
      throw InputError(source, "hybrid coarse volume mesh",
                       "the stiffness matrix could not be factorised");
  }
}

const MatX& CoarseLinearFem::nodeColumns(int node) {
  auto it = m_columns.find(node);
  if (it != m_columns.end()) return it->second;
  if (m_columns.size() >= kColumnCacheSize) m_columns.clear();  // bounded; recomputed on demand
  MatX rhs = MatX::Zero(m_numFree, 3);
  for (int a = 0; a < 3; ++a) {
    const int d = m_dof[3 * node + a];
    if (d >= 0) rhs(d, a) = 1;
  }
  MatX cols = m_numFree > 0 ? MatX(m_chol->solve(rhs)) : rhs;
  return m_columns.emplace(node, std::move(cols)).first->second;
}

void CoarseLinearFem::setOutputNodes(int count) {
  m_outputNodes = count < 0 ? -1 : std::min(count, m_numNodes);
  m_outDofs.clear();
  if (m_outputNodes >= 0)
    for (int v = 0; v < m_outputNodes; ++v)
      for (int a = 0; a < 3; ++a)
        if (m_dof[3 * v + a] >= 0) m_outDofs.push_back(m_dof[3 * v + a]);
  m_rowKey.clear();  // rebuild Z (and its output rows) at the next solve
}

void CoarseLinearFem::setSinglePrecisionResponse(bool on) {
  m_floatResponse = on;
  m_rowKey.clear();  // rebuild the output rows at the next solve
}

void CoarseLinearFem::solve(const std::vector<NodalForce>& forces, const Vec3& gravity,
                            const std::vector<Prescribed>& prescribed, MatX3& u,
                            std::vector<Vec3>* reactions) {
  VecX& x = m_scratch;
  x.setZero(m_numFree);
  if (!gravity.isZero()) {
    if (gravity != m_gravity || m_gravityU.size() != m_numFree) {
      VecX f = VecX::Zero(m_numFree);
      for (int v = 0; v < m_numNodes; ++v)
        for (int a = 0; a < 3; ++a)
          if (m_dof[3 * v + a] >= 0) f[m_dof[3 * v + a]] = m_nodeMass[v] * gravity[a];
      m_gravityU = m_numFree > 0 ? VecX(m_chol->solve(f)) : f;
      m_gravity = gravity;
    }
    x = m_gravityU;
  }
  // Nodal forces through each node's column of K^-1 (cached): a few solves, once. A load on more
  // nodes than the cache holds (a pressure patch of a few cm on a liver's coarse mesh) would
  // clear and refill it, one solve per node, every step: one solve of the assembled forces then.
  size_t loaded = 0;
  for (const NodalForce& nf : forces) loaded += nf.force.isZero() ? 0 : 1;
  if (loaded > kColumnCacheSize && m_numFree > 0) {
    VecX& f = m_forceScratch;
    f.setZero(m_numFree);
    for (const NodalForce& nf : forces)
      for (int a = 0; a < 3; ++a) {
        const int d = m_dof[3 * nf.node + a];
        if (d >= 0) f[d] += nf.force[a];
      }
    x.noalias() += m_chol->solve(f);
  } else {
    for (const NodalForce& nf : forces) {
      if (nf.force.isZero()) continue;
      x.noalias() += nodeColumns(nf.node) * nf.force;
    }
  }

  // Prescribed rows: rebuild Z and S only when the rows (nodes, weights, axes) change.
  std::vector<std::array<Real, 8>>& key = m_keyScratch;
  key.clear();
  for (const Prescribed& p : prescribed) {
    std::array<Real, 8> k = {Real(p.at.count), -1, -1, -1, 0, 0, 0, Real(p.axes)};
    for (int i = 0; i < p.at.count; ++i) {
      k[1 + i] = p.at.nodes[i];
      k[4 + i] = p.at.weights[i];
    }
    key.push_back(k);
  }
  if (key != m_rowKey) {
    m_rowKey = key;
    buildPrescribedRows(prescribed);
  }
  if (reactions) reactions->assign(prescribed.size(), Vec3::Zero());
  if (!m_rowAt.empty()) {
    // Rows in the same order as built: one per prescribed entry and free axis.
    VecX& rhs = m_rhs;
    rhs.resize(static_cast<Eigen::Index>(m_rowAt.size()));
    size_t r = 0;
    for (const Prescribed& p : prescribed)
      for (int a = 0; a < 3; ++a) {
        if (r >= m_rowAt.size()) break;
        if (!(p.axes & (1 << a))) continue;
        bool anyFree = false;
        for (int i = 0; i < p.at.count; ++i) anyFree |= m_dof[3 * p.at.nodes[i] + a] >= 0;
        if (!anyFree) continue;
        Real cu = 0;
        for (int i = 0; i < p.at.count; ++i) {
          const int d = m_dof[3 * p.at.nodes[i] + a];
          if (d >= 0) cu += p.at.weights[i] * x[d];
        }
        rhs[r++] = p.displacement[a] - cu;
      }
    m_lambda = m_S.solve(rhs);
    if (m_outputNodes >= 0 && m_floatResponse) {
      m_zl.resize(m_ZoutF.paddedRows());
      m_ZoutF.multiply(m_lambda.data(), m_zl.data());
      for (size_t k = 0; k < m_outDofs.size(); ++k) x[m_outDofs[k]] += m_zl[k];
    } else if (m_outputNodes >= 0) {
      m_zl.noalias() = m_Zout * m_lambda;
      for (size_t k = 0; k < m_outDofs.size(); ++k) x[m_outDofs[k]] += m_zl[k];
    } else {
      x.noalias() += m_Z * m_lambda;
    }
    if (reactions) {
      r = 0;
      for (size_t e = 0; e < prescribed.size() && r < m_rowAt.size(); ++e)
        for (int a = 0; a < 3 && r < m_rowAt.size(); ++a) {
          if (!(prescribed[e].axes & (1 << a))) continue;
          bool anyFree = false;
          for (int i = 0; i < prescribed[e].at.count; ++i)
            anyFree |= m_dof[3 * prescribed[e].at.nodes[i] + a] >= 0;
          if (anyFree) (*reactions)[e][a] = m_lambda[static_cast<Eigen::Index>(r++)];
        }
    }
  }

  u.setZero(m_numNodes, 3);
  const int outNodes = m_outputNodes >= 0 ? m_outputNodes : m_numNodes;
  for (int v = 0; v < outNodes; ++v)
    for (int a = 0; a < 3; ++a)
      if (m_dof[3 * v + a] >= 0) u(v, a) = x[m_dof[3 * v + a]];
}

void CoarseLinearFem::buildPrescribedRows(const std::vector<Prescribed>& prescribed) {
  m_rowAt.clear();
  m_rowAxis.clear();
  for (const Prescribed& p : prescribed)
    for (int a = 0; a < 3; ++a) {
      if (!(p.axes & (1 << a))) continue;
      bool anyFree = false;
      for (int i = 0; i < p.at.count; ++i) anyFree |= m_dof[3 * p.at.nodes[i] + a] >= 0;
      if (!anyFree) continue;  // a pinned node stays pinned
      m_rowAt.push_back(p.at);
      m_rowAxis.push_back(a);
    }
  const int m = static_cast<int>(m_rowAt.size());
  m_Z.setZero(m_numFree, m);
  for (int r = 0; r < m; ++r)
    for (int i = 0; i < m_rowAt[r].count; ++i)
      m_Z.col(r) += m_rowAt[r].weights[i] * nodeColumns(m_rowAt[r].nodes[i]).col(m_rowAxis[r]);
  MatX S(m, m);
  for (int r = 0; r < m; ++r)
    for (int c = 0; c < m; ++c) {
      Real v = 0;
      for (int i = 0; i < m_rowAt[r].count; ++i) {
        const int d = m_dof[3 * m_rowAt[r].nodes[i] + m_rowAxis[r]];
        if (d >= 0) v += m_rowAt[r].weights[i] * m_Z(d, c);
      }
      S(r, c) = v;
    }
  // Eigen's pivoting QR must not be run on a 0x0 matrix (it reads past the empty storage).
  if (m > 0) m_S.compute(S);
  if (m_outputNodes >= 0) {
    m_Zout.resize(static_cast<Eigen::Index>(m_outDofs.size()), m);
    for (size_t k = 0; k < m_outDofs.size(); ++k) m_Zout.row(k) = m_Z.row(m_outDofs[k]);
    if (m_floatResponse) {
      m_ZoutF.assign(m_Zout);
      m_Zout.resize(0, 0);
    }
  }
}

}  // namespace deform::hybrid_fem_pbd
