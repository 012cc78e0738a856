#include <deform/geometry/mesh_check.h>
#include <deform/sdk/error.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <unordered_map>

namespace deform {
namespace {

class UnionFind {
 public:
  explicit UnionFind(size_t n) : m_parent(n) { std::iota(m_parent.begin(), m_parent.end(), 0); }
  int find(int a) {
    while (m_parent[size_t(a)] != a) {
      m_parent[size_t(a)] = m_parent[size_t(m_parent[size_t(a)])];
      a = m_parent[size_t(a)];
    }
    return a;
  }
  void unite(int a, int b) {
    a = find(a);
    b = find(b);
    // Smaller index becomes the root, so roots are deterministic (the first member).
    if (a < b)
      m_parent[size_t(b)] = a;
    else if (b < a)
      m_parent[size_t(a)] = b;
  }

 private:
  std::vector<int> m_parent;
};

std::string counted(long long n, const char* singular, const char* plural) {
  return std::to_string(n) + " " + (n == 1 ? singular : plural);
}

bool finiteRow(const MatX3& V, Eigen::Index i) {
  return V.row(i).allFinite();
}

/// Bounding box of the finite rows of V.
Box finiteBox(const MatX3& V) {
  Box b;
  bool any = false;
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    if (!finiteRow(V, i)) continue;
    const Vec3 p = V.row(i).transpose();
    if (!any) {
      b.lo = b.hi = p;
      any = true;
    } else {
      b.lo = b.lo.cwiseMin(p);
      b.hi = b.hi.cwiseMax(p);
    }
  }
  return b;
}

/// For each vertex, the first-seen finite vertex within eps of it (itself when none). A hash grid
/// with cells of size eps means a partner can only be in the 27 surrounding cells.
std::vector<int> weldMap(const MatX3& V, const Box& box, Real eps) {
  const Real h = eps > 0 ? eps : 1.0;
  struct KeyHash {
    size_t operator()(const std::array<long long, 3>& k) const {
      return size_t(k[0]) * 73856093u ^ size_t(k[1]) * 19349663u ^ size_t(k[2]) * 83492791u;
    }
  };
  std::unordered_map<std::array<long long, 3>, int, KeyHash> head;  // cell -> first rep in it
  std::vector<int> next(size_t(V.rows()), -1);                      // rep -> next rep in cell
  std::vector<int> rep(size_t(V.rows()));
  head.reserve(size_t(V.rows()));
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    rep[size_t(i)] = int(i);
    if (!finiteRow(V, i)) continue;
    const Vec3 p = V.row(i).transpose();
    std::array<long long, 3> c;
    for (int k = 0; k < 3; ++k) {
      // Coordinates near DBL_MAX overflow the box to inf, so eps = h = inf and q = inf / inf is
      // NaN: such points all go to cell 0 (every point is within an infinite eps anyway).
      const Real q = (p[k] - box.lo[k]) / h;
      c[size_t(k)] = q >= 0 && q < 4e18 ? static_cast<long long>(q) : 0;
    }
    int best = -1;
    for (long long dx = -1; dx <= 1; ++dx) {
      for (long long dy = -1; dy <= 1; ++dy) {
        for (long long dz = -1; dz <= 1; ++dz) {
          const auto it = head.find({c[0] + dx, c[1] + dy, c[2] + dz});
          if (it == head.end()) continue;
          for (int j = it->second; j >= 0; j = next[size_t(j)]) {
            if ((best < 0 || j < best) && (V.row(j).transpose() - p).norm() <= eps) best = j;
          }
        }
      }
    }
    if (best >= 0) {
      rep[size_t(i)] = best;
    } else {
      auto [it, inserted] = head.try_emplace(c, int(i));
      if (!inserted) {
        next[size_t(i)] = it->second;
        it->second = int(i);
      }
    }
  }
  return rep;
}

Real triangleArea(const MatX3& V, int a, int b, int c) {
  const Vec3 pa = V.row(a), pb = V.row(b), pc = V.row(c);
  return 0.5 * (pb - pa).cross(pc - pa).norm();
}

/// One directed edge of a triangle, keyed by its undirected vertex pair.
struct HalfEdge {
  int lo, hi;
  int face;
  bool forward;  // traversed lo -> hi
  bool operator<(const HalfEdge& o) const {
    return lo != o.lo ? lo < o.lo : hi != o.hi ? hi < o.hi : face < o.face;
  }
};

std::vector<HalfEdge> halfEdges(const MatX3i& F, const std::vector<int>& faces) {
  std::vector<HalfEdge> he;
  he.reserve(3 * faces.size());
  for (int f : faces) {
    for (int k = 0; k < 3; ++k) {
      const int a = F(f, k), b = F(f, (k + 1) % 3);
      he.push_back({std::min(a, b), std::max(a, b), f, a < b});
    }
  }
  std::sort(he.begin(), he.end());
  return he;
}

/// Calls fn(begin, end) for each run of half-edges on the same undirected edge.
template <class Fn>
void forEachEdge(const std::vector<HalfEdge>& he, Fn&& fn) {
  for (size_t i = 0; i < he.size();) {
    size_t j = i + 1;
    while (j < he.size() && he[j].lo == he[i].lo && he[j].hi == he[i].hi) ++j;
    fn(i, j);
    i = j;
  }
}

/// Number of vertices whose incident triangles do not form one fan connected through edges;
/// `first` receives the lowest such vertex.
int countNonManifoldVertices(const MatX3i& F, const std::vector<int>& faces, int& first) {
  // A slot is one corner of one triangle (3 * position in `faces` + corner); the corners around a
  // vertex are joined when their triangles share an edge at that vertex.
  struct Spoke {
    int v, w, slot;
    bool operator<(const Spoke& o) const {
      return v != o.v ? v < o.v : w != o.w ? w < o.w : slot < o.slot;
    }
  };
  std::vector<Spoke> spokes;
  spokes.reserve(6 * faces.size());
  for (size_t i = 0; i < faces.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      const int slot = int(3 * i) + k;
      const int v = F(faces[i], k);
      spokes.push_back({v, F(faces[i], (k + 1) % 3), slot});
      spokes.push_back({v, F(faces[i], (k + 2) % 3), slot});
    }
  }
  std::sort(spokes.begin(), spokes.end());
  UnionFind uf(3 * faces.size());
  for (size_t i = 1; i < spokes.size(); ++i) {
    if (spokes[i].v == spokes[i - 1].v && spokes[i].w == spokes[i - 1].w) {
      uf.unite(spokes[i].slot, spokes[i - 1].slot);
    }
  }
  std::vector<std::pair<int, int>> fans;  // (vertex, fan root)
  fans.reserve(3 * faces.size());
  for (size_t i = 0; i < faces.size(); ++i) {
    for (int k = 0; k < 3; ++k) fans.emplace_back(F(faces[i], k), uf.find(int(3 * i) + k));
  }
  std::sort(fans.begin(), fans.end());
  fans.erase(std::unique(fans.begin(), fans.end()), fans.end());
  int count = 0;
  for (size_t i = 1; i < fans.size(); ++i) {
    // Count each vertex once, at its second fan.
    if (fans[i].first == fans[i - 1].first && (i < 2 || fans[i - 2].first != fans[i].first)) {
      if (count == 0) first = fans[i].first;
      ++count;
    }
  }
  return count;
}

/// Edge-connected components of `faces`: component id per entry of `faces` (0.. in order of
/// first appearance) and the number of components.
std::vector<int> components(const MatX3i& F, const std::vector<int>& faces,
                            const std::vector<HalfEdge>& he, int& numComponents) {
  std::vector<int> position(size_t(F.rows()), -1);  // face -> index in `faces`
  for (size_t i = 0; i < faces.size(); ++i) position[size_t(faces[i])] = int(i);
  UnionFind uf(faces.size());
  forEachEdge(he, [&](size_t b, size_t e) {
    for (size_t k = b + 1; k < e; ++k) {
      uf.unite(position[size_t(he[b].face)], position[size_t(he[k].face)]);
    }
  });
  std::vector<int> comp(faces.size(), -1), rootId(faces.size(), -1);
  numComponents = 0;
  for (size_t i = 0; i < faces.size(); ++i) {
    const int r = uf.find(int(i));
    if (rootId[size_t(r)] < 0) rootId[size_t(r)] = numComponents++;
    comp[i] = rootId[size_t(r)];
  }
  return comp;
}

std::string edgeName(int a, int b) {
  return "edge " + std::to_string(a) + "-" + std::to_string(b);
}

std::string formatVolume(Real v) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.2g", v);
  return buf;
}

void addIssue(MeshReport& report, MeshDefect d, long long count, std::string message) {
  report.issues.push_back({d, static_cast<int>(count), std::move(message)});
}

// The checks of validateSurface, in the order of its report. Each message ends with the first
// place (lowest index) where the defect occurs.

/// Vertices with NaN or Inf coordinates; returns their number.
int checkFinite(const MatX3& V, MeshReport& report) {
  int nonFinite = 0, firstNonFinite = -1;
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    if (finiteRow(V, i)) continue;
    if (nonFinite++ == 0) firstNonFinite = int(i);
  }
  if (nonFinite > 0) {
    addIssue(report, MeshDefect::NonFinite, nonFinite,
             counted(nonFinite, "vertex", "vertices") +
                 " with NaN or Inf coordinates, first: vertex " + std::to_string(firstNonFinite));
  }
  return nonFinite;
}

/// The triangles usable for topology (indices in range and distinct), and what the scan saw.
struct FaceScan {
  std::vector<int> faces;
  std::vector<char> referenced;  ///< per vertex: some in-range triangle names it
  int outOfRange = 0, repeated = 0, firstDegenerate = -1;
};

FaceScan scanFaces(const MatX3i& F, int nv, MeshReport& report) {
  const int nf = int(F.rows());
  FaceScan s;
  s.faces.reserve(size_t(nf));
  s.referenced.assign(size_t(nv), 0);
  int firstOutOfRange = -1;
  for (int f = 0; f < nf; ++f) {
    const int a = F(f, 0), b = F(f, 1), c = F(f, 2);
    if (std::min({a, b, c}) < 0 || std::max({a, b, c}) >= nv) {
      if (s.outOfRange++ == 0) firstOutOfRange = f;
      continue;
    }
    s.referenced[size_t(a)] = s.referenced[size_t(b)] = s.referenced[size_t(c)] = 1;
    if (a == b || b == c || a == c) {
      if (s.repeated++ == 0) s.firstDegenerate = f;
      continue;
    }
    s.faces.push_back(f);
  }
  if (s.outOfRange > 0) {
    addIssue(report, MeshDefect::IndexOutOfRange, s.outOfRange,
             counted(s.outOfRange, "triangle", "triangles") +
                 " with a vertex index out of range (" + counted(nv, "vertex", "vertices") +
                 "), first: triangle " + std::to_string(firstOutOfRange));
  }
  return s;
}

/// Vertices within the weld tolerance of an earlier one (finite coordinates only).
void checkDuplicates(const MatX3& V, Real diag, MeshReport& report) {
  const std::vector<int> rep = weldMap(V, finiteBox(V), tol::kRelativeWeld * diag);
  int dup = 0, firstDup = -1;
  for (int i = 0; i < int(V.rows()); ++i) {
    if (rep[size_t(i)] == i) continue;
    if (dup++ == 0) firstDup = i;
  }
  if (dup > 0)
    addIssue(report, MeshDefect::DuplicateVertices, dup,
             counted(dup, "duplicate vertex", "duplicate vertices") + ", first: vertex " +
                 std::to_string(firstDup) + " (at vertex " + std::to_string(rep[size_t(firstDup)]) +
                 ")");
}

/// Triangles with a repeated vertex (found by scanFaces) or, with finite coordinates, zero area.
void checkDegenerate(const MatX3& V, const MatX3i& F, const FaceScan& scan, Real diag, bool finite,
                     MeshReport& report) {
  int zeroArea = 0, firstDegenerate = scan.firstDegenerate;
  if (finite) {
    const Real minArea = tol::kRelativeZeroArea * diag * diag;
    for (int f : scan.faces) {
      if (!(triangleArea(V, F(f, 0), F(f, 1), F(f, 2)) <= minArea)) continue;
      if (zeroArea++ == 0 && (firstDegenerate < 0 || f < firstDegenerate)) firstDegenerate = f;
    }
  }
  const int repeated = scan.repeated;
  if (repeated + zeroArea == 0) return;
  const std::string what =
      repeated == 0 ? counted(zeroArea, "zero-area triangle", "zero-area triangles")
                    : counted(repeated + zeroArea, "degenerate triangle", "degenerate triangles") +
                          " (" + std::to_string(repeated) + " with a repeated vertex, " +
                          std::to_string(zeroArea) + " zero-area)";
  addIssue(report, MeshDefect::DegenerateTriangles, repeated + zeroArea,
           what + ", first: triangle " + std::to_string(firstDegenerate));
}

/// Boundary, non-manifold and inconsistently oriented edges, and non-manifold vertices; returns
/// whether the surface is closed, manifold along its edges and consistently oriented.
bool checkEdges(const MatX3i& F, const std::vector<int>& faces, const std::vector<HalfEdge>& he,
                MeshReport& report) {
  int boundary = 0, nonManifold = 0, inconsistent = 0;
  std::string firstBoundary, firstNonManifold, firstInconsistent;  // edges in sorted order
  forEachEdge(he, [&](size_t b, size_t e) {
    if (e - b == 1) {
      if (boundary++ == 0) firstBoundary = edgeName(he[b].lo, he[b].hi);
    } else if (e - b > 2) {
      if (nonManifold++ == 0) firstNonManifold = edgeName(he[b].lo, he[b].hi);
    } else if (he[b].forward == he[b + 1].forward) {
      if (inconsistent++ == 0) firstInconsistent = edgeName(he[b].lo, he[b].hi);
    }
  });
  if (boundary > 0) {
    addIssue(
        report, MeshDefect::BoundaryEdges, boundary,
        counted(boundary, "boundary edge", "boundary edges") + " (holes), first: " + firstBoundary);
  }
  if (nonManifold > 0) {
    addIssue(report, MeshDefect::NonManifoldEdges, nonManifold,
             counted(nonManifold, "non-manifold edge", "non-manifold edges") +
                 " (shared by more than two triangles), first: " + firstNonManifold);
  }
  int firstNmVertex = -1;
  const int nmVertices = countNonManifoldVertices(F, faces, firstNmVertex);
  if (nmVertices > 0) {
    addIssue(report, MeshDefect::NonManifoldVertices, nmVertices,
             counted(nmVertices, "non-manifold vertex", "non-manifold vertices") +
                 " (triangles around it do not form one fan), first: vertex " +
                 std::to_string(firstNmVertex));
  }
  if (inconsistent > 0) {
    addIssue(report, MeshDefect::InconsistentOrientation, inconsistent,
             counted(inconsistent, "edge", "edges") +
                 " with inconsistent orientation (both triangles traverse it the same way), "
                 "first: " +
                 firstInconsistent);
  }
  return boundary == 0 && nonManifold == 0 && inconsistent == 0;
}

/// A closed, consistently oriented surface whose signed volume is negative faces inward.
void checkInward(const MatX3& V, const MatX3i& F, const std::vector<int>& faces,
                 MeshReport& report) {
  Real vol = 0;
  for (int f : faces) {
    const Vec3 a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
    vol += a.dot(b.cross(c)) / 6.0;
  }
  if (vol < 0) {
    addIssue(report, MeshDefect::InwardOrientation, 1,
             "inward-facing normals (signed volume " + formatVolume(vol) + " m^3)");
  }
}

/// More than one edge-connected component.
void checkComponents(const MatX3i& F, const std::vector<int>& faces,
                     const std::vector<HalfEdge>& he, MeshReport& report) {
  int numComp = 0;
  const std::vector<int> comp = components(F, faces, he, numComp);
  if (numComp <= 1) return;
  // Component ids follow the order of first appearance: the first triangle with id 1 is the
  // first one not connected to triangle faces[0].
  const size_t second = size_t(std::find(comp.begin(), comp.end(), 1) - comp.begin());
  addIssue(report, MeshDefect::MultipleComponents, numComp,
           counted(numComp, "component", "components") + " (triangle " +
               std::to_string(faces[second]) + " is not connected to triangle " +
               std::to_string(faces[0]) + ")");
}

}  // namespace

bool isWarning(MeshDefect d) {
  return d == MeshDefect::UnreferencedVertices;
}

bool MeshReport::has(MeshDefect d) const {
  return std::any_of(issues.begin(), issues.end(),
                     [d](const MeshIssue& i) { return i.defect == d; });
}

bool MeshReport::usable() const {
  return std::all_of(issues.begin(), issues.end(),
                     [](const MeshIssue& i) { return isWarning(i.defect); });
}

MeshReport validateSurface(const SurfaceMesh& mesh) {
  MeshReport report;
  const MatX3& V = mesh.V;
  const MatX3i& F = mesh.F;
  const int nv = mesh.numVertices(), nf = mesh.numFaces();
  if (nv == 0 || nf == 0) {
    addIssue(report, MeshDefect::Empty, 0,
             "empty mesh (" + counted(nv, "vertex", "vertices") + ", " +
                 counted(nf, "triangle", "triangles") + ")");
    return report;
  }
  const bool finite = checkFinite(V, report) == 0;
  const FaceScan scan = scanFaces(F, nv, report);
  const Real diag = finiteBox(V).diagonal();
  if (finite) checkDuplicates(V, diag, report);
  checkDegenerate(V, F, scan, diag, finite, report);
  const std::vector<HalfEdge> he = halfEdges(F, scan.faces);
  const bool closedAndConsistent = checkEdges(F, scan.faces, he, report);
  if (finite && scan.outOfRange == 0 && closedAndConsistent) checkInward(V, F, scan.faces, report);
  checkComponents(F, scan.faces, he, report);
  const auto unreferenced = std::count(scan.referenced.begin(), scan.referenced.end(), 0);
  if (unreferenced > 0) {
    addIssue(report, MeshDefect::UnreferencedVertices, unreferenced,
             counted(unreferenced, "unreferenced vertex", "unreferenced vertices"));
  }
  return report;
}

void requireValidSurface(const SurfaceMesh& mesh, const std::string& file) {
  const MeshReport report = validateSurface(mesh);
  for (const MeshIssue& issue : report.issues) {
    if (!isWarning(issue.defect)) throw InputError(file, "", issue.message);
  }
}

std::vector<std::string> RepairReport::lines() const {
  std::vector<std::string> out;
  if (droppedInvalid > 0) {
    out.push_back("dropped " + counted(droppedInvalid, "triangle", "triangles") +
                  " with an out-of-range index or a NaN/Inf corner");
  }
  if (weldedVertices > 0) {
    out.push_back("welded " + counted(weldedVertices, "duplicate vertex", "duplicate vertices"));
  }
  if (droppedDegenerate > 0) {
    out.push_back("dropped " +
                  counted(droppedDegenerate, "degenerate triangle", "degenerate triangles"));
  }
  if (droppedDuplicateTriangles > 0) {
    out.push_back("dropped " +
                  counted(droppedDuplicateTriangles, "duplicate triangle", "duplicate triangles"));
  }
  if (droppedComponents > 0) {
    out.push_back("dropped " + counted(droppedComponents, "component", "components") + " (" +
                  counted(droppedComponentTriangles, "triangle", "triangles") +
                  "), kept the largest");
  }
  if (reversedWhole) out.push_back("reversed every triangle (the normals pointed inward)");
  if (flippedTriangles > 0) {
    out.push_back("flipped " + counted(flippedTriangles, "triangle", "triangles") +
                  " to orient the surface consistently");
  }
  if (droppedUnreferenced > 0) {
    out.push_back("dropped " +
                  counted(droppedUnreferenced, "unreferenced vertex", "unreferenced vertices"));
  }
  return out;
}

RepairReport repairSurface(SurfaceMesh& mesh) {
  RepairReport rep;
  const MatX3& V = mesh.V;
  const int nv = mesh.numVertices();
  MatX3i F = mesh.F;
  std::vector<char> finite(static_cast<size_t>(nv), 0);
  for (int i = 0; i < nv; ++i) finite[size_t(i)] = finiteRow(V, i);

  std::vector<int> faces;  // kept triangles (rows of F), in order
  faces.reserve(size_t(F.rows()));
  for (int f = 0; f < F.rows(); ++f) {
    bool ok = true;
    for (int k = 0; k < 3; ++k) ok = ok && F(f, k) >= 0 && F(f, k) < nv && finite[size_t(F(f, k))];
    if (ok)
      faces.push_back(f);
    else
      ++rep.droppedInvalid;
  }

  const Box box = finiteBox(V);
  const Real diag = box.diagonal();
  const std::vector<int> weld = weldMap(V, box, tol::kRelativeWeld * diag);
  for (int i = 0; i < nv; ++i) rep.weldedVertices += weld[size_t(i)] != i;
  for (int f : faces) {
    for (int k = 0; k < 3; ++k) F(f, k) = weld[size_t(F(f, k))];
  }

  const Real minArea = tol::kRelativeZeroArea * diag * diag;
  std::erase_if(faces, [&](int f) {
    const int a = F(f, 0), b = F(f, 1), c = F(f, 2);
    const bool bad = a == b || b == c || a == c || triangleArea(V, a, b, c) <= minArea;
    rep.droppedDegenerate += bad;
    return bad;
  });

  {
    std::vector<std::pair<std::array<int, 3>, int>> keyed;  // (sorted corners, position)
    keyed.reserve(faces.size());
    for (size_t i = 0; i < faces.size(); ++i) {
      std::array<int, 3> key = {F(faces[i], 0), F(faces[i], 1), F(faces[i], 2)};
      std::sort(key.begin(), key.end());
      keyed.emplace_back(key, int(i));
    }
    std::sort(keyed.begin(), keyed.end());
    std::vector<char> drop(faces.size(), 0);
    for (size_t i = 1; i < keyed.size(); ++i) {
      if (keyed[i].first == keyed[i - 1].first) drop[size_t(keyed[i].second)] = 1;
    }
    std::vector<int> kept;
    kept.reserve(faces.size());
    for (size_t i = 0; i < faces.size(); ++i) {
      if (drop[i])
        ++rep.droppedDuplicateTriangles;
      else
        kept.push_back(faces[i]);
    }
    faces.swap(kept);
  }

  std::vector<HalfEdge> he = halfEdges(F, faces);
  {
    int numComp = 0;
    const std::vector<int> comp = components(F, faces, he, numComp);
    if (numComp > 1) {
      std::vector<int> size(size_t(numComp), 0);
      for (int c : comp) ++size[size_t(c)];
      // Component ids follow first appearance, so max_element picks the earliest on ties.
      const int keep = int(std::max_element(size.begin(), size.end()) - size.begin());
      std::vector<int> kept;
      for (size_t i = 0; i < faces.size(); ++i) {
        if (comp[i] == keep) kept.push_back(faces[i]);
      }
      rep.droppedComponents = numComp - 1;
      rep.droppedComponentTriangles = int(faces.size() - kept.size());
      faces.swap(kept);
      he = halfEdges(F, faces);
    }
  }

  // Orientation: flip[f] says whether triangle f is reversed. Across an edge shared by exactly
  // two triangles, they agree when they traverse it in opposite directions.
  std::vector<int> position(size_t(F.rows()), -1);
  for (size_t i = 0; i < faces.size(); ++i) position[size_t(faces[i])] = int(i);
  std::vector<std::vector<std::pair<int, bool>>> adj(faces.size());  // (neighbour, same dir)
  forEachEdge(he, [&](size_t b, size_t e) {
    if (e - b != 2) return;
    const int p = position[size_t(he[b].face)], q = position[size_t(he[b + 1].face)];
    const bool same = he[b].forward == he[b + 1].forward;
    adj[size_t(p)].emplace_back(q, same);
    adj[size_t(q)].emplace_back(p, same);
  });
  std::vector<signed char> flip(faces.size(), -1);
  std::vector<int> queue;
  for (size_t seed = 0; seed < faces.size(); ++seed) {
    if (flip[seed] >= 0) continue;
    flip[seed] = 0;
    queue.assign(1, int(seed));
    for (size_t qi = 0; qi < queue.size(); ++qi) {
      const int p = queue[qi];
      for (const auto& [q, same] : adj[size_t(p)]) {
        if (flip[size_t(q)] >= 0) continue;
        flip[size_t(q)] = static_cast<signed char>(flip[size_t(p)] ^ int(same));
        queue.push_back(q);
      }
    }
  }
  Real vol = 0;
  for (size_t i = 0; i < faces.size(); ++i) {
    const int f = faces[i];
    const Vec3 a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
    vol += (flip[i] ? -1.0 : 1.0) * a.dot(b.cross(c)) / 6.0;
  }
  const int global = vol < 0 ? 1 : 0;
  int reversed = 0;
  for (size_t i = 0; i < faces.size(); ++i) {
    flip[i] = static_cast<signed char>(flip[i] ^ global);
    reversed += flip[i];
    if (flip[i]) std::swap(F(faces[i], 1), F(faces[i], 2));
  }
  if (2 * reversed > int(faces.size())) {
    rep.reversedWhole = true;
    rep.flippedTriangles = int(faces.size()) - reversed;
  } else {
    rep.flippedTriangles = reversed;
  }

  // Compact: keep referenced vertices in their original order.
  std::vector<int> newIndex(size_t(nv), -1);
  for (int f : faces) {
    for (int k = 0; k < 3; ++k) newIndex[size_t(F(f, k))] = 0;
  }
  int kept = 0;
  for (int i = 0; i < nv; ++i) {
    if (newIndex[size_t(i)] == 0) newIndex[size_t(i)] = kept++;
  }
  rep.droppedUnreferenced = nv - kept - rep.weldedVertices;
  SurfaceMesh out;
  out.V.resize(kept, 3);
  for (int i = 0; i < nv; ++i) {
    if (newIndex[size_t(i)] >= 0) out.V.row(newIndex[size_t(i)]) = V.row(i);
  }
  out.F.resize(Eigen::Index(faces.size()), 3);
  for (size_t i = 0; i < faces.size(); ++i) {
    for (int k = 0; k < 3; ++k) out.F(Eigen::Index(i), k) = newIndex[size_t(F(faces[i], k))];
  }
  mesh = std::move(out);
  return rep;
}

}  // namespace deform
