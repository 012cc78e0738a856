// findSelfIntersections / requireNoSelfIntersections (mesh_check.h) and the refusal of a
// self-intersecting surface by tetrahedralize() before Gmsh runs.
#include <deform/geometry/mesh_check.h>
#include <deform/geometry/mesh_io.h>
#include <deform/geometry/phantom.h>
#include <deform/geometry/tet_mesher.h>
#include <deform/sdk/error.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <set>

#include "mesh_test_util.h"

namespace deform {
namespace {

/// Closed axis-aligned box [lo, hi], 8 vertices, 12 outward triangles.
SurfaceMesh box(const Vec3& lo, const Vec3& hi) {
  SurfaceMesh m;
  m.V.resize(8, 3);
  for (int i = 0; i < 8; ++i) {
    m.V.row(i) << ((i & 1) ? hi.x() : lo.x()), ((i & 2) ? hi.y() : lo.y()),
        ((i & 4) ? hi.z() : lo.z());
  }
  m.F.resize(12, 3);
  m.F << 0, 2, 1, 1, 2, 3,  // z = lo
      4, 5, 6, 5, 7, 6,     // z = hi
      0, 1, 4, 1, 5, 4,     // y = lo
      2, 6, 3, 3, 6, 7,     // y = hi
      0, 4, 2, 2, 4, 6,     // x = lo
      1, 3, 5, 3, 7, 5;     // x = hi
  return m;
}

SurfaceMesh merged(const SurfaceMesh& a, const SurfaceMesh& b) {
  SurfaceMesh m;
  m.V.resize(a.V.rows() + b.V.rows(), 3);
  m.V << a.V, b.V;
  m.F.resize(a.F.rows() + b.F.rows(), 3);
  m.F << a.F, (b.F.array() + a.numVertices()).matrix();
  return m;
}

SurfaceMesh triangles(const std::vector<Vec3>& V, const std::vector<std::array<int, 3>>& F) {
  SurfaceMesh m;
  m.V.resize(Eigen::Index(V.size()), 3);
  for (size_t i = 0; i < V.size(); ++i) m.V.row(Eigen::Index(i)) = V[i].transpose();
  m.F.resize(Eigen::Index(F.size()), 3);
  for (size_t f = 0; f < F.size(); ++f) m.F.row(Eigen::Index(f)) << F[f][0], F[f][1], F[f][2];
  return m;
}

/// A strip extruded along y (width 1, two rows of vertices) following the polyline `xz` in the
/// x-z plane; two triangles per segment, segment s owns triangles 2s and 2s+1.
SurfaceMesh strip(const std::vector<std::array<Real, 2>>& xz) {
  std::vector<Vec3> V;
  std::vector<std::array<int, 3>> F;
  for (const auto& p : xz) {
    V.emplace_back(p[0], 0, p[1]);
    V.emplace_back(p[0], 1, p[1]);
  }
  for (int s = 0; s + 1 < int(xz.size()); ++s) {
    const int a = 2 * s, b = a + 1, c = a + 2, d = a + 3;
    F.push_back({a, c, b});
    F.push_back({b, c, d});
  }
  return triangles(V, F);
}

TEST(SelfIntersection, InterpenetratingBoxesAreFoundAndEveryPairCrossesBetweenThem) {
  const SurfaceMesh m = merged(box({0, 0, 0}, {1, 1, 1}), box({0.5, 0.4, 0.3}, {1.5, 1.4, 1.3}));
  const SelfIntersectionReport r = findSelfIntersections(m, 1000);
  ASSERT_GT(r.pairs, 0);
  ASSERT_EQ(r.listed.size(), size_t(r.pairs));
  // Each box alone is clean, so every pair has one triangle in each box (0..11 and 12..23).
  for (const auto& p : r.listed) {
    EXPECT_LT(p[0], 12);
    EXPECT_GE(p[1], 12);
  }
  // The surfaces cross on three faces of each box: every one of those six faces takes part.
  std::set<int> faces;
  for (const auto& p : r.listed) faces.insert(p[0] / 2), faces.insert(p[1] / 2);
  EXPECT_EQ(faces, (std::set<int>{1, 3, 5, 6, 8, 10}));
  EXPECT_NE(r.message().find("pairs of self-intersecting triangles (first: "), std::string::npos)
      << r.message();
}

TEST(SelfIntersection, SeparatedTouchingAndNestedBoxesDoNotIntersect) {
  // Apart.
  EXPECT_EQ(
      findSelfIntersections(merged(box({0, 0, 0}, {1, 1, 1}), box({2, 0, 0}, {3, 1, 1}))).pairs, 0);
  // Nested without touching: two components, but no surface crosses another.
  EXPECT_EQ(findSelfIntersections(
                merged(box({0, 0, 0}, {1, 1, 1}), box({0.25, 0.25, 0.25}, {0.75, 0.75, 0.75})))
                .pairs,
            0);
  // Edge to edge along a line (x = 1, z = 1): touching only.
  EXPECT_EQ(
      findSelfIntersections(merged(box({0, 0, 0}, {1, 1, 1}), box({1, 0.2, 1}, {2, 0.8, 2}))).pairs,
      0);
}

TEST(SelfIntersection, CoincidentFacesOfTwoBoxesOverlapInTheirPlane) {
  // Box B's face x = 1 lies inside box A's face x = 1 (a coplanar overlap with positive area).
  const SurfaceMesh m = merged(box({0, 0, 0}, {1, 1, 1}), box({1, 0.2, 0.2}, {2, 0.8, 0.8}));
  const SelfIntersectionReport r = findSelfIntersections(m, 1000);
  ASSERT_GT(r.pairs, 0);
  for (const auto& p : r.listed) {
    EXPECT_TRUE(p[0] == 10 || p[0] == 11) << p[0];          // A's face x = hi
    EXPECT_TRUE(p[1] == 12 + 8 || p[1] == 12 + 9) << p[1];  // B's face x = lo
  }
}

TEST(SelfIntersection, FoldedSheetPassingThroughItself) {
  // Flat from x = 0 to 2, up to (2, 0.3), then back down through the flat part to (0.5, -0.3).
  const SurfaceMesh m = strip({{0, 0}, {1, 0}, {2, 0}, {2, 0.3}, {0.5, -0.3}});
  const SelfIntersectionReport r = findSelfIntersections(m, 1000);
  ASSERT_GT(r.pairs, 0);
  for (const auto& p : r.listed) {
    // The last segment (triangles 6, 7) crosses the flat segment x in [1, 2] (triangles 2, 3).
    EXPECT_TRUE(p[0] == 2 || p[0] == 3) << p[0];
    EXPECT_TRUE(p[1] == 6 || p[1] == 7) << p[1];
  }
  // The same sheet folded back above itself (never crossing) is clean.
  EXPECT_EQ(findSelfIntersections(strip({{0, 0}, {1, 0}, {2, 0}, {2, 0.3}, {0.5, 0.1}})).pairs, 0);
}

TEST(SelfIntersection, NeighboursSharingAVertex) {
  // B shares vertex 0 with A; B's opposite edge pierces A at (0.25, 0.25, 0).
  const std::vector<Vec3> V = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.2, 0.2, -1}, {0.3, 0.3, 1}};
  EXPECT_EQ(findSelfIntersections(triangles(V, {{0, 1, 2}, {0, 3, 4}})).pairs, 1);
  // The same edge ending below A: no crossing.
  std::vector<Vec3> W = V;
  W[4] = {0.3, 0.3, -0.5};
  EXPECT_EQ(findSelfIntersections(triangles(W, {{0, 1, 2}, {0, 3, 4}})).pairs, 0);
  // Coplanar fans: overlapping sectors at the shared vertex intersect, adjacent sectors do not.
  const std::vector<Vec3> P = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}, {-1, 1, 0}};
  EXPECT_EQ(findSelfIntersections(triangles(P, {{0, 1, 2}, {0, 3, 4}})).pairs, 1);
  EXPECT_EQ(findSelfIntersections(triangles(P, {{0, 1, 3}, {0, 2, 4}})).pairs, 0);
}

TEST(SelfIntersection, NeighboursSharingAnEdge) {
  const std::vector<Vec3> flatFold = {{0, 0, 0}, {1, 0, 0}, {0.5, 1, 0}, {0.3, 0.8, 0}};
  EXPECT_EQ(findSelfIntersections(triangles(flatFold, {{0, 1, 2}, {1, 0, 3}})).pairs, 1);
  const std::vector<Vec3> flat = {{0, 0, 0}, {1, 0, 0}, {0.5, 1, 0}, {0.3, -0.8, 0}};
  EXPECT_EQ(findSelfIntersections(triangles(flat, {{0, 1, 2}, {1, 0, 3}})).pairs, 0);
  const std::vector<Vec3> sharp = {{0, 0, 0}, {1, 0, 0}, {0.5, 1, 0}, {0.3, 0.8, 0.01}};
  EXPECT_EQ(findSelfIntersections(triangles(sharp, {{0, 1, 2}, {1, 0, 3}})).pairs, 0);
}

TEST(SelfIntersection, CoplanarTrianglesWithoutSharedVertices) {
  const std::vector<Vec3> V = {{0, 0, 0},     {2, 0, 0},   {0, 2, 0},
                               {0.5, 0.5, 0}, {3, 0.5, 0}, {0.5, 3, 0}};
  EXPECT_EQ(findSelfIntersections(triangles(V, {{0, 1, 2}, {3, 4, 5}})).pairs, 1);
  std::vector<Vec3> W = V;
  for (int i = 3; i < 6; ++i) W[size_t(i)] += Vec3(5, 0, 0);
  EXPECT_EQ(findSelfIntersections(triangles(W, {{0, 1, 2}, {3, 4, 5}})).pairs, 0);
  // Small triangle strictly inside a large one, same plane.
  const std::vector<Vec3> N = {{0, 0, 0},     {4, 0, 0},   {0, 4, 0},
                               {0.5, 0.5, 0}, {1, 0.5, 0}, {0.5, 1, 0}};
  EXPECT_EQ(findSelfIntersections(triangles(N, {{0, 1, 2}, {3, 4, 5}})).pairs, 1);
}

TEST(SelfIntersection, CleanPhantomsHaveNone) {
  for (const char* name : {"liver", "gallbladder", "stomach", "intestine", "cube", "sphere"}) {
    const SurfaceMesh m = makePhantom(name);
    const SelfIntersectionReport r = findSelfIntersections(m);
    EXPECT_EQ(r.pairs, 0) << name << ": " << r.message();
    EXPECT_GT(r.candidates, m.numFaces()) << name;  // the broadphase found the neighbours
    EXPECT_NO_THROW(requireNoSelfIntersections(m, std::string("phantom:") + name));
  }
}

TEST(SelfIntersection, InvalidTrianglesAreSkippedNotCrashedOn) {
  SurfaceMesh m = merged(box({0, 0, 0}, {1, 1, 1}), box({0.5, 0.4, 0.3}, {1.5, 1.4, 1.3}));
  const long long before = findSelfIntersections(m).pairs;
  m.V.conservativeResize(m.V.rows() + 1, 3);
  m.V.row(m.V.rows() - 1) << std::nan(""), 0, 0;
  m.F.conservativeResize(m.F.rows() + 3, 3);
  m.F.row(m.F.rows() - 3) << 0, 1, 99;                   // out of range
  m.F.row(m.F.rows() - 2) << 0, 0, 1;                    // repeated index
  m.F.row(m.F.rows() - 1) << 0, 1, int(m.V.rows() - 1);  // NaN corner
  EXPECT_EQ(findSelfIntersections(m).pairs, before);
  EXPECT_EQ(findSelfIntersections(SurfaceMesh{}).pairs, 0);
}

TEST(SelfIntersection, RequireNamesTheFileThePairAndWhatToDo) {
  const SurfaceMesh m = strip({{0, 0}, {1, 0}, {2, 0}, {2, 0.3}, {0.5, -0.3}});
  try {
    requireNoSelfIntersections(m, "organ.obj");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "organ.obj");
    const std::string w = e.what();
    EXPECT_EQ(w.rfind("organ.obj: ", 0), 0u) << w;
    const SelfIntersectionReport r = findSelfIntersections(m);
    const std::string first =
        std::to_string(r.listed[0][0]) + " and " + std::to_string(r.listed[0][1]);
    EXPECT_NE(w.find(first), std::string::npos) << w;
    EXPECT_NE(w.find("self-intersecting triangles"), std::string::npos) << w;
    EXPECT_NE(w.find("\"repair\": true"), std::string::npos) << w;
    EXPECT_NE(w.find("remesh"), std::string::npos) << w;
    EXPECT_EQ(w.find('\n'), std::string::npos) << w;
  }
}

TEST(SelfIntersection, TetrahedralizeRefusesBeforeGmsh) {
  // Closed, manifold, positive volume: only the self-intersection check stops it.
  const SurfaceMesh m = merged(box({0, 0, 0}, {1, 1, 1}), box({0.5, 0.4, 0.3}, {1.5, 1.4, 1.3}));
  TetMeshOptions o;
  o.source = "two_boxes.obj";
  o.targetElements = 200;
  try {
    tetrahedralize(m, o);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "two_boxes.obj");
    EXPECT_NE(std::string(e.what()).find("cannot tetrahedralise: the surface self-intersects: "),
              std::string::npos)
        << e.what();
    EXPECT_NE(std::string(e.what()).find("remesh"), std::string::npos) << e.what();
  }
}

TEST(SelfIntersection, OneClosedComponentPushedThroughItselfPassesValidationButNotThis) {
  // The CLI fixture: the unit cube with corner (1, 1, 1) pushed through the bottom face.
  const std::string file = std::string(DEFORM_SOURCE_DIR) + "/tests/cli/pushed_through_box.obj";
  const SurfaceMesh m = readMesh(file).surface;
  const MeshReport report = validateSurface(m);
  EXPECT_TRUE(report.ok()) << report.issues[0].message;
  const SelfIntersectionReport r = findSelfIntersections(m, 1000);
  ASSERT_GT(r.pairs, 0);
  // Only the three triangles at the moved corner (3, 7, 11) can cross anything, and each pair
  // holds one of them.
  for (const auto& p : r.listed) {
    const bool moved0 = p[0] == 3 || p[0] == 7 || p[0] == 11;
    const bool moved1 = p[1] == 3 || p[1] == 7 || p[1] == 11;
    EXPECT_TRUE(moved0 || moved1) << p[0] << " " << p[1];
  }
  // Edge 5-7 pierces the bottom (triangles 0 and 1, z = 0) at (0.53, 0.2, 0), inside triangle 0.
  bool bottomHit = false;
  for (const auto& p : r.listed) bottomHit |= p[0] == 0 || p[0] == 1;
  EXPECT_TRUE(bottomHit);
  TetMeshOptions o;
  o.source = file;
  EXPECT_THROW(tetrahedralize(m, o), InputError);
}

TEST(Untangle, AFoldOnASphereIsSmoothedAwayLocally) {
  SurfaceMesh m = makePhantom("sphere");
  const SurfaceMesh clean = m;
  // Mirror vertex 0 through a neighbour: its fan folds over the neighbour's.
  const int i = m.F(0, 0), j = m.F(0, 1);
  m.V.row(i) = 2.0 * m.V.row(j) - m.V.row(i);
  const SelfIntersectionReport before = findSelfIntersections(m);
  ASSERT_GT(before.pairs, 0) << "the fixture must self-intersect";
  ASSERT_TRUE(validateSurface(m).ok());
  const SurfaceMesh folded = m;
  const UntangleReport r = untangleSelfIntersections(m);
  EXPECT_TRUE(r.ok());
  EXPECT_EQ(r.pairsBefore, before.pairs);
  EXPECT_EQ(findSelfIntersections(m).pairs, 0);
  EXPECT_TRUE(validateSurface(m).ok());
  EXPECT_EQ(m.F, clean.F);
  // Local: a small share of the vertices moved, none farther than the fold's size.
  const Real edge = (clean.V.row(i) - clean.V.row(j)).norm();
  EXPECT_GT(r.movedVertices, 0);
  EXPECT_LT(r.movedVertices, m.numVertices() / 10);
  EXPECT_LE(r.maxMove, 3 * edge);
  int moved = 0;
  for (int v = 0; v < m.numVertices(); ++v) moved += m.V.row(v) != folded.V.row(v);
  EXPECT_EQ(moved, r.movedVertices);
  ASSERT_EQ(r.lines().size(), 1u);
  EXPECT_NE(r.lines()[0].find("untangled"), std::string::npos) << r.lines()[0];
}

TEST(Untangle, AGlobalTangleIsRefusedAndTheMeshLeftAlone) {
  // The corner pushed through the bottom face would need a move of half the box to undo.
  const std::string file = std::string(DEFORM_SOURCE_DIR) + "/tests/cli/pushed_through_box.obj";
  SurfaceMesh m = readMesh(file).surface;
  const SurfaceMesh before = m;
  const UntangleReport r = untangleSelfIntersections(m);
  EXPECT_FALSE(r.ok());
  EXPECT_GT(r.pairsBefore, 0);
  EXPECT_EQ(r.pairsAfter, r.pairsBefore);
  EXPECT_EQ(m.V, before.V);
  ASSERT_EQ(r.lines().size(), 1u);
  EXPECT_NE(r.lines()[0].find("could not untangle"), std::string::npos) << r.lines()[0];
}

TEST(Untangle, ACleanSurfaceIsNotTouched) {
  SurfaceMesh m = makePhantom("liver", 0.5);
  const MatX3 V = m.V;
  const UntangleReport r = untangleSelfIntersections(m);
  EXPECT_TRUE(r.ok());
  EXPECT_EQ(r.pairsBefore, 0);
  EXPECT_EQ(r.movedVertices, 0);
  EXPECT_TRUE(r.lines().empty());
  EXPECT_EQ(m.V, V);
}

std::string evalFile(const std::string& name) {
  return std::string(DEFORM_EVAL_DATA_DIR) + "/" + name;
}

TEST(SelfIntersection, EvalDataLiverSmoothSelfIntersects) {
  if (!std::filesystem::exists(evalFile("liver-smooth.obj")))
    GTEST_SKIP() << "eval data not available";
  const SurfaceMesh m = readMesh(evalFile("liver-smooth.obj")).surface;
  ASSERT_TRUE(validateSurface(m).ok());  // closed, manifold, oriented: only this check sees it
  const SelfIntersectionReport r = findSelfIntersections(m);
  EXPECT_GT(r.pairs, 0);
  try {
    requireNoSelfIntersections(m, "liver-smooth.obj");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("liver-smooth.obj: "), std::string::npos);
  }
}

TEST(Untangle, EvalDataLiverSmoothIsUntangledAndThenMeshes) {
  if (!std::filesystem::exists(evalFile("liver-smooth.obj")))
    GTEST_SKIP() << "eval data not available";
  SurfaceMesh m = readMesh(evalFile("liver-smooth.obj")).surface;
  const UntangleReport r = untangleSelfIntersections(m);
  ASSERT_TRUE(r.ok()) << (r.lines().empty() ? "" : r.lines()[0]);
  EXPECT_GT(r.pairsBefore, 0);
  EXPECT_EQ(findSelfIntersections(m).pairs, 0);
  EXPECT_TRUE(validateSurface(m).ok());
  // The file is in centimetres (64 x 49 x 44 mm at scale 0.01): the fold's vertices go back
  // about a millimetre, and the repair stays local.
  EXPECT_LT(r.maxMove, 0.2);
  EXPECT_LT(r.movedVertices, m.numVertices() / 20);
  TetMeshOptions o;
  o.source = "liver-smooth.obj";
  o.targetElements = 4000;
  const TetMeshResult tets = tetrahedralize(m, o);
  EXPECT_GT(tets.mesh.numTets(), 1000);
}

TEST(SelfIntersection, EvalDataCleanMeshesHaveNone) {
  for (const char* name : {"Liver.stl", "gallbladder_visual.stl", "Kidney_left.stl",
                           "tissue_surface.obj", "liver.obj"}) {
    if (!std::filesystem::exists(evalFile(name))) GTEST_SKIP() << "eval data not available";
    const SurfaceMesh m = readMesh(evalFile(name)).surface;
    EXPECT_EQ(findSelfIntersections(m).pairs, 0)
        << name << ": " << findSelfIntersections(m).message();
  }
}

}  // namespace
}  // namespace deform
