// clipSurfaceByBoxes (box_clip.h): the organ minus fixed boxes is a closed, manifold, outward
// surface whose volume is the analytic difference, with the outside vertices kept bit for bit
// and every cap vertex exactly on its box plane; the edge cases (disjoint box, box around the
// whole organ, overlapping boxes, box planes through vertices and along faces) behave as stated.
#include <deform/geometry/box_clip.h>
#include <deform/geometry/mesh_check.h>
#include <deform/geometry/phantom.h>
#include <deform/sdk/error.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <set>

using namespace deform;

namespace {

Box box(Vec3 lo, Vec3 hi) {
  Box b;
  b.lo = lo;
  b.hi = hi;
  return b;
}

bool strictlyInside(const Box& b, const Vec3& p) {
  return (p.array() > b.lo.array()).all() && (p.array() < b.hi.array()).all();
}

/// Smallest angle of the cap triangles that do not touch the organ's part of the surface: the
/// ones the remeshing shaped (a cap triangle on the cut line can be thin wherever two cut points
/// are close, which keeping the organ's vertices exactly allows).
Real minInteriorCapAngleDeg(const BoxClipResult& r) {
  const MatX3& V = r.surface.V;
  const MatX3i& F = r.surface.F;
  std::vector<char> onOrgan(size_t(V.rows()), 0);
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    if (!r.capFace[size_t(f)])
      for (int k = 0; k < 3; ++k) onOrgan[size_t(F(f, k))] = 1;
  Real worst = 180;
  int counted = 0;
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    if (!r.capFace[size_t(f)] || onOrgan[size_t(F(f, 0))] || onOrgan[size_t(F(f, 1))] ||
        onOrgan[size_t(F(f, 2))])
      continue;
    ++counted;
    for (int k = 0; k < 3; ++k) {
      const Vec3 a = V.row(F(f, k)).transpose();
      const Vec3 u = V.row(F(f, (k + 1) % 3)).transpose() - a;
      const Vec3 w = V.row(F(f, (k + 2) % 3)).transpose() - a;
      worst = std::min(worst, std::atan2(u.cross(w).norm(), u.dot(w)) * 180 / M_PI);
    }
  }
  EXPECT_GT(counted, 0) << "the cap has interior triangles";
  return worst;
}

Real shortestEdge(const SurfaceMesh& s, int v) {
  Real l = std::numeric_limits<Real>::max();
  for (int f = 0; f < s.numFaces(); ++f)
    for (int k = 0; k < 3; ++k)
      if (s.F(f, k) == v)
        for (int j = 1; j < 3; ++j)
          l = std::min(l, (s.V.row(v) - s.V.row(s.F(f, (k + j) % 3))).norm());
  return l;
}

/// Everything the contract promises, for any input and boxes.
void expectValidClip(const SurfaceMesh& in, const std::vector<Box>& boxes, const BoxClipResult& r) {
  const MeshReport rep = validateSurface(r.surface);
  for (const MeshIssue& i : rep.issues)
    if (i.defect != MeshDefect::MultipleComponents) ADD_FAILURE() << i.message;
  EXPECT_GT(signedVolume(r.surface.V, r.surface.F), 0) << "outward";
  ASSERT_EQ(r.inputToClipped.size(), size_t(in.numVertices()));
  ASSERT_EQ(r.capFace.size(), size_t(r.surface.numFaces()));
  int removed = 0, prev = -1, snapped = 0;
  for (int i = 0; i < in.numVertices(); ++i) {
    const Vec3 p = in.V.row(i).transpose();
    bool inClosed = false, inOpen = false;
    for (const Box& b : boxes) {
      inClosed |= b.contains(p);
      inOpen |= strictlyInside(b, p);
    }
    const int c = r.inputToClipped[size_t(i)];
    if (c < 0) {
      ++removed;
      EXPECT_TRUE(inClosed) << "vertex " << i << " outside the boxes was dropped";
      continue;
    }
    EXPECT_GT(c, prev) << "kept vertices keep the input order";
    prev = c;
    const Vec3 q = r.surface.V.row(c).transpose();
    for (const Box& b : boxes)
      EXPECT_FALSE(strictlyInside(b, q)) << "vertex " << i << " kept inside";
    // Bit for bit, not approximately; or snapped onto a box plane by a small move.
    if ((r.surface.V.row(c).array() == in.V.row(i).array()).all()) {
      EXPECT_FALSE(inOpen) << "vertex " << i << " inside a box was kept";
      continue;
    }
    ++snapped;
    EXPECT_LT((q - p).norm(), BoxClipOptions{}.snapFraction * shortestEdge(in, i) * std::sqrt(3.0))
        << "vertex " << i;
    bool onPlane = false;
    for (const Box& b : boxes)
      for (int k = 0; k < 3; ++k) onPlane |= q[k] == b.lo[k] || q[k] == b.hi[k];
    EXPECT_TRUE(onPlane) << "vertex " << i << " moved but not onto a box plane";
  }
  EXPECT_EQ(removed, r.removedInput);
  EXPECT_LE(snapped, r.snappedInput);  // a snapped vertex can end up inside (removed)
  // Kept vertices come first.
  int kept = in.numVertices() - removed;
  for (int i = 0; i < in.numVertices(); ++i)
    if (r.inputToClipped[size_t(i)] >= kept) ADD_FAILURE() << "kept vertex numbered after new ones";
  // Caps: exactly on a box face plane (facesOnBoxFaces compares bit for bit); and nothing of the
  // result enters a box's interior (every triangle centroid outside the open boxes).
  EXPECT_EQ(facesOnBoxFaces(r.surface.V, r.surface.F, boxes), r.capFace);
  for (int f = 0; f < r.surface.numFaces(); ++f) {
    const Vec3 c = (r.surface.V.row(r.surface.F(f, 0)) + r.surface.V.row(r.surface.F(f, 1)) +
                    r.surface.V.row(r.surface.F(f, 2)))
                       .transpose() /
                   3;
    for (const Box& b : boxes) {
      const Vec3 tol = Vec3::Constant(1e-12);
      EXPECT_FALSE(strictlyInside(box(b.lo + tol, b.hi - tol), c)) << "face " << f;
    }
  }
}

// Unit cube [-1, 1]^3 as a grid of n x n split squares per face (vertices on the planes
// x_k = -1 + 2 i / n exactly for even n's halves: 0 is a vertex coordinate).
SurfaceMesh gridCube(int n) {
  SurfaceMesh s;
  std::vector<Vec3> V;
  std::vector<Eigen::Vector3i> F;
  for (int axis = 0; axis < 3; ++axis) {
    for (const int side : {-1, 1}) {
      const int base = int(V.size());
      const int u = (axis + 1) % 3, w = (axis + 2) % 3;
      for (int i = 0; i <= n; ++i)
        for (int j = 0; j <= n; ++j) {
          Vec3 p;
          p[axis] = side;
          p[u] = -1 + 2.0 * i / n;
          p[w] = -1 + 2.0 * j / n;
          V.push_back(p);
        }
      for (int i = 0; i < n; ++i)
        for (int j = 0; j < n; ++j) {
          const int a = base + i * (n + 1) + j, b = a + (n + 1), c = b + 1, d = a + 1;
          if (side > 0) {
            F.emplace_back(a, b, c);
            F.emplace_back(a, c, d);
          } else {
            F.emplace_back(a, c, b);
            F.emplace_back(a, d, c);
          }
        }
    }
  }
  s.V.resize(Eigen::Index(V.size()), 3);
  for (size_t i = 0; i < V.size(); ++i) s.V.row(Eigen::Index(i)) = V[i].transpose();
  s.F.resize(Eigen::Index(F.size()), 3);
  for (size_t i = 0; i < F.size(); ++i) s.F.row(Eigen::Index(i)) = F[i].transpose();
  // Weld the shared edge/corner vertices of the six grids.
  RepairReport rr = repairSurface(s);
  (void)rr;
  return s;
}

}  // namespace

TEST(BoxClip, GridCubeIsAValidClosedSurface) {
  const SurfaceMesh s = gridCube(4);
  EXPECT_TRUE(validateSurface(s).ok());
  EXPECT_NEAR(signedVolume(s.V, s.F), 8.0, 1e-12);
}

TEST(BoxClip, CubeMinusCornerBoxHasTheAnalyticVolume) {
  const SurfaceMesh s = gridCube(4);
  // A corner box whose planes (0.3) cut no vertex: removes [0.3, 1]^3.
  const std::vector<Box> boxes = {box(Vec3::Constant(0.3), Vec3::Constant(2))};
  const BoxClipResult r = clipSurfaceByBoxes(s, boxes);
  expectValidClip(s, boxes, r);
  EXPECT_EQ(r.boxesCut, 1);
  EXPECT_EQ(r.snappedInput, 0) << "no vertex near the planes";
  EXPECT_NEAR(signedVolume(r.surface.V, r.surface.F), 8.0 - std::pow(0.7, 3), 1e-12);
  EXPECT_GT(std::count(r.capFace.begin(), r.capFace.end(), 1), 3);
  EXPECT_GT(r.removedInput, 0);
}

TEST(BoxClip, SphereMinusSlabMatchesTheCapVolumeOfThePolyhedron) {
  // Polyhedral sphere: the removed volume is the part of the polyhedron above z = 0.02; check it
  // against the same polyhedron clipped by the half-space computed independently (tets from the
  // centre, each cut by the plane, exact for a star-shaped polyhedron).
  const SurfaceMesh s = makePhantom("sphere", 1.0);
  const Real zc = 0.02;
  const std::vector<Box> boxes = {box(Vec3(-1, -1, zc), Vec3(1, 1, 1))};
  BoxClipOptions exact;  // no snapping: the volume of this very polyhedron
  exact.snapFraction = 0;
  const BoxClipResult r = clipSurfaceByBoxes(s, boxes, exact);
  expectValidClip(s, boxes, r);
  // Volume below z = zc of the polyhedron: sum over cone tets (origin, triangle) of the part of
  // each tet below the plane, by recursive subdivision-free clipping of a tet against a plane.
  auto clippedTetVolume = [&](const std::array<Vec3, 4>& t) {
    // Clip the tet (convex) by z <= zc: triangulate the clipped polytope from its vertices via
    // the divergence theorem is involved; instead, integrate in z: the cross-section area of a
    // tet is piecewise quadratic in z, so Simpson on pieces between vertex heights is exact.
    std::vector<Real> zs = {t[0].z(), t[1].z(), t[2].z(), t[3].z(), zc};
    std::sort(zs.begin(), zs.end());
    auto area = [&](Real z) {
      // Cross-section of the tet at height z: convex polygon of edge/plane intersections.
      std::vector<Vec3> pts;
      for (int a = 0; a < 4; ++a)
        for (int b = a + 1; b < 4; ++b) {
          const Real za = t[size_t(a)].z(), zb = t[size_t(b)].z();
          if ((za - z) * (zb - z) > 0 || za == zb) continue;
          const Real s2 = (z - za) / (zb - za);
          pts.push_back(t[size_t(a)] + s2 * (t[size_t(b)] - t[size_t(a)]));
        }
      if (pts.size() < 3) return 0.0;
      Vec3 c = Vec3::Zero();
      for (const Vec3& p : pts) c += p;
      c /= Real(pts.size());
      std::sort(pts.begin(), pts.end(), [&](const Vec3& p, const Vec3& q) {
        return std::atan2(p.y() - c.y(), p.x() - c.x()) < std::atan2(q.y() - c.y(), q.x() - c.x());
      });
      Real A = 0;
      for (size_t i = 0; i < pts.size(); ++i) {
        const Vec3& p = pts[i];
        const Vec3& q = pts[(i + 1) % pts.size()];
        A += 0.5 * ((p - c).cross(q - c)).z();
      }
      return std::abs(A);
    };
    Real v = 0;
    for (size_t i = 0; i + 1 < zs.size(); ++i) {
      const Real z0 = zs[i], z1 = std::min(zs[i + 1], zc);
      if (z1 <= z0) continue;
      v +=
          (z1 - z0) / 6 *
          (area(z0 + 1e-15 * (z1 - z0)) + 4 * area(0.5 * (z0 + z1)) + area(z1 - 1e-15 * (z1 - z0)));
    }
    return v;
  };
  Real below = 0;
  for (int f = 0; f < s.numFaces(); ++f)
    below += clippedTetVolume({Vec3::Zero(), s.V.row(s.F(f, 0)).transpose(),
                               s.V.row(s.F(f, 1)).transpose(), s.V.row(s.F(f, 2)).transpose()});
  EXPECT_NEAR(signedVolume(r.surface.V, r.surface.F), below, 1e-9 * below);
  // and it is close to the analytic ball minus its cap (the polyhedron is inscribed).
  const Real R = 0.05, h = R - zc;
  const Real analytic = 4.0 / 3 * M_PI * R * R * R - M_PI * h * h * (3 * R - h) / 3;
  EXPECT_NEAR(signedVolume(r.surface.V, r.surface.F), analytic, 0.01 * analytic);
  // The cap (a disc on z = zc) is remeshed into well-shaped triangles.
  EXPECT_GT(minInteriorCapAngleDeg(r), 12.0);
}

TEST(BoxClip, BoxPlanesThroughVerticesAndAlongFaces) {
  // Box z in [0, 1]: its bottom plane runs through a row of grid vertices and along grid edges,
  // its top plane coincides with the cube's top face. Leaves the lower half.
  const SurfaceMesh s = gridCube(4);
  const std::vector<Box> boxes = {box(Vec3(-2, -2, 0), Vec3(2, 2, 1))};
  const BoxClipResult r = clipSurfaceByBoxes(s, boxes);
  expectValidClip(s, boxes, r);
  EXPECT_NEAR(signedVolume(r.surface.V, r.surface.F), 4.0, 1e-12);
  // Vertices on z = 0 are on the cut: kept (pinned by the closed box), not duplicated.
  for (int i = 0; i < s.numVertices(); ++i)
    if (s.V(i, 2) == 0) {
      EXPECT_GE(r.inputToClipped[size_t(i)], 0) << i;
    }
  // Box whose face x = 1 lies on the cube's face x = 1 (coplanar, touching from outside the
  // organ's interior on one side): removes [0.5, 1] x [-0.5, 0.5] x [-0.5, 0.5].
  const std::vector<Box> side = {box(Vec3(0.5, -0.5, -0.5), Vec3(1, 0.5, 0.5))};
  const BoxClipResult q = clipSurfaceByBoxes(s, side);
  expectValidClip(s, side, q);
  EXPECT_NEAR(signedVolume(q.surface.V, q.surface.F), 8.0 - 0.5, 1e-12);
}

TEST(BoxClip, OverlappingBoxesRemoveTheirUnion) {
  const SurfaceMesh s = gridCube(4);
  const std::vector<Box> boxes = {box(Vec3(0.3, -2, -2), Vec3(2, 2, 2)),
                                  box(Vec3(-2, -0.2, -2), Vec3(2, 2, 2))};
  const BoxClipResult r = clipSurfaceByBoxes(s, boxes);
  expectValidClip(s, boxes, r);
  const Real removed = 0.7 * 2 * 2 + 2 * 1.2 * 2 - 0.7 * 1.2 * 2;
  EXPECT_NEAR(signedVolume(r.surface.V, r.surface.F), 8.0 - removed, 1e-12);
  EXPECT_EQ(r.boxesCut, 2);
}

TEST(BoxClip, DisjointBoxIsANoOp) {
  const SurfaceMesh s = gridCube(3);
  const std::vector<Box> boxes = {box(Vec3(1.5, 1.5, 1.5), Vec3(2, 2, 2)),
                                  box(Vec3(-0.5, -0.5, 1.0), Vec3(0.5, 0.5, 2))};  // touches only
  const BoxClipResult r = clipSurfaceByBoxes(s, boxes);
  EXPECT_EQ(r.boxesCut, 0);
  EXPECT_EQ(r.removedInput, 0);
  ASSERT_EQ(r.surface.numVertices(), s.numVertices());
  EXPECT_TRUE((r.surface.V.array() == s.V.array()).all());
  // The same triangles (each may start at another corner).
  auto triangles = [](const MatX3i& F) {
    std::set<std::array<int, 3>> out;
    for (Eigen::Index f = 0; f < F.rows(); ++f) {
      std::array<int, 3> t = {F(f, 0), F(f, 1), F(f, 2)};
      while (t[0] != std::min({t[0], t[1], t[2]})) t = {t[1], t[2], t[0]};
      out.insert(t);
    }
    return out;
  };
  EXPECT_EQ(triangles(r.surface.F), triangles(s.F));
}

TEST(BoxClip, BoxAroundTheWholeOrganIsAnInputError) {
  const SurfaceMesh s = gridCube(2);
  BoxClipOptions o;
  o.source = "scene.json";
  try {
    clipSurfaceByBoxes(s, {box(Vec3::Constant(-1), Vec3::Constant(1))}, o);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("scene.json"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("whole organ"), std::string::npos) << e.what();
  }
}

TEST(BoxClip, LiverPhantomWithTheLiverPokeBoxes) {
  // The two overlapping boxes of scenes/liver_poke.json on the full phantom.
  const SurfaceMesh s = makePhantom("liver", 1.0);
  const std::vector<Box> boxes = {box(Vec3(-0.11, -0.08, -0.05), Vec3(0.11, -0.035, 0.05)),
                                  box(Vec3(-0.11, -0.08, -0.05), Vec3(0.11, 0.03, -0.032))};
  BoxClipOptions o;
  o.capEdgeLength = 0.003;
  const BoxClipResult r = clipSurfaceByBoxes(s, boxes, o);
  expectValidClip(s, boxes, r);
  EXPECT_EQ(validateSurface(r.surface).ok(), true);
  EXPECT_GT(r.removedInput, 100);
  EXPECT_LT(signedVolume(r.surface.V, r.surface.F), signedVolume(s.V, s.F));
  EXPECT_GT(minInteriorCapAngleDeg(r), 12.0);
}

TEST(BoxClip, BoxStrictlyInsideLeavesACavity) {
  const SurfaceMesh s = gridCube(3);
  const std::vector<Box> boxes = {box(Vec3(-0.2, -0.3, -0.1), Vec3(0.4, 0.1, 0.5))};
  const BoxClipResult r = clipSurfaceByBoxes(s, boxes);
  expectValidClip(s, boxes, r);
  EXPECT_TRUE(validateSurface(r.surface).has(MeshDefect::MultipleComponents));
  EXPECT_NEAR(signedVolume(r.surface.V, r.surface.F), 8.0 - 0.6 * 0.4 * 0.6, 1e-12);
  EXPECT_EQ(r.removedInput, 0);
  EXPECT_EQ(r.boxesCut, 1);
}

TEST(BoxClip, VertexNearAPlaneIsSnappedOntoIt) {
  // Planes a hair (1e-4 of the 0.5 grid edge) off the grid rows z = 0 and x = 0.5: the vertices
  // there move onto them (no sliver strip); with snapFraction 0 they stay bit for bit.
  const SurfaceMesh s = gridCube(4);
  const std::vector<Box> boxes = {box(Vec3(-2, -2, 5e-5), Vec3(0.5 + 5e-5, 2, 2))};
  const BoxClipResult r = clipSurfaceByBoxes(s, boxes);
  {
    SCOPED_TRACE("snapped");
    expectValidClip(s, boxes, r);
  }
  EXPECT_GT(r.snappedInput, 0);
  EXPECT_NEAR(signedVolume(r.surface.V, r.surface.F), 8.0 - (1.5 + 5e-5) * 2 * (1 - 5e-5), 1e-12);
  BoxClipOptions exact;
  exact.snapFraction = 0;
  const BoxClipResult q = clipSurfaceByBoxes(s, boxes, exact);
  // Without snapping every kept vertex is exact, and the 5e-5 wide strips along the cuts are
  // there (triangles the mesh checker calls zero-area: what snapping avoids).
  EXPECT_EQ(q.snappedInput, 0);
  for (int i = 0; i < s.numVertices(); ++i) {
    const int c = q.inputToClipped[size_t(i)];
    if (c >= 0) {
      EXPECT_TRUE((q.surface.V.row(c).array() == s.V.row(i).array()).all()) << i;
    }
  }
  EXPECT_NEAR(signedVolume(q.surface.V, q.surface.F), 8.0 - (1.5 + 5e-5) * 2 * (1 - 5e-5), 1e-12);
}
