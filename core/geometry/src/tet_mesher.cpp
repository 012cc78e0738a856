#include "gmsh_mesher.h"

#include <deform/geometry/mesh_check.h>
#include <deform/geometry/tet_mesher.h>
#include <deform/internal/component.h>
#include <deform/sdk/cache.h>
#include <deform/sdk/error.h>

#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>
#include <mutex>
#include <queue>
#include <unordered_map>

namespace deform {

namespace {

using Clock = std::chrono::steady_clock;

std::uint64_t edgeKey(int a, int b) {
  if (a > b) std::swap(a, b);
  return (std::uint64_t(std::uint32_t(a)) << 32) | std::uint32_t(b);
}

/// "" when every edge is used by exactly two triangles, else a short reason.
std::string closednessProblem(const SurfaceMesh& s) {
  if (s.numVertices() < 4 || s.numFaces() < 4) return "fewer than 4 vertices or triangles";
  std::unordered_map<std::uint64_t, int> uses;
  uses.reserve(3 * s.F.rows());
  for (Eigen::Index f = 0; f < s.F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const int a = s.F(f, k), b = s.F(f, (k + 1) % 3);
      if (a < 0 || b < 0 || a >= s.numVertices() || b >= s.numVertices())
        return "triangle " + std::to_string(f) + " has a vertex index out of range";
      if (a == b) return "triangle " + std::to_string(f) + " repeats a vertex";
      ++uses[edgeKey(a, b)];
    }
  }
  long long open = 0, nonManifold = 0;
  for (const auto& [k, n] : uses) {
    if (n == 1) ++open;
    if (n > 2) ++nonManifold;
  }
  if (open > 0) return "surface is not closed (" + std::to_string(open) + " boundary edges)";
  if (nonManifold > 0)
    return "surface is not manifold (" + std::to_string(nonManifold) + " edges with >2 triangles)";
  if (!s.V.allFinite()) return "non-finite vertex coordinates";
  return "";
}

#ifdef DEFORM_HAVE_GMSH
/// Gmsh's tets of s at size h, from the back end's shared object.
GmshOutput runGmsh(GmshTetrahedralize mesh, const SurfaceMesh& s, Real h, const GmshSize& size) {
  GmshOutput out;
  mesh(s, h, size, out);
  return out;
}
#endif

std::vector<char> serialise(const GmshOutput& o) {
  ByteWriter w;
  w.string(o.error);
  w.matrix(o.V);
  w.matrix(o.T);
  return std::move(w.bytes());
}

bool writeAll(int fd, const char* p, size_t n) {
  while (n > 0) {
    const ssize_t k = ::write(fd, p, n);
    if (k < 0) {
      if (errno == EINTR) continue;
      return false;
    }
    p += k;
    n -= size_t(k);
  }
  return true;
}

/// Runs Gmsh in a forked child with a wall-clock limit. Falls back to running in-process when
/// fork() is unavailable.
GmshOutput runGmshIsolated(const SurfaceMesh& s, Real h, const GmshSize& sizeAt,
                           Real timeoutSeconds) {
#ifndef DEFORM_HAVE_GMSH
  (void)s, (void)h, (void)sizeAt, (void)timeoutSeconds;
  GmshOutput o;
  o.error = "deformbench was built without Gmsh";
  return o;
#else
  static std::mutex gmshMutex;
  std::lock_guard<std::mutex> lock(gmshMutex);
  // Loaded here, in the parent, so that the child only calls it.
  GmshTetrahedralize mesh = nullptr;
  try {
    mesh = reinterpret_cast<GmshTetrahedralize>(
        coreComponentSymbol(kGmshLibrary, kGmshEntry, "tetrahedral meshing"));
  } catch (const std::exception& e) {
    GmshOutput o;
    o.error = e.what();
    return o;
  }
  int fds[2];
  if (::pipe(fds) != 0) return runGmsh(mesh, s, h, sizeAt);
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fds[0]);
    ::close(fds[1]);
    return runGmsh(mesh, s, h, sizeAt);
  }
  if (pid == 0) {
    ::close(fds[0]);
    const int devnull = ::open("/dev/null", O_WRONLY);
    if (devnull >= 0) {  // Gmsh may still print on fatal paths; keep the parent's output clean
      ::dup2(devnull, 1);
      ::dup2(devnull, 2);
    }
    const std::vector<char> bytes = serialise(runGmsh(mesh, s, h, sizeAt));
    const long long size = static_cast<long long>(bytes.size());
    const bool ok = writeAll(fds[1], reinterpret_cast<const char*>(&size), sizeof size) &&
                    writeAll(fds[1], bytes.data(), bytes.size());
    ::close(fds[1]);
    ::_exit(ok ? 0 : 1);
  }
  ::close(fds[1]);
  GmshOutput out;
  std::vector<char> buf;
  const auto deadline = Clock::now() + std::chrono::duration<double>(timeoutSeconds);
  bool timedOut = false;
  char chunk[1 << 16];
  for (;;) {
    const double left = std::chrono::duration<double>(deadline - Clock::now()).count();
    if (left <= 0) {
      timedOut = true;
      break;
    }
    pollfd p{fds[0], POLLIN, 0};
    const int r = ::poll(&p, 1, int(std::min(left * 1000.0 + 1, 1e9)));
    if (r < 0 && errno == EINTR) continue;
    if (r == 0) continue;
    const ssize_t k = ::read(fds[0], chunk, sizeof chunk);
    if (k < 0 && errno == EINTR) continue;
    if (k <= 0) break;  // EOF (child done or dead) or error
    buf.insert(buf.end(), chunk, chunk + k);
  }
  ::close(fds[0]);
  if (timedOut) ::kill(pid, SIGKILL);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (timedOut) {
    out.error = "Gmsh did not finish within " + std::to_string(timeoutSeconds) + " s";
    return out;
  }
  if (WIFSIGNALED(status)) {
    out.error = std::string("Gmsh crashed (") + strsignal(WTERMSIG(status)) + ")";
    return out;
  }
  try {
    if (buf.size() < sizeof(long long)) throw std::runtime_error("short");
    long long size = 0;
    std::memcpy(&size, buf.data(), sizeof size);
    if (size != static_cast<long long>(buf.size() - sizeof size)) throw std::runtime_error("size");
    std::vector<char> payload(buf.begin() + sizeof size, buf.end());
    ByteReader r(payload);
    out.error = r.string();
    r.matrix(out.V);
    r.matrix(out.T);
  } catch (const std::exception&) {
    out.error = "the Gmsh child process returned no result";
  }
  return out;
#endif
}

/// Sorted triangles (as sorted index triples) of a face list, for comparing boundaries.
std::vector<std::array<int, 3>> sortedTriangles(const MatX3i& F) {
  std::vector<std::array<int, 3>> t(size_t(F.rows()));
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    t[size_t(f)] = {F(f, 0), F(f, 1), F(f, 2)};
    std::sort(t[size_t(f)].begin(), t[size_t(f)].end());
  }
  std::sort(t.begin(), t.end());
  return t;
}

Real dihedralAngles(const std::array<Vec3, 4>& x, Real& minDeg, Real& maxDeg) {
  // Outward face normals; dihedral angle at the edge shared by faces i, j is pi - angle(ni, nj).
  static const int faces[4][3] = {{1, 2, 3}, {0, 3, 2}, {0, 1, 3}, {0, 2, 1}};
  Vec3 nrm[4];
  for (int f = 0; f < 4; ++f) {
    nrm[f] = (x[faces[f][1]] - x[faces[f][0]]).cross(x[faces[f][2]] - x[faces[f][0]]);
    const Real l = nrm[f].norm();
    if (l > 0) nrm[f] /= l;
  }
  minDeg = 180, maxDeg = 0;
  for (int i = 0; i < 4; ++i)
    for (int j = i + 1; j < 4; ++j) {
      const Real c = std::clamp(-nrm[i].dot(nrm[j]), Real(-1), Real(1));
      const Real a = std::acos(c) * 180.0 / M_PI;
      minDeg = std::min(minDeg, a);
      maxDeg = std::max(maxDeg, a);
    }
  return minDeg;
}

}  // namespace

Real edgeLengthForElements(Real volume, long long elements) {
  // N ~ c V / h^3. A regular tet of edge h has volume h^3 / (6 sqrt 2), i.e. c = 8.49; Gmsh's
  // Delaunay meshes at uniform size h have about 6.6 tets per h^3 (measured on a sphere and a
  // box, 2k-200k tets).
  constexpr Real kTetsPerCube = 6.6;
  return std::cbrt(kTetsPerCube * std::max<Real>(volume, 0) / Real(std::max(1LL, elements)));
}

SurfaceMesh refineSurfaceEdges(const SurfaceMesh& surface, Real maxEdge,
                               const MeshGrading& grading) {
  std::vector<Vec3> V;
  V.reserve(size_t(surface.numVertices()));
  for (int i = 0; i < surface.numVertices(); ++i) V.push_back(surface.V.row(i).transpose());
  std::vector<std::array<int, 3>> F(size_t(surface.numFaces()));
  std::unordered_map<std::uint64_t, std::array<int, 2>> edgeFacesMap;
  auto attach = [&](int a, int b, int f) {
    auto [it, fresh] = edgeFacesMap.try_emplace(edgeKey(a, b), std::array<int, 2>{-1, -1});
    (it->second[0] < 0 ? it->second[0] : it->second[1]) = f;
  };
  auto replace = [&](int a, int b, int from, int to) {
    auto& e = edgeFacesMap.at(edgeKey(a, b));
    (e[0] == from ? e[0] : e[1]) = to;
  };
  for (int f = 0; f < surface.numFaces(); ++f) {
    F[size_t(f)] = {surface.F(f, 0), surface.F(f, 1), surface.F(f, 2)};
    for (int k = 0; k < 3; ++k) attach(F[size_t(f)][k], F[size_t(f)][(k + 1) % 3], f);
  }
  // Longest first; ties by key, so the result does not depend on hash order.
  using Item = std::pair<Real, std::uint64_t>;
  auto cmp = [](const Item& a, const Item& b) {
    return a.first < b.first || (a.first == b.first && a.second > b.second);
  };
  std::priority_queue<Item, std::vector<Item>, decltype(cmp)> queue(cmp);
  auto push = [&](int a, int b) {
    const Real l = (V[size_t(a)] - V[size_t(b)]).norm();
    if (l > grading.size(0.5 * (V[size_t(a)] + V[size_t(b)]), maxEdge))
      queue.emplace(l, edgeKey(a, b));
  };
  for (const auto& [key, faces] : edgeFacesMap) push(int(key >> 32), int(key & 0xffffffffu));
  while (!queue.empty()) {
    const std::uint64_t key = queue.top().second;
    queue.pop();
    auto it = edgeFacesMap.find(key);
    if (it == edgeFacesMap.end()) continue;
    const int f1 = it->second[0], f2 = it->second[1];
    if (f1 < 0 || f2 < 0) continue;  // open edge: not expected on a closed surface
    // Rotate f1 so that it reads (p, q, c) with the directed edge p->q; f2 then has q->p.
    auto rotateTo = [&](int f, int first, int second) {
      auto& t = F[size_t(f)];
      for (int r = 0; r < 3; ++r) {
        if (t[0] == first && t[1] == second) return;
        t = {t[1], t[2], t[0]};
      }
    };
    const int a = int(key >> 32), b = int(key & 0xffffffffu);
    int p = a, q = b;
    {
      const auto& t = F[size_t(f1)];
      bool forward = false;
      for (int k = 0; k < 3; ++k) forward |= (t[k] == a && t[(k + 1) % 3] == b);
      if (!forward) std::swap(p, q);
    }
    rotateTo(f1, p, q);
    rotateTo(f2, q, p);
    const int c = F[size_t(f1)][2], d = F[size_t(f2)][2];
    const int m = int(V.size());
    V.push_back(0.5 * (V[size_t(p)] + V[size_t(q)]));
    const int g1 = int(F.size()), g2 = g1 + 1;
    F[size_t(f1)] = {p, m, c};
    F.push_back({m, q, c});
    F[size_t(f2)] = {q, m, d};
    F.push_back({m, p, d});
    edgeFacesMap.erase(it);
    edgeFacesMap[edgeKey(p, m)] = {f1, g2};
    edgeFacesMap[edgeKey(m, q)] = {g1, f2};
    edgeFacesMap[edgeKey(m, c)] = {f1, g1};
    edgeFacesMap[edgeKey(m, d)] = {f2, g2};
    replace(q, c, f1, g1);
    replace(p, d, f2, g2);
    push(p, m);
    push(m, q);
    push(m, c);
    push(m, d);
  }
  SurfaceMesh out;
  out.V.resize(Eigen::Index(V.size()), 3);
  for (size_t i = 0; i < V.size(); ++i) out.V.row(Eigen::Index(i)) = V[i].transpose();
  out.F.resize(Eigen::Index(F.size()), 3);
  for (size_t f = 0; f < F.size(); ++f) out.F.row(Eigen::Index(f)) << F[f][0], F[f][1], F[f][2];
  return out;
}

TetMesh surfaceVolumeCached(const SurfaceMesh& surface, long long elements,
                            const std::string& source, Cache& cache) {
  CacheKey key;
  key.add("tets.surface/1").add(surface.V).add(surface.F).add(elements);
  const int nv = surface.numVertices();
  if (auto hit = cache.get("tets.surface", key)) {
    try {
      ByteReader r(*hit);
      TetMesh m;
      r.matrix(m.V);
      r.matrix(m.T);
      if (m.numVertices() >= nv && m.numTets() > 0 && m.V.topRows(nv) == surface.V) return m;
    } catch (const std::exception&) {
      // unreadable entry: mesh again
    }
    cache.reject("tets.surface", key);
  }
  TetMeshOptions o;
  o.targetElements = elements;
  o.source = source;
  TetMeshResult r = tetrahedralize(surface, o);
  if (r.inputVertices != nv || r.mesh.numVertices() < nv || r.mesh.V.topRows(nv) != surface.V)
    throw InputError(source, "", "cannot tetrahedralise: the mesher changed the surface");
  ByteWriter w;
  w.matrix(r.mesh.V);
  w.matrix(r.mesh.T);
  cache.put("tets.surface", key, w.bytes());
  return std::move(r.mesh);
}

TetMeshQuality tetMeshQuality(const TetMesh& mesh) {
  TetMeshQuality q;
  q.elements = mesh.numTets();
  q.nodes = mesh.numVertices();
  q.minDihedralDeg = 180;
  q.maxDihedralDeg = 0;
  q.minMeanRatio = 1;
  for (int t = 0; t < mesh.numTets(); ++t) {
    std::array<Vec3, 4> x;
    for (int k = 0; k < 4; ++k) x[k] = mesh.V.row(mesh.T(t, k)).transpose();
    const Real vol = tetVolume(x[0], x[1], x[2], x[3]);
    if (!(vol > 0)) {
      ++q.degenerate;
      q.minMeanRatio = 0;
      continue;
    }
    Real lo, hi;
    dihedralAngles(x, lo, hi);
    q.minDihedralDeg = std::min(q.minDihedralDeg, lo);
    q.maxDihedralDeg = std::max(q.maxDihedralDeg, hi);
    Real sumSq = 0;
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j) sumSq += (x[i] - x[j]).squaredNorm();
    q.minMeanRatio = std::min(q.minMeanRatio, 12.0 * std::pow(3.0 * vol, 2.0 / 3.0) / sumSq);
  }
  if (mesh.numTets() == 0) q.minDihedralDeg = q.maxDihedralDeg = q.minMeanRatio = 0;
  return q;
}

TetMeshResult tetrahedralize(const SurfaceMesh& input, const TetMeshOptions& options) {
  const auto start = Clock::now();
  auto fail = [&](const std::string& why) {
    return InputError(options.source, "", "cannot tetrahedralise: " + why);
  };
  if (const std::string why = closednessProblem(input); !why.empty()) throw fail(why);
  if (options.checkSelfIntersections) {
    const SelfIntersectionReport si = findSelfIntersections(input, 1);
    if (!si.ok()) {
      throw fail("the surface self-intersects: " + si.message() +
                 " (\"repair\": true in the scene's organ untangles small folds by local "
                 "smoothing; otherwise remesh or edit the surface so that it bounds a valid "
                 "volume)");
    }
  }
  const Real volume = signedVolume(input.V, input.F);
  if (!(volume > 0)) throw fail("surface encloses no positive volume (inward or self-overlapping)");

  TetMeshResult result;
  result.inputVertices = input.numVertices();
  result.edgeLength = options.edgeLength > 0
                          ? options.edgeLength
                          : edgeLengthForElements(volume, options.targetElements);
  if (!(result.edgeLength > 0) || !std::isfinite(result.edgeLength))
    throw fail("invalid target edge length");
  if (options.grading.active() && !(options.grading.ratio > 0)) throw fail("invalid grading ratio");
  result.boundary =
      options.refineSurface ? refineSurfaceEdges(input, result.edgeLength, options.grading) : input;

  GmshSize size;
  if (options.grading.active())
    size = [g = options.grading, h = result.edgeLength](const Vec3& x) { return g.size(x, h); };
  GmshOutput g = runGmshIsolated(result.boundary, result.edgeLength, size, options.timeoutSeconds);
  if (!g.error.empty()) throw fail(g.error);

  result.mesh.V = std::move(g.V);
  result.mesh.T = std::move(g.T);
  orientTetsPositive(result.mesh);
  // The tets' boundary must be exactly the surface we gave Gmsh (no Steiner points on it).
  const SurfaceMesh b = tetBoundary(result.mesh);
  if (sortedTriangles(b.F) != sortedTriangles(result.boundary.F))
    throw fail(
        "the mesher changed the surface (boundary recovery inserted points: the surface "
        "may self-intersect)");
  result.quality = tetMeshQuality(result.mesh);
  result.seconds = std::chrono::duration<double>(Clock::now() - start).count();
  return result;
}

}  // namespace deform
