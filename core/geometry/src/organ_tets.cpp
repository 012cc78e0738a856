#include <deform/box_clip.h>
#include <deform/cache.h>
#include <deform/organ_tets.h>
#include <deform/tet_mesher.h>
#include <deform/tet_nodes.h>

#include <algorithm>

namespace deform {

namespace {

// The entry's kind and version are reference_fem's from before it moved here: caches built by
// earlier runs stay valid.
constexpr const char* kMeshCacheKind = "reference_fem.tets";
constexpr const char* kMeshCacheVersion = "reference_fem.tets/4";

std::vector<int> meshSurface(const Organ& organ, const OrganTetOptions& options, Cache& cache,
                             TetMesh& mesh) {
  TetMeshOptions o;
  o.edgeLength = options.edgeLength;
  o.targetElements = options.targetElements;
  o.refineSurface = options.refineSurface;
  o.timeoutSeconds = options.timeoutSeconds;
  o.source = organ.source;
  const int nv = organ.surface.numVertices();
  const bool conform = options.conformFixed && !organ.fixed.boxes.empty();
  CacheKey key;
  key.add(kMeshCacheVersion).add(organ.surface.V).add(organ.surface.F);
  key.add(o.edgeLength).add(o.targetElements).add((long long)o.refineSurface);
  key.add((long long)conform);
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

OrganTets organTets(const Organ& organ, const OrganTetOptions& options, Cache& cache) {
  OrganTets out;
  if (organ.volume) {
    out.mesh = *organ.volume;
    TetMesh& mesh = out.mesh;
    for (int t = 0; t < mesh.numTets(); ++t) {
      const auto r = mesh.T.row(t);
      if (tetVolume(mesh.V.row(r(0)), mesh.V.row(r(1)), mesh.V.row(r(2)), mesh.V.row(r(3))) < 0)
        std::swap(mesh.T(t, 2), mesh.T(t, 3));
    }
    out.surfaceNode = surfaceVertexNodes(organ, mesh.V);
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

}  // namespace deform
