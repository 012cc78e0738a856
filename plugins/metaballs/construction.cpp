#include "construction.h"

#include "electrostatic_optimisation.h"
#include "radius_adjustment.h"
#include "sphere_merging.h"
#include "sphere_packing.h"
#include "vacant_space_filling.h"
#include "voxel_grid.h"

#include <deform/geometry/distance.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

namespace deform::metaballs {

namespace {

/// The surface in the construction's own frame: centred on its bounding box, divided by the box's
/// longest side and rounded to multiples of 2^-32 (1 mm in 4300 km). Every stage decides by
/// comparisons (Delaunay predicates, a voxel centre at exactly half a cell from a face, equal
/// coverage gains), and on a regular mesh many of them are ties that round-off settles: the same
/// organ given in cm or in m (x 0.01 is not exact in binary) then grew a different sphere set
/// (the scaled cube: 101 spheres and 495 links at 1 cm, 100 and 476 at 1 m). In this frame the
/// same shape in any units and at any place is the same input bit for bit, unless a coordinate
/// lies within round-off of a rounding boundary.
struct CanonicalFrame {
  Vec3 centre = Vec3::Zero();
  Real size = 1;
};

SurfaceMesh canonicalSurface(const SurfaceMesh& surface, CanonicalFrame& frame) {
  const Box b = boundingBox(surface.V);
  const Real size = b.size().maxCoeff();
  if (std::isfinite(size) && size > 0) frame = {b.center(), size};
  constexpr Real kQuantum = 0x1p32;
  SurfaceMesh u = surface;
  for (Eigen::Index i = 0; i < u.V.rows(); ++i)
    for (int c = 0; c < 3; ++c)
      u.V(i, c) =
          std::round((surface.V(i, c) - frame.centre(c)) / frame.size * kQuantum) / kQuantum;
  return u;
}

}  // namespace

double ConstructionReport::totalSeconds() const {
  double s = 0;
  for (double x : seconds) s += x;
  return s;
}

Metaballs constructMetaballs(const SurfaceMesh& input, const ConstructionParams& p) {
  CanonicalFrame frame;
  const SurfaceMesh surface = canonicalSurface(input, frame);
  using Clock = std::chrono::steady_clock;
  Metaballs m;
  ConstructionReport& rep = m.report;
  auto t0 = Clock::now();
  auto lap = [&](int stage) {
    const auto t = Clock::now();
    rep.seconds[stage] = std::chrono::duration<double>(t - t0).count();
    t0 = t;
  };
  const MeshDistance dist(surface);
  const VoxelGrid grid = voxelizeInside(surface, p.voxelResolution);
  // Absolute tolerance for "outside": round-off of the distance queries.
  const Real tol = 1e-9 * boundingBox(surface.V).diagonal();

  PackingResult pack = packSpheres(surface, dist, grid, p.targetSpheres);
  rep.medialCandidates = pack.candidates;
  rep.packedSpheres = pack.spheres.size();
  rep.degenerateTets = pack.degenerateTets;
  SphereSet s = std::move(pack.spheres);
  lap(0);

  const RadiusAdjustmentResult adj = adjustRadii(s, dist, 0.5 * grid.cellSize, tol);
  rep.outsideBeforeAdjustment = adj.outsideBefore;
  rep.removedByAdjustment = adj.removedOutsideCentre + adj.removedTooSmall;
  rep.outsideAfterAdjustment = countSpheresOutside(s, dist, tol);
  lap(1);

  if (s.size() == 0) throw std::runtime_error("metaballs: no sphere fits inside the surface");
  std::vector<Real> r(s.radii.data(), s.radii.data() + s.size());
  std::nth_element(r.begin(), r.begin() + long(r.size() / 2), r.end());
  FillParams fp;
  fp.neighbours = p.fillNeighbours;
  fp.minRadius = std::max(0.5 * grid.cellSize, p.fillMinRadiusRatio * r[r.size() / 2]);
  fp.maxGenerations = p.fillMaxGenerations;
  rep.filledSpheres = fillVacantSpace(s, dist, fp).added;
  lap(2);

  rep.mergedPairs = mergeOverlappingSpheres(s, dist).merged;
  lap(3);

  ElectrostaticParams ep;
  ep.rangeVoxels = p.attractionRangeVoxels;
  ep.maxMoves = p.maxOptimisationMoves;
  const ElectrostaticResult er = optimiseElectrostatic(s, grid, dist, ep);
  rep.insideVoxels = er.insideVoxels;
  rep.hollowBefore = er.hollowBefore;
  rep.hollowAfter = er.hollowAfter;
  rep.optimisationMoves = er.moves;
  rep.outsideAfterOptimisation = countSpheresOutside(s, dist, tol);
  lap(4);

  m.topology = buildTopology(s, p.topologyNeighbours);
  rep.spheres = s.size();
  rep.links = int(m.topology.links.rows());
  rep.bridges = m.topology.bridges;
  // Back to the input's frame.
  s.radii *= frame.size;
  s.centers *= frame.size;
  s.centers.rowwise() += frame.centre.transpose();
  m.spheres = std::move(s);
  lap(5);
  return m;
}

std::vector<char> serialiseMetaballs(const Metaballs& m) {
  ByteWriter w;
  w.string(kConstructionVersion);
  w.matrix(m.spheres.centers);
  w.matrix(m.spheres.radii);
  w.matrix(m.topology.links);
  w.pod<long long>((long long)m.topology.selected.size());
  for (const auto& sel : m.topology.selected) {
    w.pod<long long>((long long)sel.size());
    for (int j : sel) w.pod<int>(j);
  }
  w.pod<int>(m.topology.bridges);
  w.pod(m.report);
  return std::move(w.bytes());
}

Metaballs deserialiseMetaballs(const std::vector<char>& bytes) {
  ByteReader rd(bytes);
  Metaballs m;
  if (rd.string() != kConstructionVersion) throw std::runtime_error("metaballs payload: version");
  rd.matrix(m.spheres.centers);
  rd.matrix(m.spheres.radii);
  rd.matrix(m.topology.links);
  const long long n = rd.pod<long long>();
  if (n != m.spheres.size() || m.spheres.centers.rows() != n)
    throw std::runtime_error("metaballs payload: sphere count");
  m.topology.selected.resize(size_t(n));
  for (auto& sel : m.topology.selected) {
    const long long k = rd.pod<long long>();
    if (k < 0 || k > n) throw std::runtime_error("metaballs payload: selection size");
    for (long long q = 0; q < k; ++q) sel.push_back(rd.pod<int>());
  }
  m.topology.bridges = rd.pod<int>();
  m.report = rd.pod<ConstructionReport>();
  for (Eigen::Index l = 0; l < m.topology.links.rows(); ++l)
    for (int c = 0; c < 2; ++c)
      if (m.topology.links(l, c) < 0 || m.topology.links(l, c) >= n)
        throw std::runtime_error("metaballs payload: link index");
  if (!rd.atEnd()) throw std::runtime_error("metaballs payload: trailing bytes");
  return m;
}

}  // namespace deform::metaballs
