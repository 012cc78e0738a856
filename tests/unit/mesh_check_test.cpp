#include <deform/geometry/mesh_check.h>
#include <deform/sdk/error.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <limits>
#include <set>

#include "mesh_test_util.h"

namespace deform {
namespace {

using testing::octahedron;

const MeshIssue* find(const MeshReport& r, MeshDefect d) {
  for (const auto& i : r.issues) {
    if (i.defect == d) return &i;
  }
  return nullptr;
}

std::vector<MeshDefect> defects(const MeshReport& r) {
  std::vector<MeshDefect> d;
  for (const auto& i : r.issues) d.push_back(i.defect);
  return d;
}

void appendVertex(SurfaceMesh& m, const Vec3& p) {
  m.V.conservativeResize(m.V.rows() + 1, 3);
  m.V.row(m.V.rows() - 1) = p.transpose();
}

void appendFace(SurfaceMesh& m, int a, int b, int c) {
  m.F.conservativeResize(m.F.rows() + 1, 3);
  m.F.row(m.F.rows() - 1) << a, b, c;
}

/// a followed by b with b's indices shifted and b's positions moved by `shift`.
SurfaceMesh disjointUnion(const SurfaceMesh& a, const SurfaceMesh& b, const Vec3& shift) {
  SurfaceMesh m;
  m.V.resize(a.V.rows() + b.V.rows(), 3);
  m.V << a.V, (b.V.rowwise() + shift.transpose());
  m.F.resize(a.F.rows() + b.F.rows(), 3);
  m.F << a.F, (b.F.array() + a.numVertices()).matrix();
  return m;
}

std::string requireMessage(const SurfaceMesh& m) {
  try {
    requireValidSurface(m, "organ.obj");
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "organ.obj");
    EXPECT_EQ(e.place(), "");
    return e.problem();
  }
  return "";
}

/// Triangles as sets of rotations-normalised index triples (orientation kept).
std::set<std::array<int, 3>> orientedFaces(const MatX3i& F) {
  std::set<std::array<int, 3>> out;
  for (int f = 0; f < F.rows(); ++f) {
    std::array<int, 3> t = {F(f, 0), F(f, 1), F(f, 2)};
    std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end());
    out.insert(t);
  }
  return out;
}

TEST(MeshCheck, OctahedronIsValid) {
  const MeshReport r = validateSurface(octahedron());
  EXPECT_TRUE(r.ok()) << (r.issues.empty() ? "" : r.issues[0].message);
  EXPECT_NO_THROW(requireValidSurface(octahedron(), "x"));
}

TEST(MeshCheck, MissingFaceGivesBoundaryEdges) {
  SurfaceMesh m = octahedron();
  m.F.conservativeResize(7, 3);
  const MeshReport r = validateSurface(m);
  EXPECT_EQ(defects(r), std::vector<MeshDefect>{MeshDefect::BoundaryEdges});
  EXPECT_EQ(r.issues[0].count, 3);
  // Face 7 (0, 3, 5) is gone: its edges 0-3, 0-5, 3-5 are open; the first in order is 0-3.
  EXPECT_EQ(r.issues[0].message, "3 boundary edges (holes), first: edge 0-3");
  EXPECT_EQ(requireMessage(m), "3 boundary edges (holes), first: edge 0-3");
}

TEST(MeshCheck, FinGivesNonManifoldEdge) {
  SurfaceMesh m = octahedron();
  appendVertex(m, Vec3(1, 1, 1));
  appendFace(m, 0, 2, 6);  // a third triangle on edge (0, 2)
  const MeshReport r = validateSurface(m);
  ASSERT_TRUE(r.has(MeshDefect::NonManifoldEdges));
  EXPECT_EQ(find(r, MeshDefect::NonManifoldEdges)->count, 1);
  EXPECT_EQ(find(r, MeshDefect::BoundaryEdges)->count, 2);
  EXPECT_FALSE(r.has(MeshDefect::MultipleComponents));
  // Priority: holes are reported before non-manifold edges.
  EXPECT_EQ(requireMessage(m), "2 boundary edges (holes), first: edge 0-6");
  EXPECT_EQ(find(r, MeshDefect::NonManifoldEdges)->message,
            "1 non-manifold edge (shared by more than two triangles), first: edge 0-2");
}

TEST(MeshCheck, TwoSolidsTouchingAtOneVertexGiveNonManifoldVertex) {
  SurfaceMesh a = octahedron();
  // Second octahedron shifted by +2 in x shares the point (1,0,0): glue its vertex 1 onto 0.
  SurfaceMesh m = disjointUnion(a, a, Vec3(2, 0, 0));
  for (int f = 8; f < 16; ++f) {
    for (int k = 0; k < 3; ++k) {
      if (m.F(f, k) == 7) m.F(f, k) = 0;
    }
  }
  const MeshReport r = validateSurface(m);
  ASSERT_TRUE(r.has(MeshDefect::NonManifoldVertices));
  EXPECT_EQ(find(r, MeshDefect::NonManifoldVertices)->count, 1);
  const std::string nm = find(r, MeshDefect::NonManifoldVertices)->message;
  EXPECT_NE(nm.find("one fan), first: vertex 0"), std::string::npos) << nm;
  EXPECT_FALSE(r.has(MeshDefect::BoundaryEdges));
  EXPECT_FALSE(r.has(MeshDefect::NonManifoldEdges));
  EXPECT_TRUE(r.has(MeshDefect::UnreferencedVertices));  // the orphaned vertex 7
}

TEST(MeshCheck, OneFlippedFaceGivesInconsistentOrientation) {
  SurfaceMesh m = octahedron();
  std::swap(m.F(3, 1), m.F(3, 2));
  const MeshReport r = validateSurface(m);
  EXPECT_EQ(defects(r), std::vector<MeshDefect>{MeshDefect::InconsistentOrientation});
  EXPECT_EQ(r.issues[0].count, 3);  // all three edges of face 3 (3, 0, 4): 0-3 comes first
  EXPECT_NE(r.issues[0].message.find("same way), first: edge 0-3"), std::string::npos)
      << r.issues[0].message;
}

TEST(MeshCheck, AllFlippedGivesInward) {
  SurfaceMesh m = octahedron();
  m.F.col(1).swap(m.F.col(2));
  const MeshReport r = validateSurface(m);
  EXPECT_EQ(defects(r), std::vector<MeshDefect>{MeshDefect::InwardOrientation});
  EXPECT_EQ(r.issues[0].message, "inward-facing normals (signed volume -1.3 m^3)");
}

TEST(MeshCheck, DisjointSolidsGiveComponents) {
  const SurfaceMesh m = disjointUnion(octahedron(), octahedron(), Vec3(5, 0, 0));
  const MeshReport r = validateSurface(m);
  EXPECT_EQ(defects(r), std::vector<MeshDefect>{MeshDefect::MultipleComponents});
  EXPECT_EQ(r.issues[0].message, "2 components (triangle 8 is not connected to triangle 0)");
}

TEST(MeshCheck, DuplicateVertexWithinWeldTolerance) {
  SurfaceMesh m = octahedron();
  appendVertex(m, Vec3(1 + 1e-12, 0, 0));  // within 1e-9 * diagonal of vertex 0
  m.F(0, 0) = 6;
  MeshReport r = validateSurface(m);
  ASSERT_TRUE(r.has(MeshDefect::DuplicateVertices));
  EXPECT_EQ(find(r, MeshDefect::DuplicateVertices)->message,
            "1 duplicate vertex, first: vertex 6 (at vertex 0)");
  EXPECT_TRUE(r.has(MeshDefect::BoundaryEdges));  // the split opens the surface
  EXPECT_EQ(requireMessage(m), "1 duplicate vertex, first: vertex 6 (at vertex 0)");

  m.V(6, 0) = 1 + 1e-6;  // well outside the tolerance
  r = validateSurface(m);
  EXPECT_FALSE(r.has(MeshDefect::DuplicateVertices));
}

TEST(MeshCheck, DegenerateTriangles) {
  SurfaceMesh m = octahedron();
  appendVertex(m, Vec3(0, 0.5, 0.5));  // midpoint of vertices 2 and 4
  appendFace(m, 2, 6, 4);              // zero area
  MeshReport r = validateSurface(m);
  ASSERT_TRUE(r.has(MeshDefect::DegenerateTriangles));
  EXPECT_EQ(find(r, MeshDefect::DegenerateTriangles)->message,
            "1 zero-area triangle, first: triangle 8");
  appendFace(m, 0, 0, 1);  // repeated index
  r = validateSurface(m);
  EXPECT_EQ(find(r, MeshDefect::DegenerateTriangles)->count, 2);
  EXPECT_EQ(find(r, MeshDefect::DegenerateTriangles)->message,
            "2 degenerate triangles (1 with a repeated vertex, 1 zero-area), first: triangle 8");
}

TEST(MeshCheck, NonFiniteIndexOutOfRangeEmptyUnreferenced) {
  SurfaceMesh m = octahedron();
  m.V(2, 1) = std::numeric_limits<double>::infinity();
  EXPECT_EQ(defects(validateSurface(m)).front(), MeshDefect::NonFinite);
  EXPECT_EQ(validateSurface(m).issues[0].message,
            "1 vertex with NaN or Inf coordinates, first: vertex 2");

  m = octahedron();
  m.F(5, 1) = 6;
  MeshReport r = validateSurface(m);
  EXPECT_EQ(defects(r).front(), MeshDefect::IndexOutOfRange);
  EXPECT_EQ(r.issues[0].count, 1);
  EXPECT_EQ(r.issues[0].message,
            "1 triangle with a vertex index out of range (6 vertices), first: triangle 5");

  EXPECT_EQ(defects(validateSurface(SurfaceMesh{})), std::vector<MeshDefect>{MeshDefect::Empty});
  EXPECT_NE(requireMessage(SurfaceMesh{}).find("empty"), std::string::npos);

  m = octahedron();
  appendVertex(m, Vec3(3, 3, 3));
  r = validateSurface(m);
  EXPECT_EQ(defects(r), std::vector<MeshDefect>{MeshDefect::UnreferencedVertices});
  EXPECT_FALSE(r.ok());
  EXPECT_TRUE(r.usable());
  EXPECT_NO_THROW(requireValidSurface(m, "x"));  // a warning only
}

TEST(MeshCheck, FirstDefectWinsInPriorityOrder) {
  SurfaceMesh m = disjointUnion(octahedron(), octahedron(), Vec3(5, 0, 0));
  m.F.conservativeResize(15, 3);  // hole in the second one, and still two components
  // The dropped face 15 is face 7 (0, 3, 5) of the second octahedron, shifted by 6 vertices.
  EXPECT_EQ(requireMessage(m), "3 boundary edges (holes), first: edge 6-9");
}

TEST(MeshRepair, FixesDuplicatesFlipsStrayComponentAndJunk) {
  const SurfaceMesh clean = octahedron();
  SurfaceMesh m = clean;
  appendVertex(m, Vec3(1, 0, 0));  // 6: duplicate of vertex 0
  for (int f : {3, 7}) {
    for (int k = 0; k < 3; ++k) {
      if (m.F(f, k) == 0) m.F(f, k) = 6;
    }
  }
  std::swap(m.F(5, 0), m.F(5, 1));  // one flipped triangle
  appendVertex(m, Vec3(9, 9, 9));   // 7: unreferenced
  // 8..11: a small stray tetrahedron far away.
  for (const Vec3& p : {Vec3(10, 0, 0), Vec3(10.1, 0, 0), Vec3(10, 0.1, 0), Vec3(10, 0, 0.1)}) {
    appendVertex(m, p);
  }
  appendFace(m, 8, 10, 9);
  appendFace(m, 8, 9, 11);
  appendFace(m, 8, 11, 10);
  appendFace(m, 9, 10, 11);
  appendFace(m, 1, 1, 2);  // repeated index
  appendFace(m, 2, 1, 4);  // same vertices as triangle 1
  ASSERT_FALSE(validateSurface(m).usable());

  const RepairReport rep = repairSurface(m);
  EXPECT_EQ(rep.weldedVertices, 1);
  EXPECT_EQ(rep.droppedDegenerate, 1);
  EXPECT_EQ(rep.droppedDuplicateTriangles, 1);
  EXPECT_EQ(rep.droppedComponents, 1);
  EXPECT_EQ(rep.droppedComponentTriangles, 4);
  EXPECT_EQ(rep.flippedTriangles, 1);
  EXPECT_FALSE(rep.reversedWhole);
  EXPECT_EQ(rep.droppedUnreferenced, 5);
  EXPECT_EQ(rep.droppedInvalid, 0);

  const MeshReport after = validateSurface(m);
  EXPECT_TRUE(after.ok()) << (after.issues.empty() ? "" : after.issues[0].message);
  EXPECT_EQ(m.V, clean.V);  // kept vertices in their original order
  EXPECT_EQ(orientedFaces(m.F), orientedFaces(clean.F));

  const auto lines = rep.lines();
  EXPECT_NE(std::find(lines.begin(), lines.end(), "welded 1 duplicate vertex"), lines.end());
  EXPECT_EQ(lines.size(), 6u);
}

TEST(MeshRepair, InwardSurfaceIsReversedWhole) {
  SurfaceMesh m = octahedron();
  m.F.col(1).swap(m.F.col(2));
  std::swap(m.F(0, 1), m.F(0, 2));  // ... except triangle 0, the one BFS starts from
  const RepairReport rep = repairSurface(m);
  EXPECT_TRUE(rep.reversedWhole);
  EXPECT_EQ(rep.flippedTriangles, 1);
  EXPECT_TRUE(validateSurface(m).ok());
  EXPECT_EQ(orientedFaces(m.F), orientedFaces(octahedron().F));
}

TEST(MeshRepair, WrongSeedTriangleIsStillASingleFlip) {
  SurfaceMesh m = octahedron();
  std::swap(m.F(0, 1), m.F(0, 2));
  const RepairReport rep = repairSurface(m);
  EXPECT_FALSE(rep.reversedWhole);
  EXPECT_EQ(rep.flippedTriangles, 1);
  EXPECT_TRUE(validateSurface(m).ok());
  EXPECT_TRUE(rep.lines().size() == 1u);
}

TEST(MeshRepair, DropsTrianglesWithBadIndicesOrNonFiniteCorners) {
  SurfaceMesh m = octahedron();
  appendVertex(m, Vec3(std::numeric_limits<double>::quiet_NaN(), 0, 0));
  appendFace(m, 0, 1, 6);
  appendFace(m, 0, 1, 17);
  const RepairReport rep = repairSurface(m);
  EXPECT_EQ(rep.droppedInvalid, 2);
  EXPECT_EQ(rep.droppedUnreferenced, 1);
  EXPECT_TRUE(validateSurface(m).ok());
}

TEST(MeshRepair, HolesAreNotRepaired) {
  SurfaceMesh m = octahedron();
  m.F.conservativeResize(7, 3);
  repairSurface(m);
  EXPECT_TRUE(validateSurface(m).has(MeshDefect::BoundaryEdges));
}

}  // namespace
}  // namespace deform
