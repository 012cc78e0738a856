#include <deform/geometry/voxelize.h>
#include <deform/sdk/error.h>

#include <algorithm>
#include <cmath>
#include <utility>

namespace deform {

Vec3i VoxelGrid::cellOf(const Vec3& p) const {
  const Vec3 q = (p - origin) / cellSize;
  return Vec3i(static_cast<int>(std::floor(q.x())), static_cast<int>(std::floor(q.y())),
               static_cast<int>(std::floor(q.z())));
}

Box VoxelGrid::cellBox(const Vec3i& c) const {
  Box b;
  b.lo = origin + cellSize * c.cast<Real>();
  b.hi = b.lo + Vec3::Constant(cellSize);
  return b;
}

Vec3 VoxelGrid::cellCenter(const Vec3i& c) const {
  return origin + cellSize * (c.cast<Real>() + Vec3::Constant(0.5));
}

Vec3i VoxelGrid::cellAt(long long index) const {
  const long long nxy = static_cast<long long>(dims.x()) * dims.y();
  return Vec3i(static_cast<int>(index % dims.x()), static_cast<int>((index / dims.x()) % dims.y()),
               static_cast<int>(index / nxy));
}

long long VoxelGrid::numCentresInside() const {
  long long n = 0;
  for (std::uint8_t f : centreInside) n += f;
  return n;
}

int VoxelGrid::numInside() const {
  int n = 0;
  for (const Vec3i& c : cells) n += at(c) == CellState::Inside;
  return n;
}

int VoxelGrid::numCrossing() const {
  int n = 0;
  for (const Vec3i& c : cells) n += at(c) == CellState::Crossing;
  return n;
}

bool triangleBoxOverlap(const Vec3& boxCenter, const Vec3& halfSize, const Vec3& a, const Vec3& b,
                        const Vec3& c) {
  const Vec3 v[3] = {a - boxCenter, b - boxCenter, c - boxCenter};
  // Box face normals: the triangle's bounding box against the box.
  for (int i = 0; i < 3; ++i) {
    const Real lo = std::min({v[0][i], v[1][i], v[2][i]});
    const Real hi = std::max({v[0][i], v[1][i], v[2][i]});
    if (lo > halfSize[i] || hi < -halfSize[i]) return false;
  }
  const Vec3 e[3] = {v[1] - v[0], v[2] - v[1], v[0] - v[2]};
  // The nine cross products of box axes and triangle edges.
  for (const Vec3& edge : e) {
    for (int i = 0; i < 3; ++i) {
      const Vec3 axis = Vec3::Unit(i).cross(edge);
      const Real p0 = axis.dot(v[0]), p1 = axis.dot(v[1]), p2 = axis.dot(v[2]);
      const Real r = halfSize.dot(axis.cwiseAbs());
      if (std::min({p0, p1, p2}) > r || std::max({p0, p1, p2}) < -r) return false;
    }
  }
  // The triangle's plane.
  const Vec3 n = e[0].cross(e[1]);
  return std::abs(n.dot(v[0])) <= halfSize.dot(n.cwiseAbs());
}

namespace {

// Sign of orient2d(P, R, q) in the (y, z) plane with q perturbed by (eps, eps^2): exact zeros are
// resolved by the derivative, so no ray ever passes "exactly through" an edge.
int perturbedOrient(const Vec3& P, const Vec3& R, Real qy, Real qz) {
  const Real dy = R.y() - P.y(), dz = R.z() - P.z();
  const Real o = dy * (qz - P.z()) - dz * (qy - P.y());
  if (o > 0) return 1;
  if (o < 0) return -1;
  if (dz != 0) return dz < 0 ? 1 : -1;  // d/dqy = -dz
  if (dy != 0) return dy > 0 ? 1 : -1;  // d/dqz = dy
  return 0;
}

// Same, for the directed edge (i -> j): evaluated with the lower index first so that the two
// triangles sharing an edge get exactly opposite signs.
int edgeOrient(const MatX3& V, int i, int j, Real qy, Real qz, Real* value) {
  const bool flip = j < i;
  const int a = flip ? j : i, b = flip ? i : j;
  const Vec3 P = V.row(a), R = V.row(b);
  const Real o = (R.y() - P.y()) * (qz - P.z()) - (R.z() - P.z()) * (qy - P.y());
  const int s = perturbedOrient(P, R, qy, qz);
  *value = flip ? -o : o;
  return flip ? -s : s;
}

struct Crossing {
  Real x;
  int sign;
  bool operator<(const Crossing& o) const { return x < o.x || (x == o.x && sign < o.sign); }
};

VoxelGrid buildGrid(const SurfaceMesh& s, Real h, long long maxGridCells) {
  if (s.numVertices() == 0 || s.numFaces() == 0) {
    throw InputError("", "voxelize", "empty surface mesh");
  }
  if (!(h > 0) || !std::isfinite(h)) {
    throw InputError("", "voxelize", "cell size must be positive and finite");
  }
  const Box bb = boundingBox(s.V);
  VoxelGrid g;
  g.cellSize = h;
  long long total = 1;
  for (int d = 0; d < 3; ++d) {
    const double n = std::floor(bb.size()[d] / h) + 1.0;
    if (n > 1e9) throw InputError("", "voxelize", "cell size too small for the mesh");
    g.dims[d] = static_cast<int>(n);
    total *= g.dims[d];
  }
  if (total > maxGridCells) {
    throw InputError("", "voxelize",
                     "grid of " + std::to_string(total) + " cells exceeds the limit of " +
                         std::to_string(maxGridCells) + " (cell size too small)");
  }
  g.origin = bb.center() - 0.5 * h * g.dims.cast<Real>();
  g.state.assign(total, CellState::Outside);
  return g;
}

// Classifies the cells of g (state Outside, centreInside empty on entry). clampVertices: mark the
// clamped cell of every vertex Crossing (the default grid contains every vertex); otherwise only
// the vertices inside the grid.
void classify(const SurfaceMesh& s, VoxelGrid& g, bool clampVertices);

}  // namespace

VoxelGrid voxelize(const SurfaceMesh& s, Real h, long long maxGridCells) {
  VoxelGrid g = buildGrid(s, h, maxGridCells);
  classify(s, g, true);
  return g;
}

VoxelGrid voxelizeGrid(const SurfaceMesh& s, const Vec3& origin, Real h, const Vec3i& dims,
                       long long maxGridCells) {
  if (s.numVertices() == 0 || s.numFaces() == 0) {
    throw InputError("", "voxelize", "empty surface mesh");
  }
  if (!(h > 0) || !std::isfinite(h)) {
    throw InputError("", "voxelize", "cell size must be positive and finite");
  }
  if ((dims.array() < 1).any()) throw InputError("", "voxelize", "grid dimensions must be >= 1");
  const long long total = static_cast<long long>(dims.x()) * dims.y() * dims.z();
  if (total > maxGridCells) {
    throw InputError("", "voxelize",
                     "grid of " + std::to_string(total) + " cells exceeds the limit of " +
                         std::to_string(maxGridCells) + " (cell size too small)");
  }
  VoxelGrid g;
  g.origin = origin;
  g.cellSize = h;
  g.dims = dims;
  g.state.assign(total, CellState::Outside);
  classify(s, g, false);
  return g;
}

namespace {

void classify(const SurfaceMesh& s, VoxelGrid& g, bool clampVertices) {
  const Real h = g.cellSize;
  g.centreInside.assign(g.state.size(), 0);
  const Vec3 half = Vec3::Constant(0.5 * h);
  auto clampCell = [&](Vec3i c) {
    for (int d = 0; d < 3; ++d) c[d] = std::clamp(c[d], 0, g.dims[d] - 1);
    return c;
  };

  // 1. Cells crossed by the surface.
  for (int f = 0; f < s.numFaces(); ++f) {
    const Vec3 a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
    const Vec3i lo = clampCell(g.cellOf(a.cwiseMin(b).cwiseMin(c)));
    const Vec3i hi = clampCell(g.cellOf(a.cwiseMax(b).cwiseMax(c)));
    for (int k = lo.z(); k <= hi.z(); ++k) {
      for (int j = lo.y(); j <= hi.y(); ++j) {
        for (int i = lo.x(); i <= hi.x(); ++i) {
          const Vec3i cell(i, j, k);
          CellState& st = g.state[g.linearIndex(cell)];
          if (st == CellState::Crossing) continue;
          if (triangleBoxOverlap(g.cellBox(cell).center(), half, a, b, c)) {
            st = CellState::Crossing;
          }
        }
      }
    }
  }
  // Every vertex's own cell is crossing, even where rounding made the overlap test miss it.
  for (int v = 0; v < s.numVertices(); ++v) {
    const Vec3i c = g.cellOf(s.V.row(v));
    if (clampVertices) {
      g.state[g.linearIndex(clampCell(c))] = CellState::Crossing;
    } else if (g.contains(c)) {
      g.state[g.linearIndex(c)] = CellState::Crossing;
    }
  }

  // 2. Winding number along +x through the centres of each (j, k) row.
  const int ny = g.dims.y(), nz = g.dims.z();
  std::vector<std::vector<Crossing>> rows(static_cast<size_t>(ny) * nz);
  for (int f = 0; f < s.numFaces(); ++f) {
    const int ia = s.F(f, 0), ib = s.F(f, 1), ic = s.F(f, 2);
    const Vec3 a = s.V.row(ia), b = s.V.row(ib), c = s.V.row(ic);
    const Real ylo = std::min({a.y(), b.y(), c.y()}), yhi = std::max({a.y(), b.y(), c.y()});
    const Real zlo = std::min({a.z(), b.z(), c.z()}), zhi = std::max({a.z(), b.z(), c.z()});
    // The rows are widened by one on each side: a ray through a vertex's y or z, rounded one way
    // here and the other in qy, qz, would otherwise be tested against one triangle of the edge it
    // passes and not the other, and lose (or double) its crossing, turning the whole row inside
    // out (the cube at 1 cm and 1 m lost 45 of its 343 cells, at 10 cm none). The exact edge
    // tests below decide; the extra rows cost nothing.
    const int j0 = std::max(0, static_cast<int>(std::ceil((ylo - g.origin.y()) / h - 0.5)) - 1);
    const int j1 =
        std::min(ny - 1, static_cast<int>(std::floor((yhi - g.origin.y()) / h - 0.5)) + 1);
    const int k0 = std::max(0, static_cast<int>(std::ceil((zlo - g.origin.z()) / h - 0.5)) - 1);
    const int k1 =
        std::min(nz - 1, static_cast<int>(std::floor((zhi - g.origin.z()) / h - 0.5)) + 1);
    for (int k = k0; k <= k1; ++k) {
      const Real qz = g.origin.z() + (k + 0.5) * h;
      for (int j = j0; j <= j1; ++j) {
        const Real qy = g.origin.y() + (j + 0.5) * h;
        Real w0, w1, w2;  // barycentric weights times twice the projected area
        const int s0 = edgeOrient(s.V, ib, ic, qy, qz, &w0);
        const int s1 = edgeOrient(s.V, ic, ia, qy, qz, &w1);
        const int s2 = edgeOrient(s.V, ia, ib, qy, qz, &w2);
        if (s0 == 0 || s0 != s1 || s1 != s2) continue;
        const Real sum = w0 + w1 + w2;
        Real x;
        if (sum != 0) {
          x = (w0 * a.x() + w1 * b.x() + w2 * c.x()) / sum;
        } else {
          x = (a.x() + b.x() + c.x()) / 3.0;  // ray grazes a sliver; its position barely matters
        }
        // Projected area has the sign of n_x; entering the solid along +x has n_x < 0.
        rows[static_cast<size_t>(k) * ny + j].push_back({x, -s0});
      }
    }
  }
  for (int k = 0; k < nz; ++k) {
    for (int j = 0; j < ny; ++j) {
      std::vector<Crossing>& row = rows[static_cast<size_t>(k) * ny + j];
      if (row.empty()) continue;
      std::sort(row.begin(), row.end());
      size_t next = 0;
      int winding = 0;
      for (int i = 0; i < g.dims.x(); ++i) {
        const Real xc = g.origin.x() + (i + 0.5) * h;
        while (next < row.size() && row[next].x < xc) winding += row[next++].sign;
        const long long idx = g.linearIndex(Vec3i(i, j, k));
        g.centreInside[idx] = winding != 0 ? 1 : 0;
        CellState& st = g.state[idx];
        if (st == CellState::Outside && winding != 0) st = CellState::Inside;
      }
    }
  }

  for (int k = 0; k < nz; ++k) {
    for (int j = 0; j < ny; ++j) {
      for (int i = 0; i < g.dims.x(); ++i) {
        if (g.state[g.linearIndex(Vec3i(i, j, k))] != CellState::Outside) {
          g.cells.emplace_back(i, j, k);
        }
      }
    }
  }
}

}  // namespace

long long voxelCount(const SurfaceMesh& surface, Real cellSize) {
  return voxelize(surface, cellSize).numCells();
}

Real cellSizeForCount(const SurfaceMesh& surface, long long target, int iterations) {
  if (target < 1) throw InputError("", "voxelize", "target cell count must be >= 1");
  if (surface.numVertices() == 0) throw InputError("", "voxelize", "empty surface mesh");
  const Box bb = boundingBox(surface.V);
  const Vec3 size = bb.size().cwiseMax(1e-12 * bb.diagonal());
  const Real h0 = std::cbrt(size.prod() / static_cast<Real>(target));
  // Bracket: count(hHi) <= target <= count(hLo).
  Real hHi = 2 * h0;
  long long cHi = voxelCount(surface, hHi);
  for (int n = 0; n < 60 && cHi > target; ++n) cHi = voxelCount(surface, hHi *= 2);
  Real hLo = 0.5 * hHi;
  long long cLo = voxelCount(surface, hLo);
  for (int n = 0; n < 60 && cLo < target; ++n) cLo = voxelCount(surface, hLo *= 0.5);
  for (int it = 0; it < iterations && cLo != target && cHi != target; ++it) {
    const Real mid = 0.5 * (hLo + hHi);
    const long long c = voxelCount(surface, mid);
    if (c > target) {
      hLo = mid;
      cLo = c;
    } else {
      hHi = mid;
      cHi = c;
    }
  }
  if (cHi == target) return hHi;
  if (cLo == target) return hLo;
  return (target - cHi <= cLo - target) ? hHi : hLo;
}

}  // namespace deform
