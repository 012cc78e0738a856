// Hybrid FEM+PBD kernels: vertex-cover simplification, load processing, incision, rest data.
#include <deform/geometry/mesh_check.h>
#include <deform/geometry/phantom.h>
#include <gtest/gtest.h>

#include <cstdio>
#include <limits>
#include <map>
#include <numbers>
#include <random>
#include <set>

#include "../support/meshes.h"
#include "batched_projection.h"
#include "coarse_fem.h"
#include "incision.h"
#include "load_processing.h"
#include "response_product.h"
#include "surface_pbd.h"
#include "vertex_cover_simplification.h"

namespace deform::hybrid_fem_pbd {
namespace {

// ---------------------------------------------------------------- vertex cover simplification

class Simplification : public ::testing::TestWithParam<std::pair<const char*, double>> {};

TEST_P(Simplification, CoverPropertyAndValidClosedCoarseSurface) {
  const auto [name, res] = GetParam();
  const SurfaceMesh fine = makePhantom(name, res);
  const MatX2i E = uniqueEdges(fine.F);
  const SimplificationResult r = simplifyByVertexCover(fine);

  // Cover before merging: every edge has an endpoint in the cover, and the cover is minimal
  // (each cover vertex has a non-cover neighbour, i.e. the complement is a maximal independent
  // set).
  ASSERT_EQ(static_cast<int>(r.firstCover.size()), fine.numVertices());
  EXPECT_TRUE(isVertexCover(E, r.firstCover));
  std::vector<char> hasFreeNeighbour(fine.numVertices(), 0);
  for (Eigen::Index e = 0; e < E.rows(); ++e) {
    if (!r.firstCover[E(e, 1)]) hasFreeNeighbour[E(e, 0)] = 1;
    if (!r.firstCover[E(e, 0)]) hasFreeNeighbour[E(e, 1)] = 1;
  }
  for (int v = 0; v < fine.numVertices(); ++v) {
    if (r.firstCover[v]) {
      EXPECT_TRUE(hasFreeNeighbour[v]) << "cover vertex " << v << " redundant";
    }
  }
  std::printf("%s: fine %d, coarse %d vertices, %lld merged, %lld rejected\n", name,
              fine.numVertices(), r.coarse.numVertices(), r.collapsed, r.rejected);

  // Coarse surface: valid closed manifold, outward, built from fine vertices, fewer of them.
  const MeshReport report = validateSurface(r.coarse);
  EXPECT_TRUE(report.ok()) << (report.ok() ? "" : report.issues.front().message);
  EXPECT_GT(signedVolume(r.coarse.V, r.coarse.F), 0);
  EXPECT_LT(r.coarse.numVertices(), fine.numVertices());
  EXPECT_GT(r.collapsed, fine.numVertices() / 5);
  ASSERT_EQ(static_cast<int>(r.coarseToFine.size()), r.coarse.numVertices());
  for (int c = 0; c < r.coarse.numVertices(); ++c) {
    const int f = r.coarseToFine[c];
    EXPECT_TRUE(r.firstCover[f] || r.rejected > 0);
    EXPECT_EQ((r.coarse.V.row(c) - fine.V.row(f)).norm(), 0.0);
  }
  // Every merge kept the triangle quality above the bound.
  for (int f = 0; f < r.coarse.numFaces(); ++f) {
    const Vec3 a = r.coarse.V.row(r.coarse.F(f, 0)), b = r.coarse.V.row(r.coarse.F(f, 1)),
               c = r.coarse.V.row(r.coarse.F(f, 2));
    EXPECT_GE(triangleQuality(a, b, c), 0.1 - 1e-12);
  }
  // The enclosed volume changes little (merges move no vertex, they only drop some).
  const Real v0 = signedVolume(fine.V, fine.F), v1 = signedVolume(r.coarse.V, r.coarse.F);
  EXPECT_NEAR(v1 / v0, 1.0, 0.1);
}

INSTANTIATE_TEST_SUITE_P(Phantoms, Simplification,
                         ::testing::Values(std::make_pair("cube", 0.5),
                                           std::make_pair("sphere", 0.5),
                                           std::make_pair("liver", 0.25),
                                           std::make_pair("steak", 1.0)));

TEST(Simplification, TwoLevelsAreCoarserAndStillValid) {
  const SurfaceMesh fine = makePhantom("sphere", 0.5);
  SimplificationOptions o1, o2;
  o2.levels = 2;
  const auto r1 = simplifyByVertexCover(fine, o1);
  const auto r2 = simplifyByVertexCover(fine, o2);
  EXPECT_LT(r2.coarse.numVertices(), r1.coarse.numVertices());
  EXPECT_TRUE(validateSurface(r2.coarse).ok());
}

TEST(VertexCover, DetectsAnUncoveredEdge) {
  MatX2i E(3, 2);
  E << 0, 1, 1, 2, 2, 3;
  EXPECT_TRUE(isVertexCover(E, {0, 1, 1, 0}));
  EXPECT_FALSE(isVertexCover(E, {0, 1, 0, 0}));
  // Path 0-1-2-3: the min-degree greedy takes 0 (degree 1), then 2 or 3; cover size 2.
  const std::vector<char> c = vertexCoverFromIndependentSet(E, 4);
  EXPECT_TRUE(isVertexCover(E, c));
  EXPECT_EQ(c[0] + c[1] + c[2] + c[3], 2);
}

// ---------------------------------------------------------------- load processing

TEST(LoadProcessing, ConservesForceAndMoment) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<Real> u(-1, 1);
  for (int trial = 0; trial < 200; ++trial) {
    MatX3 V(3, 3);
    for (int i = 0; i < 9; ++i) V(i / 3, i % 3) = u(rng);
    MatX3i F(1, 3);
    F << 0, 1, 2;
    const Vec3 p(u(rng), u(rng), u(rng)), f(u(rng), u(rng), u(rng));
    const CoarseAttachment a = attachToCoarseSurface(p, V, F);
    const auto nf = equivalentNodalForces(a, f);
    Vec3 sum = Vec3::Zero(), moment = Vec3::Zero();
    for (int k = 0; k < a.count; ++k) {
      sum += nf[k];
      moment += (V.row(a.nodes[k]).transpose() - a.projection).cross(nf[k]);
      EXPECT_GE(a.weights[k], -1e-12);
    }
    EXPECT_LT((sum - f).norm(), 1e-12);
    EXPECT_LT(moment.norm(), 1e-10);
    // The projection is the closest point of the triangle (no sampled point is closer).
    for (int s = 0; s < 50; ++s) {
      Real b1 = (u(rng) + 1) / 2, b2 = (u(rng) + 1) / 2;
      if (b1 + b2 > 1) {
        b1 = 1 - b1;
        b2 = 1 - b2;
      }
      const Vec3 q = V.row(0).transpose() + b1 * (V.row(1) - V.row(0)).transpose() +
                     b2 * (V.row(2) - V.row(0)).transpose();
      EXPECT_GE((q - p).norm(), (a.projection - p).norm() - 1e-12);
    }
  }
}

TEST(LoadProcessing, PointOnTheCoarseTriangleKeepsTheMomentAboutItself) {
  MatX3 V(3, 3);
  V << 0, 0, 0, 2, 0, 0, 0, 1, 0;
  MatX3i F(1, 3);
  F << 0, 1, 2;
  const Vec3 p(0.5, 0.25, 0), f(0.3, -1.0, 2.0);
  const CoarseAttachment a = attachToCoarseSurface(p, V, F);
  ASSERT_EQ(a.count, 3);
  const auto nf = equivalentNodalForces(a, f);
  Vec3 moment = Vec3::Zero();
  for (int k = 0; k < 3; ++k) moment += (V.row(a.nodes[k]).transpose() - p).cross(nf[k]);
  EXPECT_LT(moment.norm(), 1e-14);
  EXPECT_NEAR(a.weights[0], 0.5, 1e-14);   // 1 - 0.25 - 0.25
  EXPECT_NEAR(a.weights[1], 0.25, 1e-14);  // x / 2
  EXPECT_NEAR(a.weights[2], 0.25, 1e-14);  // y / 1
  // A control node takes the whole force.
  const CoarseAttachment c = attachToCoarseSurface(p, V, F, 1);
  EXPECT_EQ(c.count, 1);
  EXPECT_EQ(c.nodes[0], 1);
  EXPECT_EQ(c.weights[0], 1.0);
}

// ---------------------------------------------------------------- incision rest data

TEST(Incision, LawOfCosinesRestLengthsMatchTheTriangle) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<Real> u(0, 1);
  for (int trial = 0; trial < 100; ++trial) {
    const Vec3 A(u(rng), u(rng), u(rng)), B(u(rng), u(rng), u(rng)), C(u(rng), u(rng), u(rng));
    const Real lAB = (B - A).norm(), lBC = (C - B).norm(), lCA = (A - C).norm();
    auto bary = [&] {
      Vec3 b(u(rng), u(rng), u(rng));
      return Vec3(b / b.sum());
    };
    const Vec3 bp = bary(), bq = bary();
    const Vec3 P = bp[0] * A + bp[1] * B + bp[2] * C, Q = bq[0] * A + bq[1] * B + bq[2] * C;
    EXPECT_NEAR(restDistanceInTriangle(lAB, lBC, lCA, bp, bq), (P - Q).norm(), 1e-12);
    // Edge point on AB (paper Fig. 8(a)): l_AP = lambda_B l_AB.
    const Real t = u(rng);
    EXPECT_NEAR(restDistanceInTriangle(lAB, lBC, lCA, Vec3(1, 0, 0), Vec3(1 - t, t, 0)), t * lAB,
                1e-12);
  }
}

// A flat patch of n unit squares along x, each split by its diagonal (x,0)-(x+1,1):
// bottom row vertices 0..n, top row n+1..2n+1.
SurfaceMesh patch(int n) {
  SurfaceMesh m;
  m.V.resize(2 * (n + 1), 3);
  for (int x = 0; x <= n; ++x) {
    m.V.row(x) = Vec3(x, 0, 0).transpose();
    m.V.row(n + 1 + x) = Vec3(x, 1, 0).transpose();
  }
  m.F.resize(2 * n, 3);
  for (int x = 0; x < n; ++x) {
    m.F.row(2 * x) = Vec3i(x, x + 1, n + 2 + x).transpose();
    m.F.row(2 * x + 1) = Vec3i(x, n + 2 + x, n + 1 + x).transpose();
  }
  return m;
}

struct EdgeUse {
  int boundary = 0, interior = 0, overused = 0, directedTwice = 0;
};
EdgeUse edgeUse(const MatX3i& F) {
  std::map<std::pair<int, int>, int> und;
  std::set<std::pair<int, int>> dir;
  EdgeUse r;
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int a = F(f, k), b = F(f, (k + 1) % 3);
      ++und[{std::min(a, b), std::max(a, b)}];
      if (!dir.insert({a, b}).second) ++r.directedTwice;
    }
  for (const auto& [e, n] : und) {
    if (n == 1) ++r.boundary;
    if (n == 2) ++r.interior;
    if (n > 2) ++r.overused;
  }
  return r;
}

Real minArea(const MatX3& V, const MatX3i& F) {
  Real m = 1e300;
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Vec3 a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
    m = std::min(m, 0.5 * (b - a).cross(c - a).norm());
  }
  return m;
}

CuttableSurface cuttable(const SurfaceMesh& m) {
  return CuttableSurface::fromMesh(m.V, m.V, m.F);
}

CutReport cutAlong(CuttableSurface& s, std::vector<Vec3> points) {
  CutPath path;
  path.points = std::move(points);
  return cutSurface(s, path);
}

// After a cut: no edge in more than two triangles, consistently oriented, `boundary` boundary
// edges and no triangle of area minArea or less. Returns the edge use.
EdgeUse expectCleanCut(const CuttableSurface& s, int boundary, Real minTriangleArea) {
  const MatX3i F = s.faces();
  const EdgeUse use = edgeUse(F);
  EXPECT_EQ(use.overused, 0);
  EXPECT_EQ(use.directedTwice, 0);  // consistently oriented
  EXPECT_EQ(use.boundary, boundary);
  EXPECT_GT(minArea(s.x, F), minTriangleArea);
  return use;
}

/// Vertex v of the cut surface is at p (to 1e-12).
void expectVertexAt(const CuttableSurface& s, int v, const Vec3& p) {
  EXPECT_LT((s.x.row(v) - p.transpose()).norm(), 1e-12) << "vertex " << v;
}

/// The cut's path points by kind and what it added.
void expectCutCounts(const CutReport& r, int facetPoints, int edgePoints, int newVertices,
                     int newFaces) {
  EXPECT_EQ(r.facetPoints, facetPoints);
  EXPECT_EQ(r.edgePoints, edgePoints);
  EXPECT_EQ(r.newVertices, newVertices);
  EXPECT_EQ(r.newFaces, newFaces);
}

TEST(Incision, EndToEdgeToEndOnTwoSquares) {
  // Path (0.6,0.3) -> (1.4,0.8): facet point in triangle (0,1,4), edge point on edge (1,4) at
  // y = 0.3 + 0.625 * 0.4 = 0.55, facet point in triangle (1,5,4). Insertions: face split +2
  // triangles, edge split +2, face split +2; the edge point is the only interior path vertex,
  // duplicated once. New vertices 2 + 1 + 1 = 4, triangles 4 -> 10.
  const SurfaceMesh m = patch(2);
  CuttableSurface s = cuttable(m);
  const CutReport r = cutAlong(s, {Vec3(0.6, 0.3, 0), Vec3(1.4, 0.8, 0)});
  ASSERT_TRUE(r.applied) << r.reason;
  expectCutCounts(r, 2, 1, 4, 6);
  EXPECT_EQ(r.vertexPoints, 0);
  ASSERT_EQ(r.path.size(), 3u);
  ASSERT_EQ(r.duplicates.size(), 1u);
  const int e = r.path[1], copy = r.duplicates[0].second;
  EXPECT_EQ(r.duplicates[0].first, e);
  expectVertexAt(s, e, Vec3(1, 0.55, 0));
  EXPECT_EQ((s.x.row(copy) - s.x.row(e)).norm(), 0.0);
  // Original indices unchanged, new vertices appended.
  EXPECT_EQ((s.x.topRows(6) - m.V).norm(), 0.0);
  expectCleanCut(s, 6 + 4, 0.01);  // the patch's own 6 boundary edges + the cut's 4 lips
  // Area is conserved by the subdivision.
  EXPECT_NEAR(surfaceArea(s.x, s.faces()), 2.0, 1e-12);
}

TEST(Incision, ThroughTriangleOnThreeSquares) {
  // Path (0.6,0.3) -> (2.4,0.7), y = 0.3 + (2/9)(x - 0.6): facet point in (0,1,5); edge points
  // on (1,5) at y = 7/18, on diagonal (1,6) at (1.5,0.5), on (2,6) at y = 11/18; facet point in
  // (2,7,6). Triangle (1,6,5) is crossed edge to edge (3 pieces). New vertices: 5 points + 3
  // duplicates = 8; triangles 6 + 2 + 2 + 2 + 2 + 2 = 16.
  CuttableSurface s = cuttable(patch(3));
  const CutReport r = cutAlong(s, {Vec3(0.6, 0.3, 0), Vec3(2.4, 0.7, 0)});
  ASSERT_TRUE(r.applied) << r.reason;
  expectCutCounts(r, 2, 3, 8, 10);
  ASSERT_EQ(r.path.size(), 5u);
  expectVertexAt(s, r.path[1], Vec3(1, 7.0 / 18, 0));
  expectVertexAt(s, r.path[2], Vec3(1.5, 0.5, 0));
  expectVertexAt(s, r.path[3], Vec3(2, 11.0 / 18, 0));
  expectCleanCut(s, 8 + 8, 1e-3);  // patch boundary 8, cut lips 2 x 4
  EXPECT_NEAR(surfaceArea(s.x, s.faces()), 3.0, 1e-12);
}

TEST(Incision, CutInsideOneTriangleGetsAMidpoint) {
  // Both ends in triangle (0,1,4) of one square: face split (+2), face split of a piece (+2),
  // midpoint of the cut edge (+2), duplicated midpoint: +4 vertices, +6 triangles.
  CuttableSurface s = cuttable(patch(1));
  const CutReport r = cutAlong(s, {Vec3(0.45, 0.15, 0), Vec3(0.8, 0.35, 0)});
  ASSERT_TRUE(r.applied) << r.reason;
  EXPECT_EQ(r.facetPoints, 2);
  EXPECT_EQ(r.newVertices, 4);
  EXPECT_EQ(r.newFaces, 6);
  const EdgeUse use = edgeUse(s.faces());
  EXPECT_EQ(use.overused, 0);
  EXPECT_EQ(use.boundary, 4 + 4);
}

TEST(Incision, RejectsAPathThatIsTooShort) {
  CuttableSurface s = cuttable(patch(1));
  const CutReport r = cutAlong(s, {Vec3(0.5, 0.25, 0), Vec3(0.5, 0.25, 0)});
  EXPECT_FALSE(r.applied);
  EXPECT_EQ(s.numVertices(), 4);  // unchanged
}

TEST(Incision, ConstraintsAfterCutAreAtRestOnACurvedSurface) {
  const SurfaceMesh m = makePhantom("sphere", 0.3);
  const SurfaceConstraints c0 = buildSurfaceConstraints(m.V, m.F);
  CuttableSurface s = cuttable(m);
  const CutReport r =
      cutAlong(s, {Vec3(-0.02, -0.01, 0.05), Vec3(0.0, 0.0, 0.05), Vec3(0.02, 0.012, 0.05)});
  ASSERT_TRUE(r.applied) << r.reason;
  EXPECT_GT(r.edgePoints, 0);
  const EdgeUse use = expectCleanCut(s, 2 * (static_cast<int>(r.path.size()) - 1), 0);
  const SurfaceConstraints c = constraintsAfterCut(s, c0);
  // Rest lengths from the law of cosines equal the rest distances (the pieces are flat).
  for (const auto& d : c.stretch)
    EXPECT_NEAR(d.rest, (s.rest.row(d.a) - s.rest.row(d.b)).norm(), 1e-12);
  // Bending rest angles are the rest configuration's angles (kept across original edges, 0
  // inside original triangles).
  for (const auto& h : c.bending) {
    Real theta;
    Vec3 g[4];
    ASSERT_TRUE(pbd::dihedralAngle(s.rest.row(h.p[0]).transpose(), s.rest.row(h.p[1]).transpose(),
                                   s.rest.row(h.p[2]).transpose(), s.rest.row(h.p[3]).transpose(),
                                   theta, g));
    EXPECT_NEAR(theta, h.restAngle, 1e-9);
  }
  // One stretch per edge, one bending per interior edge.
  EXPECT_EQ(static_cast<int>(c.stretch.size()), use.boundary + use.interior);
  EXPECT_EQ(static_cast<int>(c.bending.size()), use.interior);
}

// ---------------------------------------------------------------- batched projection

TEST(BatchedProjection, PolynomialAtan2MatchesTheLibrary) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1), e(-12, 12);
  double worst = 0;
  auto check = [&](double y, double x) {
    const double d = pbd::wrapAngle(atan2Polynomial(y, x) - std::atan2(y, x));
    worst = std::max(worst, std::abs(d));
  };
  for (int i = 0; i < 200000; ++i) {
    const double s = std::pow(10.0, e(rng));  // the angle does not depend on the scale
    check(s * u(rng), s * u(rng));
  }
  // Axes, diagonals and the reduction thresholds tan(j pi / 16).
  for (double y : {0.0, 1.0, -1.0, 0.19891236737965800, 0.41421356237309503, 0.6681786379192989})
    for (double x : {1.0, -1.0, 0.0, 1e-300, -1e-300}) {
      check(y, x);
      check(x, y);
    }
  std::printf("max |atan2Polynomial - std::atan2| = %.3g rad\n", worst);
  EXPECT_LT(worst, 1e-15);
  EXPECT_EQ(atan2Polynomial(0.0, 0.0), 0.0);
  EXPECT_EQ(atan2Polynomial(0.0, 2.0), 0.0);
  EXPECT_EQ(atan2Polynomial(-3.0, 0.0), -std::numbers::pi / 2);
}

/// A phantom's surface constraints, every third particle immovable and the others of inverse
/// mass 1 +- 0.5, and a start state p0 moved randomly by up to h (0.3 of the mean edge scale).
struct ProjectionCase {
  SurfaceMesh surface;
  SurfaceConstraints constraints;
  VecX w;
  Real h = 0;
  MatX3 p0;
};

ProjectionCase projectionCase(const char* name, unsigned seed) {
  ProjectionCase pc;
  pc.surface = makePhantom(name, 0.5);
  const SurfaceMesh& s = pc.surface;
  pc.constraints = buildSurfaceConstraints(s.V, s.F);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  const int n = s.numVertices();
  pc.w.resize(n);
  for (int i = 0; i < n; ++i) pc.w[i] = (i % 3 == 0) ? 0.0 : 1.0 + 0.5 * u(rng);
  pc.h = 0.3 * std::sqrt(surfaceArea(s.V, s.F) / s.numFaces());
  pc.p0 = s.V;
  for (int i = 0; i < n; ++i)
    for (int a = 0; a < 3; ++a) pc.p0(i, a) += pc.h * u(rng);
  return pc;
}

/// Positions as padded rows (x, y, z, 0).
std::vector<Real> padded(const MatX3& p) {
  std::vector<Real> x4(4 * size_t(p.rows()), 0.0);
  for (Eigen::Index i = 0; i < p.rows(); ++i)
    for (int a = 0; a < 3; ++a) x4[4 * size_t(i) + size_t(a)] = p(i, a);
  return x4;
}

// The batched projection (scalar and AVX2) does what the one-by-one reference does: same
// constraints, stiffnesses and order, on a randomly deformed surface with immovable particles
// mixed in (as control nodes are), including hinges far from their rest angle.
TEST(BatchedProjection, MatchesTheReferenceProjection) {
  for (const char* name : {"sphere", "liver"}) {
    const ProjectionCase pc = projectionCase(name, 11);
    const auto& [s, c, w, h, p0] = pc;
    const int n = s.numVertices();
    const ActiveConstraints act = activeConstraints(c, w);
    ASSERT_FALSE(act.stretchColourOverflow);
    ASSERT_FALSE(act.bendingColourOverflow);
    MatX3 ref = p0;
    const long long degRef = projectSurfaceConstraints(ref, w, c, act, 1.0, 0.5, 10);
    const SurfaceBatches b = buildSurfaceBatches(c, act, w, 1.0, 0.5, 10);
    for (bool simd : {false, true}) {
      std::vector<Real> x4 = padded(p0);
      const long long deg = projectSurfaceBatches(x4.data(), b, 10, simd);
      EXPECT_EQ(deg, degRef);
      Real worst = 0, moved = 0;
      for (int i = 0; i < n; ++i) {
        const Vec3 xi(x4[4 * i], x4[4 * i + 1], x4[4 * i + 2]);
        worst = std::max(worst, (xi - ref.row(i).transpose()).norm());
        moved = std::max(moved, (xi - p0.row(i).transpose()).norm());
        if (w[i] == 0) {
          EXPECT_EQ((xi - p0.row(i).transpose()).norm(), 0.0);
        }
        EXPECT_EQ(x4[4 * i + 3], 0.0);
      }
      std::printf("%s simd=%d: max |batched - reference| = %.3g m (max correction %.3g m)\n", name,
                  simd, worst, moved);
      EXPECT_GT(moved, 0.1 * h);
      EXPECT_LT(worst, 1e-9 * h);
    }
  }
}

// The single-precision projection (isometric bending, positions relative to the centre) follows
// the double one to float rounding, leaves immovable particles exactly in place, and moves
// nothing at rest (rest values measured with its own arithmetic), with and without AVX2.
TEST(BatchedProjection, SinglePrecisionFollowsTheDoubleProjection) {
  for (const char* name : {"sphere", "liver"}) {
    const ProjectionCase pc = projectionCase(name, 12);
    const auto& [s, c, w, h, p0] = pc;
    const int n = s.numVertices();
    const ActiveConstraints act = activeConstraints(c, w);
    SurfaceBatches b = buildSurfaceBatches(c, act, w, 1.0, 0.5, 10);
    addIsometricBending(b, s.V);
    std::vector<Real> ref = padded(p0);
    const long long degRef = projectSurfaceBatches(ref.data(), b, 10, true);
    const Vec3 origin = boundingBox(s.V).center();
    auto toFloat = [&](const MatX3& p) {
      std::vector<float> x4(4 * n, 0.0f);
      for (int i = 0; i < n; ++i)
        for (int a = 0; a < 3; ++a) x4[4 * i + a] = static_cast<float>(p(i, a) - origin[a]);
      return x4;
    };
    for (bool simd : {false, true}) {
      SurfaceBatches bf = b;
      addSinglePrecision(bf, s.V, origin, simd);
      ASSERT_TRUE(bf.singlePrecision);
      const std::vector<float> rest = toFloat(s.V);
      std::vector<float> x4 = rest;
      EXPECT_EQ(projectSurfaceBatchesF(x4.data(), bf, 10, simd), 0);
      EXPECT_TRUE(x4 == rest) << "the rest state moved";
      x4 = toFloat(p0);
      EXPECT_EQ(projectSurfaceBatchesF(x4.data(), bf, 10, simd), degRef);
      Real worst = 0, moved = 0;
      for (int i = 0; i < n; ++i) {
        Vec3 xi, ri;
        for (int a = 0; a < 3; ++a) {
          xi[a] = p0(i, a) + (x4[4 * i + a] - static_cast<float>(p0(i, a) - origin[a]));
          ri[a] = ref[4 * i + a];
        }
        worst = std::max(worst, (xi - ri).norm());
        moved = std::max(moved, (ri - p0.row(i).transpose()).norm());
        if (w[i] == 0) {
          EXPECT_EQ((xi - p0.row(i).transpose()).norm(), 0.0);
        }
      }
      std::printf("%s simd=%d: max |float - double| = %.3g m (max correction %.3g m)\n", name, simd,
                  worst, moved);
      // Float rounding of the coordinates (relative to the centre), amplified by the sweeps.
      const Real ulp = std::numeric_limits<float>::epsilon() *
                       (s.V.rowwise() - origin.transpose()).cwiseAbs().maxCoeff();
      std::printf("  = %.3g float ulps of the largest coordinate\n", worst / ulp);
      EXPECT_GT(moved, 0.1 * h);
      EXPECT_LT(worst, 100 * ulp);
    }
  }
}

// The grasp response in float storage (blocked, double sums) is the double product to float
// rounding of Z, with AVX2 and without, for row counts off the block size and odd column counts.
TEST(GraspResponse, BlockedFloatProductMatchesTheDoubleProduct) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  for (const auto& [rows, cols] : {std::pair{37, 5}, std::pair{300, 75}, std::pair{16, 1}}) {
    MatX Z(rows, cols);
    VecX lambda(cols);
    for (int j = 0; j < cols; ++j) {
      lambda[j] = 10 * u(rng);
      for (int r = 0; r < rows; ++r) Z(r, j) = 1e-4 * u(rng);
    }
    const VecX exact = Z * lambda;
    const VecX bound = Z.cwiseAbs() * lambda.cwiseAbs();
    BlockedResponse b;
    b.assign(Z);
    ASSERT_EQ(b.paddedRows() % BlockedResponse::kRows, 0);
    ASSERT_GE(b.paddedRows(), rows);
    std::vector<double> y[2];
    for (int simd = 0; simd < 2; ++simd) {
      y[simd].assign(b.paddedRows(), -1.0);
      b.multiply(lambda.data(), y[simd].data(), simd == 1);
      for (int r = 0; r < rows; ++r)
        EXPECT_LE(std::abs(y[simd][r] - exact[r]), 1.2e-7 * bound[r]) << rows << " row " << r;
      for (int r = rows; r < b.paddedRows(); ++r) EXPECT_EQ(y[simd][r], 0.0);
    }
    for (int r = 0; r < rows; ++r) EXPECT_NEAR(y[0][r], y[1][r], 1e-14 * bound[r]);
  }
}

}  // namespace
}  // namespace deform::hybrid_fem_pbd

namespace deform::hybrid_fem_pbd {
namespace {

// Forces on more nodes than the coarse FEM keeps columns of K^-1 for (a pressure patch of a few
// cm on a liver's coarse mesh) are solved as one assembled vector, not node by node with the
// cache cleared and refilled every step (minutes per step on the liver): by linearity the answer
// is the sum of the two halves' answers, each through the per-node columns.
TEST(CoarseFem, ForcesOnManyNodesEqualTheSumOfTheirHalves) {
  const TetMesh mesh = deform::testing::tetBox(10, 10, 6, 0.1, 0.1, 0.06);  // 847 nodes, 726 free
  std::vector<int> fixed;
  for (int v = 0; v < mesh.V.rows(); ++v)
    if (mesh.V(v, 2) == 0) fixed.push_back(v);
  CoarseLinearFem fem;
  fem.init(mesh, Material{}, fixed, "box");
  std::vector<CoarseLinearFem::NodalForce> all, first, second;
  for (int v = 0; v < mesh.V.rows(); ++v) {
    if (mesh.V(v, 2) == 0) continue;
    const CoarseLinearFem::NodalForce f{v, Vec3(0.01 * std::sin(v), 0.02, -0.03 * (v % 7))};
    all.push_back(f);
    (all.size() % 2 ? first : second).push_back(f);
  }
  ASSERT_GT(first.size(), 512u / 2);
  ASSERT_LT(first.size(), 512u);  // each half through the per-node columns
  ASSERT_GT(all.size(), 512u);    // the whole as one assembled vector
  MatX3 u, u1, u2;
  fem.solve(all, Vec3::Zero(), {}, u);
  fem.solve(first, Vec3::Zero(), {}, u1);
  fem.solve(second, Vec3::Zero(), {}, u2);
  ASSERT_GT(u.norm(), 0);
  EXPECT_LT((u - u1 - u2).norm(), 1e-10 * u.norm());
}

}  // namespace
}  // namespace deform::hybrid_fem_pbd
