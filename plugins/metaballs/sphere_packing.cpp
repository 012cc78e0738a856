#include "sphere_packing.h"

#include <deform/geometry/kdtree.h>
#include <deform/sdk/error.h>

#include "delaunay.h"

#include <algorithm>
#include <queue>

namespace deform::metaballs {

namespace {
// Circumcentre of a tetrahedron; false when it is flat.
bool circumcentre(const Vec3& a, const Vec3& b, const Vec3& c, const Vec3& d, Vec3& out) {
  Mat3 m;
  m.row(0) = (b - a).transpose();
  m.row(1) = (c - a).transpose();
  m.row(2) = (d - a).transpose();
  const Real det = m.determinant();
  const Real scale = (b - a).norm() * (c - a).norm() * (d - a).norm();
  if (!(std::abs(det) > 1e-10 * scale)) return false;
  const Vec3 rhs(0.5 * (b - a).squaredNorm(), 0.5 * (c - a).squaredNorm(),
                 0.5 * (d - a).squaredNorm());
  out = a + m.inverse() * rhs;
  return out.allFinite();
}
}  // namespace

MedialCandidates medialCandidates(const SurfaceMesh& surface, const MeshDistance& dist,
                                  Real minRadius) {
  MedialCandidates out;
  const int n = surface.numVertices();
  // For each sample: best (largest radius) inside Voronoi vertex among its Delaunay tets.
  std::vector<int> poleTet(size_t(n), -1);
  std::vector<Real> poleRadius(size_t(n), -1);
  std::vector<Vec3> tetCentre;
  std::vector<Real> tetRadius;
  std::vector<std::array<int, 4>> del;
  try {
    del = delaunayTetrahedra(surface.V);
  } catch (const std::runtime_error& e) {
    throw InputError("", "metaballs sphere packing", e.what());
  }
  for (const auto& ids : del) {
    ++out.delaunayTets;
    Vec3 c;
    const Vec3 a = surface.V.row(ids[0]);
    if (!circumcentre(a, surface.V.row(ids[1]), surface.V.row(ids[2]), surface.V.row(ids[3]), c)) {
      ++out.degenerateTets;
      continue;
    }
    const Real r = (c - a).norm();
    const int t = int(tetCentre.size());
    tetCentre.push_back(c);
    tetRadius.push_back(r);
    int insideState = -1;  // tested lazily: only tets that would become a pole pay the query
    for (int q = 0; q < 4; ++q) {
      if (r > poleRadius[size_t(ids[q])]) {
        if (insideState < 0) insideState = dist.inside(c) ? 1 : 0;
        if (insideState == 0) break;
        poleRadius[size_t(ids[q])] = r;
        poleTet[size_t(ids[q])] = t;
      }
    }
  }
  std::vector<int> tets;
  for (int t : poleTet)
    if (t >= 0) tets.push_back(t);
  std::sort(tets.begin(), tets.end());
  tets.erase(std::unique(tets.begin(), tets.end()), tets.end());
  std::vector<Real> dvals;
  for (int t : tets) {
    const Vec3& c = tetCentre[size_t(t)];
    const Real d = dist.distance(c);
    if (d < minRadius) continue;
    out.poleBalls.append(c, tetRadius[size_t(t)]);
    dvals.push_back(d);
  }
  out.distance = Eigen::Map<VecX>(dvals.data(), Eigen::Index(dvals.size()));
  return out;
}

PackingResult packSpheres(const SurfaceMesh& surface, const MeshDistance& dist,
                          const VoxelGrid& grid, int target) {
  PackingResult res;
  const MedialCandidates cand = medialCandidates(surface, dist, 0.5 * grid.cellSize);
  res.degenerateTets = cand.degenerateTets;
  // Samples: inside voxel centres, then surface vertices.
  std::vector<int> insideIdx;
  for (size_t i = 0; i < grid.centreInside.size(); ++i)
    if (grid.centreInside[i]) insideIdx.push_back(int(i));
  MatX3 vox(Eigen::Index(insideIdx.size()), 3);
  for (size_t i = 0; i < insideIdx.size(); ++i)
    vox.row(Eigen::Index(i)) = voxelCenter(grid, insideIdx[i]);
  const KdTree3 voxTree(vox);
  const KdTree3 surfTree(surface.V);
  const int nVox = int(insideIdx.size());
  res.samples = nVox + surface.numVertices();
  const Real slack = grid.cellSize;

  // Candidates: the inner poles, then the inside voxel centres (their ball is the largest empty
  // ball there, radius D(c)), so that spheres can also be placed off the medial axis.
  SphereSet all = cand.poleBalls;
  std::vector<Real> dall(cand.distance.data(), cand.distance.data() + cand.distance.size());
  for (size_t i = 0; i < insideIdx.size(); ++i) {
    const Vec3 x = vox.row(Eigen::Index(i)).transpose();
    const Real d = dist.distance(x);
    if (d < 0.5 * grid.cellSize) continue;
    all.append(x, d);
    dall.push_back(d);
  }
  res.candidates = all.size();
  // A candidate covers samples only up to the radius at which `target` balls of equal size would
  // fill the organ twice over: the budget then spreads over the whole body instead of a few
  // medial balls covering everything.
  const Real volume = Real(nVox) * grid.cellSize * grid.cellSize * grid.cellSize;
  const Real cap = std::cbrt(2.0 * volume * 3.0 / (4.0 * 3.14159265358979 * std::max(target, 1)));
  const int nc = all.size();
  std::vector<std::vector<int>> covers(static_cast<size_t>(nc));
  std::vector<int> tmp;
  for (int c = 0; c < nc; ++c) {
    const Vec3 x = all.center(c);
    const Real d = std::min(dall[size_t(c)], cap);
    voxTree.radius(x, d, tmp);
    auto& list = covers[size_t(c)];
    list = tmp;
    surfTree.radius(x, dall[size_t(c)] + slack, tmp);
    for (int s : tmp)
      if ((surface.V.row(s).transpose() - x).norm() <= cap + slack) list.push_back(nVox + s);
  }
  std::vector<uint8_t> covered(size_t(res.samples), 0);
  // Lazy greedy: gains only shrink, so a popped entry whose recomputed gain still equals its key
  // is the true maximum. Key (gain, -index) breaks ties towards the lower index.
  std::priority_queue<std::pair<long long, int>> pq;
  for (int c = 0; c < nc; ++c) pq.push({(long long)covers[size_t(c)].size(), -c});
  std::vector<int> chosen;
  while ((int)chosen.size() < target && !pq.empty()) {
    const auto [g, negc] = pq.top();
    pq.pop();
    const int c = -negc;
    long long now = 0;
    for (int s : covers[size_t(c)]) now += covered[size_t(s)] ? 0 : 1;
    if (now == 0) continue;
    if (now < g) {
      pq.push({now, negc});
      continue;
    }
    chosen.push_back(c);
    for (int s : covers[size_t(c)]) {
      if (!covered[size_t(s)]) {
        covered[size_t(s)] = 1;
        ++res.coveredSamples;
      }
    }
  }
  std::sort(chosen.begin(), chosen.end());
  for (int c : chosen) res.spheres.append(all.center(c), all.radii(c));
  return res;
}

}  // namespace deform::metaballs
