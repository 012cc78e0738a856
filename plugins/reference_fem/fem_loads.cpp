// Loads on the FemSystem (fem_solver.h): traction forces on boundary faces and the point force
// spread as a pressure patch (PointLoadSpreader).
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

/// Nodal forces of a traction on the boundary triangles whose three corners select() takes:
/// share(triangle, area, add) gives each triangle's forces by add(node, force); they are summed
/// per node and returned in node order.
template <class Share>
std::vector<std::pair<int, Vec3>> spreadTraction(const TetMesh& mesh,
                                                 const std::function<bool(const Vec3&)>& select,
                                                 Share&& share) {
  const SurfaceMesh b = tetBoundary(mesh);
  std::map<int, Vec3> acc;
  const auto add = [&](int node, const Vec3& f) {
    auto [it, fresh] = acc.try_emplace(node, Vec3::Zero());
    it->second += f;
  };
  for (int f = 0; f < b.numFaces(); ++f) {
    const Vec3 p0 = mesh.V.row(b.F(f, 0)), p1 = mesh.V.row(b.F(f, 1)), p2 = mesh.V.row(b.F(f, 2));
    if (!select(p0) || !select(p1) || !select(p2)) continue;
    share(b.F.row(f), 0.5 * (p1 - p0).cross(p2 - p0).norm(), add);
  }
  return {acc.begin(), acc.end()};
}

}  // namespace

std::vector<std::pair<int, Vec3>> tractionForces(const TetMesh& mesh, const Vec3& traction,
                                                 const std::function<bool(const Vec3&)>& select) {
  // The 3-node triangle's shape functions integrate to area / 3 at each corner.
  return spreadTraction(mesh, select, [&](const auto& tri, Real area, const auto& add) {
    for (int k = 0; k < 3; ++k) add(tri(k), area / 3.0 * traction);
  });
}

std::vector<std::pair<int, Vec3>> tractionForces(const FemSystem& system, const Vec3& traction,
                                                 const std::function<bool(const Vec3&)>& select) {
  if (system.order() != ElementOrder::Quadratic)
    return tractionForces(system.rest(), traction, select);
  // The 6-node triangle's shape functions integrate to 0 at the corners, area / 3 at the
  // midsides.
  return spreadTraction(system.rest(), select, [&](const auto& tri, Real area, const auto& add) {
    for (int k = 0; k < 3; ++k)
      add(system.edgeNode(tri(k), tri((k + 1) % 3)), area / 3.0 * traction);
  });
}

PointLoadSpreader::PointLoadSpreader(const TetMesh& mesh)
    : m_rest(mesh.V),
      m_area(VecX::Zero(mesh.numVertices())),
      m_neighbors(size_t(mesh.numVertices())) {
  const SurfaceMesh b = tetBoundary(mesh);
  for (int f = 0; f < b.numFaces(); ++f) {
    const Vec3 p0 = b.V.row(b.F(f, 0)), p1 = b.V.row(b.F(f, 1)), p2 = b.V.row(b.F(f, 2));
    const Real third = (p1 - p0).cross(p2 - p0).norm() / 6.0;
    for (int k = 0; k < 3; ++k) {
      const int a = b.F(f, k), c = b.F(f, (k + 1) % 3);
      m_area(a) += third;
      m_neighbors[size_t(a)].push_back(c);
      m_neighbors[size_t(c)].push_back(a);
    }
  }
  for (auto& n : m_neighbors) {
    std::sort(n.begin(), n.end());
    n.erase(std::unique(n.begin(), n.end()), n.end());
  }
}

PointLoadSpreader::PointLoadSpreader(const FemSystem& system) : PointLoadSpreader(system.rest()) {
  if (system.order() != ElementOrder::Quadratic) return;
  const SurfaceMesh b = tetBoundary(system.rest());
  m_nodeFaces.resize(size_t(system.numNodes()));
  for (int f = 0; f < b.numFaces(); ++f) {
    std::array<int, 6> n{};
    for (int k = 0; k < 3; ++k) {
      n[size_t(k)] = b.F(f, k);
      n[size_t(3 + k)] = system.edgeNode(b.F(f, k), b.F(f, (k + 1) % 3));
      m_nodeFaces[size_t(b.F(f, k))].push_back(int(m_quadFaces.size()));
    }
    m_quadFaces.push_back(n);
  }
}

PointLoadPatch PointLoadSpreader::patch(int c, Real radius) const {
  PointLoadPatch p;
  const Vec3 centre = m_rest.row(c).transpose();
  Real longest = 0;
  for (int n : m_neighbors[size_t(c)])
    longest = std::max(longest, (m_rest.row(n).transpose() - centre).norm());
  p.radius = std::max(radius, 1.5 * longest);
  if (m_neighbors[size_t(c)].empty() || !(p.radius > 0)) {
    p.nodes = {c};
    p.weights = {1.0};
    return p;
  }
  // Breadth-first over boundary edges, staying inside the disc.
  std::vector<char> seen(m_neighbors.size(), 0);
  seen[size_t(c)] = 1;
  p.nodes.push_back(c);
  for (size_t head = 0; head < p.nodes.size(); ++head) {
    for (int n : m_neighbors[size_t(p.nodes[head])]) {
      if (seen[size_t(n)] || (m_rest.row(n).transpose() - centre).norm() >= p.radius) continue;
      seen[size_t(n)] = 1;
      p.nodes.push_back(n);
    }
  }
  if (!m_quadFaces.empty()) return quadraticPatch(std::move(p));
  std::vector<Real> k;
  for (int i : p.nodes) {
    const Real rho = (m_rest.row(i).transpose() - centre).norm() / p.radius;
    k.push_back(m_area(i) * (1 - rho * rho));
  }
  Real sum = 0;
  for (Real w : k) sum += w;
  for (Real w : k) p.weights.push_back(w / sum);
  return p;
}

PointLoadPatch PointLoadSpreader::quadraticPatch(PointLoadPatch p) const {
  const Vec3 centre = m_rest.row(p.nodes[0]).transpose();
  std::vector<int> faces;
  for (int i : p.nodes)
    for (int f : m_nodeFaces[size_t(i)]) faces.push_back(f);
  std::sort(faces.begin(), faces.end());
  faces.erase(std::unique(faces.begin(), faces.end()), faces.end());
  constexpr int kSub = 4;  // sub-triangles per edge: k is clamped at the circle rho = R
  std::map<int, Real> load;
  Real total = 0;
  for (int f : faces) {
    const auto& n = m_quadFaces[size_t(f)];
    const Vec3 X0 = m_rest.row(n[0]), X1 = m_rest.row(n[1]), X2 = m_rest.row(n[2]);
    std::array<Real, 6> fi{};
    pressureKernelQuadrature(X0, X1, X2, centre, p.radius, kSub, [&](const Vec3& L, Real k) {
      if (k == 0) return;
      const Real L0 = L(0), L1 = L(1), L2 = L(2);
      const std::array<Real, 6> N = {L0 * (2 * L0 - 1), L1 * (2 * L1 - 1), L2 * (2 * L2 - 1),
                                     4 * L0 * L1,       4 * L1 * L2,       4 * L2 * L0};
      for (int q = 0; q < 6; ++q) fi[size_t(q)] += N[size_t(q)] * k;
      total += k;
    });
    for (int q = 0; q < 6; ++q) load[n[size_t(q)]] += fi[size_t(q)];
  }
  PointLoadPatch out;
  out.radius = p.radius;
  if (!(total > 0)) return p;
  out.nodes.push_back(p.nodes[0]);
  out.weights.push_back(load[p.nodes[0]] / total);
  for (const auto& [node, f] : load) {
    if (node == p.nodes[0]) continue;
    out.nodes.push_back(node);
    out.weights.push_back(f / total);
  }
  return out;
}

}  // namespace deform::reference_fem
