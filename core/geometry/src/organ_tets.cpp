#include <deform/geometry/box_clip.h>
#include <deform/geometry/organ_tets.h>
#include <deform/geometry/tet_mesher.h>
#include <deform/geometry/tet_nodes.h>
#include <deform/sdk/cache.h>

#include <algorithm>
#include <array>
#include <limits>
#include <map>
#include <set>

namespace deform {

namespace {

// The entry's kind and version are reference_fem's from before it moved here: caches built by
// earlier runs stay valid.
constexpr const char* kMeshCacheKind = "reference_fem.tets";
constexpr const char* kMeshCacheVersion = "reference_fem.tets/4";

std::vector<int> meshSurface(const Organ& organ, const OrganTetOptions& options, Cache& cache,
                             TetMesh& mesh) {
  const TetMeshOptions o{.edgeLength = options.edgeLength,
                         .targetElements = options.targetElements,
                         .refineSurface = options.refineSurface,
                         .grading = options.grading,
                         .timeoutSeconds = options.timeoutSeconds,
                         .source = organ.source};
  const int nv = organ.surface.numVertices();
  const bool conform = options.conformFixed && !organ.fixed.boxes.empty();
  CacheKey key;
  key.add(kMeshCacheVersion).add(organ.surface.V).add(organ.surface.F);
  key.add(o.edgeLength).add(o.targetElements).add((long long)o.refineSurface);
  key.add((long long)conform);
  if (o.grading.active()) {  // added only when graded: the uniform meshes' keys are unchanged
    key.add("graded");
    for (int k = 0; k < 3; ++k) key.add(o.grading.centre(k));
    key.add(o.grading.radius).add(o.grading.ratio).add(o.grading.growth);
  }
  if (conform)
    for (const Box& b : organ.fixed.boxes)
      for (int k = 0; k < 3; ++k) key.add(b.lo[k]).add(b.hi[k]);
  if (auto hit = cache.get(kMeshCacheKind, key)) {
    try {
      ByteReader r(*hit);
      TetMesh m;
      Eigen::VectorXi map;
      r.matrix(m.V);
      r.matrix(m.T);
      r.matrix(map);
      if (map.size() == nv && m.numTets() > 0 && map.maxCoeff() < m.numVertices()) {
        mesh = std::move(m);
        return std::vector<int>(map.data(), map.data() + map.size());
      }
    } catch (const std::exception&) {
      // fall through: remesh
    }
  }
  Eigen::VectorXi map = Eigen::VectorXi::LinSpaced(nv, 0, nv - 1);
  TetMeshResult r;
  if (conform) {
    BoxClipOptions c;
    c.source = organ.source;
    // Cap triangles about as long as the interior tet edges, but no longer than the organ's
    // mean edge: the cut lines are as fine as the organ's surface, and cap triangles much
    // longer than the cut segments they stand on are needles (full liver phantom at 8,000
    // tets: a zero-area cap triangle and a flat tet; capped: min dihedral 0.85 deg).
    const Real interior =
        o.edgeLength > 0 ? o.edgeLength
                         : edgeLengthForElements(signedVolume(organ.surface.V, organ.surface.F),
                                                 o.targetElements);
    const MatX2i E = uniqueEdges(organ.surface.F);
    Real sum = 0;
    for (Eigen::Index e = 0; e < E.rows(); ++e)
      sum += (organ.surface.V.row(E(e, 0)) - organ.surface.V.row(E(e, 1))).norm();
    c.capEdgeLength = E.rows() > 0 ? std::min(interior, sum / Real(E.rows())) : interior;
    const BoxClipResult clip = clipSurfaceByBoxes(organ.surface, organ.fixed.boxes, c);
    map = Eigen::Map<const Eigen::VectorXi>(clip.inputToClipped.data(), nv);
    r = tetrahedralize(clip.surface, o);
  } else {
    r = tetrahedralize(organ.surface, o);
  }
  ByteWriter w;
  w.matrix(r.mesh.V);
  w.matrix(r.mesh.T);
  w.matrix(map);
  cache.put(kMeshCacheKind, key, w.bytes());
  mesh = r.mesh;
  return std::vector<int>(map.data(), map.data() + map.size());
}

}  // namespace

std::vector<ParamSpec> withOrganTetParams(std::vector<ParamSpec> specs, size_t at) {
  const std::vector<ParamSpec> mesh = {
      ParamSpec::integer("elements", 1000, 100, 5000000,
                         "target number of tets (used when edge_length is 0; an organ's surface "
                         "vertices are all nodes, so a fine surface gives more)"),
      ParamSpec::real("edge_length", "m", 0.0, 0.0, 1.0,
                      "target interior tet edge length; 0: from elements"),
      ParamSpec::flag("refine_surface", true,
                      "split surface edges longer than the edge length before meshing (the "
                      "input vertices stay nodes with their indices)"),
      ParamSpec::flag("conform_fixed", true,
                      "mesh the organ minus the fixed boxes (caps pinned, u = 0), so the clamped "
                      "boundary is the same at every refinement; false: mesh the whole organ and "
                      "pin the nodes that fall inside the boxes"),
      ParamSpec::real("mesh_timeout", "s", 600.0, 1.0, 86400.0,
                      "wall-clock limit of the Gmsh child process"),
      ParamSpec::real("focus_x", "m", 0.0, -1e3, 1e3,
                      "x of the point the mesh is graded toward (see focus_radius)"),
      ParamSpec::real("focus_y", "m", 0.0, -1e3, 1e3, "y of the point the mesh is graded toward"),
      ParamSpec::real("focus_z", "m", 0.0, -1e3, 1e3, "z of the point the mesh is graded toward"),
      ParamSpec::real("focus_radius", "m", 0.0, 0.0, 1e3,
                      "within this distance of the focus point, tet and (with refine_surface) "
                      "surface edges are focus_ratio x the edge length, growing by focus_growth "
                      "per m beyond; 0: uniform size (a grasp's or a load's region is where a "
                      "reference's error is: grading refines it at every convergence level)"),
      ParamSpec::real("focus_ratio", "1", 0.35, 0.05, 1.0,
                      "edge length near the focus point over the edge length"),
      ParamSpec::real("focus_growth", "1", 0.3, 0.01, 10.0,
                      "increase of the edge length per distance beyond focus_radius"),
  };
  specs.insert(specs.begin() + std::ptrdiff_t(std::min(at, specs.size())), mesh.begin(),
               mesh.end());
  return specs;
}

OrganTetOptions organTetOptions(const ParamValues& p) {
  OrganTetOptions o;
  o.edgeLength = p.real("edge_length");
  o.targetElements = p.integer("elements");
  o.refineSurface = p.flag("refine_surface");
  o.conformFixed = p.flag("conform_fixed");
  o.timeoutSeconds = p.real("mesh_timeout");
  o.grading.centre = Vec3(p.real("focus_x"), p.real("focus_y"), p.real("focus_z"));
  o.grading.radius = p.real("focus_radius");
  o.grading.ratio = p.real("focus_ratio");
  o.grading.growth = p.real("focus_growth");
  return o;
}

OrganTets organTets(const Organ& organ, const OrganTetOptions& options, Cache& cache) {
  OrganTets out;
  if (organ.volume) {
    out.mesh = *organ.volume;
    orientTetsPositive(out.mesh);
    out.surfaceNode = surfaceVertexNodes(organ, out.mesh.V);
  } else {
    out.surfaceNode = meshSurface(organ, options, cache, out.mesh);
  }
  return out;
}

QuadraticTetNodes addMidsideNodes(const TetMesh& corners) {
  QuadraticTetNodes q;
  q.numCorners = corners.numVertices();
  const int nt = corners.numTets();
  std::vector<std::pair<int, int>> all;
  all.reserve(size_t(6 * nt));
  for (int t = 0; t < nt; ++t)
    for (const auto& e : kQuadraticTetEdges) {
      const int a = corners.T(t, e[0]), b = corners.T(t, e[1]);
      all.emplace_back(std::min(a, b), std::max(a, b));
    }
  std::sort(all.begin(), all.end());
  all.erase(std::unique(all.begin(), all.end()), all.end());
  q.edges = std::move(all);
  q.V.resize(Eigen::Index(q.numCorners + int(q.edges.size())), 3);
  q.V.topRows(q.numCorners) = corners.V;
  for (size_t k = 0; k < q.edges.size(); ++k)
    q.V.row(Eigen::Index(q.numCorners + int(k))) =
        0.5 * (corners.V.row(q.edges[k].first) + corners.V.row(q.edges[k].second));
  q.elements.resize(nt, 10);
  for (int t = 0; t < nt; ++t) {
    for (int a = 0; a < 4; ++a) q.elements(t, a) = corners.T(t, a);
    for (int e = 0; e < 6; ++e)
      q.elements(t, 4 + e) = q.edgeNode(corners.T(t, kQuadraticTetEdges[e][0]),
                                        corners.T(t, kQuadraticTetEdges[e][1]));
  }
  return q;
}

int QuadraticTetNodes::edgeNode(int a, int b) const {
  const std::pair<int, int> key(std::min(a, b), std::max(a, b));
  const auto it = std::lower_bound(edges.begin(), edges.end(), key);
  if (it == edges.end() || *it != key) return -1;
  return numCorners + int(it - edges.begin());
}

QuadraticSurfaceLoad::QuadraticSurfaceLoad(const TetMesh& corners,
                                           std::function<int(int, int)> edgeNode)
    : m_nodes(corners.V), m_edgeNode(std::move(edgeNode)) {
  m_faces = tetBoundary(corners).F;
  m_nodeFaces.resize(size_t(m_nodes.rows()));
  for (int f = 0; f < int(m_faces.rows()); ++f)
    for (int k = 0; k < 3; ++k) m_nodeFaces[size_t(m_faces(f, k))].push_back(f);
}

std::vector<std::pair<int, Vec3>> QuadraticSurfaceLoad::spread(
    const std::vector<std::pair<int, Vec3>>& cornerForces) const {
  std::map<int, Vec3> force;
  for (const auto& [node, f] : cornerForces) {
    auto it = force.try_emplace(node, Vec3::Zero()).first;
    it->second += f;
  }
  // The loaded triangles: boundary faces whose three corners all carry a share.
  std::set<int> faces;
  for (const auto& [node, f] : force) {
    if (node < 0 || node >= int(m_nodeFaces.size())) continue;
    for (int t : m_nodeFaces[size_t(node)]) {
      bool loaded = true;
      for (int k = 0; k < 3; ++k) loaded = loaded && force.count(m_faces(t, k));
      if (loaded) faces.insert(t);
    }
  }
  std::map<int, Real> lumped;  // each node's third of its loaded triangles' areas
  std::vector<Real> area;
  for (int t : faces) {
    const Vec3 X0 = m_nodes.row(m_faces(t, 0)), X1 = m_nodes.row(m_faces(t, 1)),
               X2 = m_nodes.row(m_faces(t, 2));
    area.push_back(0.5 * (X1 - X0).cross(X2 - X0).norm());
    for (int k = 0; k < 3; ++k) lumped[m_faces(t, k)] += area.back() / 3;
  }
  std::map<int, Vec3> out;
  auto add = [&](int node, const Vec3& f) {
    auto it = out.try_emplace(node, Vec3::Zero()).first;
    it->second += f;
  };
  for (const auto& [node, f] : force) {
    const auto it = lumped.find(node);
    if (it == lumped.end() || !(it->second > 0)) add(node, f);
  }
  // With the traction t linear on a triangle of area A, the integrals of t against the quadratic
  // shape functions are A (t_i / 30 - (t_j + t_k) / 60) at corner i and
  // A (2 (t_i + t_j) + t_k) / 15 at the midside node of edge ij.
  size_t a = 0;
  for (int t : faces) {
    const Real A = area[a++];
    if (!(A > 0)) continue;
    std::array<int, 3> n{};
    std::array<Vec3, 3> tr;
    for (int k = 0; k < 3; ++k) {
      n[size_t(k)] = m_faces(t, k);
      tr[size_t(k)] = force.at(n[size_t(k)]) / lumped.at(n[size_t(k)]);
    }
    for (int i = 0; i < 3; ++i) {
      const int j = (i + 1) % 3, k = (i + 2) % 3;
      add(n[size_t(i)], A * (tr[size_t(i)] / 30 - (tr[size_t(j)] + tr[size_t(k)]) / 60));
      const int mid = m_edgeNode(n[size_t(i)], n[size_t(j)]);
      const Vec3 fm = A * (2 * (tr[size_t(i)] + tr[size_t(j)]) + tr[size_t(k)]) / 15;
      if (mid >= 0) {
        add(mid, fm);
      } else {  // no midside node (not a quadratic edge): half to each end keeps the total
        add(n[size_t(i)], 0.5 * fm);
        add(n[size_t(j)], 0.5 * fm);
      }
    }
  }
  return {out.begin(), out.end()};
}

std::vector<int> tetBoundaryNodes(const TetMesh& corners,
                                  const std::function<int(int, int)>& edgeNode) {
  const SurfaceMesh boundary = tetBoundary(corners);
  std::vector<int> out;
  for (Eigen::Index f = 0; f < boundary.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      out.push_back(boundary.F(f, k));
      const int mid = edgeNode ? edgeNode(boundary.F(f, k), boundary.F(f, (k + 1) % 3)) : -1;
      if (mid >= 0) out.push_back(mid);
    }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

GraspedPatchNodes::GraspedPatchNodes(const SurfaceMesh& surface, std::vector<int> surfaceNode,
                                     const MatX3& nodes, std::vector<int> boundaryNodes)
    : m_surface(surface),
      m_surfaceNode(std::move(surfaceNode)),
      m_nodes(nodes),
      m_boundaryNodes(std::move(boundaryNodes)),
      m_vertexFaces(size_t(surface.numVertices())),
      m_isVertexNode(size_t(nodes.rows()), 0) {
  for (int f = 0; f < surface.numFaces(); ++f)
    for (int k = 0; k < 3; ++k) m_vertexFaces[size_t(surface.F(f, k))].push_back(f);
  for (int n : m_surfaceNode)
    if (n >= 0 && n < int(nodes.rows())) m_isVertexNode[size_t(n)] = 1;
}

std::vector<int> GraspedPatchNodes::nodes(const std::vector<int>& graspedVertices) const {
  std::vector<int> out;
  for (int v : graspedVertices)
    if (v >= 0 && v < int(m_surfaceNode.size()) && m_surfaceNode[size_t(v)] >= 0)
      out.push_back(m_surfaceNode[size_t(v)]);
  for (const Held& h : held(graspedVertices)) out.push_back(h.node);
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

std::vector<GraspedPatchNodes::Held> GraspedPatchNodes::held(
    const std::vector<int>& graspedVertices) const {
  std::vector<Held> out;
  std::vector<int> grasped = graspedVertices;
  std::sort(grasped.begin(), grasped.end());
  const auto isGrasped = [&](int v) {
    return std::binary_search(grasped.begin(), grasped.end(), v);
  };
  std::vector<int> faces;
  std::vector<std::pair<int, int>> edges;  // surface edges with both ends grasped
  for (int v : grasped) {
    if (v < 0 || v >= int(m_vertexFaces.size())) continue;
    for (int f : m_vertexFaces[size_t(v)]) {
      bool all = true;
      for (int k = 0; k < 3; ++k) {
        const int a = m_surface.F(f, k), b = m_surface.F(f, (k + 1) % 3);
        all = all && isGrasped(a);
        if (isGrasped(a) && isGrasped(b)) edges.emplace_back(std::min(a, b), std::max(a, b));
      }
      if (all) faces.push_back(f);
    }
  }
  std::sort(faces.begin(), faces.end());
  faces.erase(std::unique(faces.begin(), faces.end()), faces.end());
  std::sort(edges.begin(), edges.end());
  edges.erase(std::unique(edges.begin(), edges.end()), edges.end());
  if (edges.empty()) return out;
  Vec3 lo = Vec3::Constant(std::numeric_limits<Real>::max()), hi = -lo;
  Real longest = 0;
  for (const auto& [a, b] : edges) {
    const Vec3 xa = m_surface.V.row(a).transpose(), xb = m_surface.V.row(b).transpose();
    lo = lo.cwiseMin(xa).cwiseMin(xb);
    hi = hi.cwiseMax(xa).cwiseMax(xb);
    longest = std::max(longest, (xa - xb).norm());
  }
  const Real tol = 1e-6 * longest;  // on the triangle: a node of the mesh of this very surface
  lo.array() -= tol;
  hi.array() += tol;
  for (int n : m_boundaryNodes) {
    if (m_isVertexNode[size_t(n)]) continue;
    const Vec3 x = m_nodes.row(n).transpose();
    if ((x.array() < lo.array()).any() || (x.array() > hi.array()).any()) continue;
    bool found = false;
    for (int f : faces) {
      const Vec3 a = m_surface.V.row(m_surface.F(f, 0)), b = m_surface.V.row(m_surface.F(f, 1)),
                 c = m_surface.V.row(m_surface.F(f, 2));
      const Vec3 normal = (b - a).cross(c - a);
      const Real twiceArea = normal.norm();
      if (!(twiceArea > 0)) continue;
      if (std::abs((x - a).dot(normal)) / twiceArea > tol) continue;
      const Real wa = (b - x).cross(c - x).dot(normal) / (twiceArea * twiceArea);
      const Real wb = (c - x).cross(a - x).dot(normal) / (twiceArea * twiceArea);
      const Real wc = 1 - wa - wb;
      const Real eps = tol / longest;
      if (wa < -eps || wb < -eps || wc < -eps) continue;
      Held h;
      h.node = n;
      for (int k = 0; k < 3; ++k) h.vertices[size_t(k)] = m_surface.F(f, k);
      h.weights = Vec3(wa, wb, wc);
      out.push_back(h);
      found = true;
      break;
    }
    // On an edge between two grasped vertices (held by every model's surface along the edge).
    for (size_t e = 0; e < edges.size() && !found; ++e) {
      const Vec3 a = m_surface.V.row(edges[e].first), b = m_surface.V.row(edges[e].second);
      const Real len2 = (b - a).squaredNorm();
      if (!(len2 > 0)) continue;
      const Real t = (x - a).dot(b - a) / len2;
      if (t < -tol / longest || t > 1 + tol / longest) continue;
      if ((a + t * (b - a) - x).norm() > tol) continue;
      Held h;
      h.node = n;
      h.vertices = {edges[e].first, edges[e].second, edges[e].first};
      h.weights = Vec3(1 - t, t, 0);
      out.push_back(h);
      found = true;
    }
  }
  return out;
}

}  // namespace deform
