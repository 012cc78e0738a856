// Tet mesher: surface vertices kept with their indices, boundary == input surface, positive
// tets, sane quality, bad surfaces rejected with InputError (no crash, no hang).
#include "../support/meshes.h"
#include "test_shapes.h"

#include <deform/geometry/tet_mesher.h>
#include <deform/sdk/error.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <array>

using namespace deform;
using namespace deform::reference_fem;
using deform::testing::icosphere;

namespace {

std::vector<std::array<int, 3>> sortedFaces(const MatX3i& F) {
  std::vector<std::array<int, 3>> t;
  for (int f = 0; f < F.rows(); ++f) {
    std::array<int, 3> a{F(f, 0), F(f, 1), F(f, 2)};
    // Keep orientation: rotate so the smallest index comes first.
    std::rotate(a.begin(), std::min_element(a.begin(), a.end()), a.end());
    t.push_back(a);
  }
  std::sort(t.begin(), t.end());
  return t;
}

void checkMesh(const SurfaceMesh& s, const TetMeshResult& r) {
  ASSERT_GE(r.mesh.numVertices(), s.numVertices());
  for (int i = 0; i < s.numVertices(); ++i)
    ASSERT_EQ(r.mesh.V.row(i), s.V.row(i)) << "surface vertex " << i << " moved or renumbered";
  int negative = 0;
  for (int t = 0; t < r.mesh.numTets(); ++t) {
    const auto q = r.mesh.T.row(t);
    if (!(tetVolume(r.mesh.V.row(q(0)), r.mesh.V.row(q(1)), r.mesh.V.row(q(2)),
                    r.mesh.V.row(q(3))) > 0))
      ++negative;
  }
  EXPECT_EQ(negative, 0);
  EXPECT_EQ(r.quality.degenerate, 0);
  // Boundary of the tets == the given (possibly refined) surface, with the same orientation.
  EXPECT_EQ(sortedFaces(tetBoundary(r.mesh).F), sortedFaces(r.boundary.F));
  // Volumes agree.
  Real v = 0;
  for (int t = 0; t < r.mesh.numTets(); ++t) {
    const auto q = r.mesh.T.row(t);
    v += tetVolume(r.mesh.V.row(q(0)), r.mesh.V.row(q(1)), r.mesh.V.row(q(2)), r.mesh.V.row(q(3)));
  }
  EXPECT_NEAR(v, signedVolume(s.V, s.F), 1e-9 * signedVolume(s.V, s.F));
  EXPECT_GT(r.quality.minDihedralDeg, 1.0);
  EXPECT_GT(r.quality.minMeanRatio, 0.05);
}

}  // namespace

TEST(TetMesher, SphereKeepsEverySurfaceVertex) {
  const SurfaceMesh s = icosphere(3, 0.03);
  TetMeshOptions o;
  o.targetElements = 5000;
  o.source = "sphere";
  const TetMeshResult r = tetrahedralize(s, o);
  checkMesh(s, r);
  EXPECT_GT(r.mesh.numVertices(), s.numVertices());  // interior nodes appended
  // Without refinement the boundary is the input surface itself.
  EXPECT_EQ(r.boundary.numVertices(), s.numVertices());
  EXPECT_EQ(sortedFaces(r.boundary.F), sortedFaces(s.F));
  // Element count within a factor 2 of the target (the surface bounds sizes near it).
  EXPECT_GT(r.quality.elements, o.targetElements / 2);
  EXPECT_LT(r.quality.elements, o.targetElements * 2);
}

TEST(TetMesher, RefinedSurfaceKeepsOriginalVerticesAndGeometry) {
  const SurfaceMesh s = boxSurface(Vec3(0, 0, 0), Vec3(0.1, 0.01, 0.01), Vec3i(10, 1, 1));
  TetMeshOptions o;
  o.edgeLength = 0.003;
  o.refineSurface = true;
  const TetMeshResult r = tetrahedralize(s, o);
  checkMesh(s, r);
  EXPECT_GT(r.boundary.numVertices(), s.numVertices());
  const MatX2i E = uniqueEdges(r.boundary.F);
  for (int e = 0; e < E.rows(); ++e)
    EXPECT_LE((r.boundary.V.row(E(e, 0)) - r.boundary.V.row(E(e, 1))).norm(), 0.003 + 1e-12);
  EXPECT_NEAR(surfaceArea(r.boundary.V, r.boundary.F), surfaceArea(s.V, s.F), 1e-12);
}

TEST(TetMesher, RefineSurfaceEdgesIsClosedAndDeterministic) {
  const SurfaceMesh s = icosphere(1, 1.0);
  const SurfaceMesh a = refineSurfaceEdges(s, 0.2), b = refineSurfaceEdges(s, 0.2);
  EXPECT_EQ(a.V, b.V);
  EXPECT_EQ(a.F, b.F);
  const MatX2i E = uniqueEdges(a.F);
  const MatX2i EF = edgeFaces(a.F, E);
  for (int e = 0; e < E.rows(); ++e) {
    EXPECT_GE(EF(e, 1), 0);
    EXPECT_LE((a.V.row(E(e, 0)) - a.V.row(E(e, 1))).norm(), 0.2);
  }
  EXPECT_EQ(3 * a.numFaces(), 2 * E.rows());  // closed: every edge in two triangles
  EXPECT_NEAR(signedVolume(a.V, a.F), signedVolume(s.V, s.F), 1e-12);
  EXPECT_EQ(a.V.topRows(s.numVertices()), s.V);
}

TEST(TetMesher, GradedMeshIsFineAtTheFocusOnlyOnTheSurfaceAndInside) {
  // A 30 mm sphere at h = 10 mm, graded toward its north pole: 3 mm within 5 mm of it.
  const SurfaceMesh s = icosphere(2, 0.03);
  TetMeshOptions o;
  o.edgeLength = 0.01;
  o.refineSurface = true;
  o.grading = {.centre = Vec3(0, 0, 0.03), .radius = 0.005, .ratio = 0.3, .growth = 0.3};
  const TetMeshResult r = tetrahedralize(s, o);
  checkMesh(s, r);
  const MatX2i E = uniqueEdges(r.boundary.F);
  for (int e = 0; e < E.rows(); ++e) {
    const Vec3 a = r.boundary.V.row(E(e, 0)), b = r.boundary.V.row(E(e, 1));
    EXPECT_LE((a - b).norm(), o.grading.size(0.5 * (a + b), o.edgeLength) + 1e-12);
  }
  // Mean tet edge near the pole and in the southern half.
  double nearSum = 0, farSum = 0;
  int nearCount = 0, farCount = 0;
  for (int t = 0; t < r.mesh.numTets(); ++t) {
    Vec3 c = Vec3::Zero();
    double edges = 0;
    for (int i = 0; i < 4; ++i) {
      c += 0.25 * r.mesh.V.row(r.mesh.T(t, i)).transpose();
      for (int j = i + 1; j < 4; ++j)
        edges += (r.mesh.V.row(r.mesh.T(t, i)) - r.mesh.V.row(r.mesh.T(t, j))).norm() / 6;
    }
    if ((c - o.grading.centre).norm() < 0.008) nearSum += edges, ++nearCount;
    if (c.z() < -0.005) farSum += edges, ++farCount;
  }
  ASSERT_GT(nearCount, 0);
  ASSERT_GT(farCount, 0);
  EXPECT_LT(nearSum / nearCount, 0.5 * o.edgeLength);
  EXPECT_GT(farSum / farCount, 2.0 * nearSum / nearCount);
  TetMeshOptions uniform = o;
  uniform.grading = {};
  EXPECT_GT(r.mesh.numTets(), 2 * tetrahedralize(s, uniform).mesh.numTets());
}

TEST(TetMesher, OpenSurfaceIsInputErrorNamingTheSource) {
  SurfaceMesh s = icosphere(2, 0.03);
  s.F.conservativeResize(s.numFaces() - 1, 3);
  TetMeshOptions o;
  o.source = "open.obj";
  try {
    tetrahedralize(s, o);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "open.obj");
    EXPECT_NE(e.problem().find("cannot tetrahedralise"), std::string::npos) << e.what();
    EXPECT_NE(e.problem().find("not closed"), std::string::npos) << e.what();
  }
}

TEST(TetMesher, SelfIntersectingSurfaceIsInputError) {
  // Two spheres overlapping, merged into one vertex/face list: closed and manifold edge-wise,
  // but self-intersecting. Gmsh must fail (or be caught changing the surface), never hang.
  const SurfaceMesh a = icosphere(2, 0.03), b = icosphere(2, 0.03, Vec3(0.02, 0, 0));
  SurfaceMesh s;
  s.V.resize(a.numVertices() + b.numVertices(), 3);
  s.V << a.V, b.V;
  s.F.resize(a.numFaces() + b.numFaces(), 3);
  s.F << a.F, (b.F.array() + a.numVertices()).matrix();
  TetMeshOptions o;
  o.targetElements = 2000;
  o.timeoutSeconds = 60;
  o.source = "overlap.obj";
  EXPECT_THROW(tetrahedralize(s, o), InputError);
}
