// Tests of the surface conforming to the fixed region (conformToBoxes, decimateQuadric with
// regions) and of the clamp with the reaction on the support faces only (SupportColumns).
#include "../support/meshes.h"
#include "bem_accuracy.h"
#include "bem_assembly.h"
#include "conforming_surface.h"
#include "surface_decimation.h"

#include <gtest/gtest.h>

#include <algorithm>

#include <iostream>

namespace deform::particle_bem {
namespace {

// The bottom of a shape, cut at a height that falls between vertex rings.
Box bottomBox(Real top) {
  Box b;
  b.lo = Vec3::Constant(-1);
  b.hi = Vec3(1, 1, top);
  return b;
}

// Vertices with faces on both sides of the partition (the fixed region's boundary curve).
std::vector<int> boundaryCurve(const SurfaceMesh& s, const std::vector<Box>& boxes) {
  const std::vector<char> tag = facesInBoxes(s.V, s.F, boxes);
  std::vector<char> in(s.numVertices(), 0), out(s.numVertices(), 0);
  for (int f = 0; f < s.numFaces(); ++f)
    for (int k = 0; k < 3; ++k) (tag[f] ? in : out)[s.F(f, k)] = 1;
  std::vector<int> curve;
  for (int v = 0; v < s.numVertices(); ++v)
    if (in[v] && out[v]) curve.push_back(v);
  return curve;
}

Real fixedArea(const SurfaceMesh& s, const std::vector<Box>& boxes) {
  const std::vector<char> tag = facesInBoxes(s.V, s.F, boxes);
  Real a = 0;
  for (int f = 0; f < s.numFaces(); ++f)
    if (tag[f]) {
      const Vec3 x0 = s.V.row(s.F(f, 0)), x1 = s.V.row(s.F(f, 1)), x2 = s.V.row(s.F(f, 2));
      a += 0.5 * (x1 - x0).cross(x2 - x0).norm();
    }
  return a;
}

TEST(ConformingSurface, CutIsClosedManifoldOutwardAndOnTheBoxFace) {
  const SurfaceMesh s = testing::ellipsoid(3, Vec3(0.08, 0.05, 0.03));
  const Real h = -0.0117;
  const std::vector<Box> boxes = {bottomBox(h)};
  ASSERT_GT(nonConformingFaces(s, boxes), 0);  // the input's triangles cross the plane
  for (const Real snap : {0.0, 0.02}) {
    ConformStats st;
    const SurfaceMesh c = conformToBoxes(s, boxes, &st, snap);
    EXPECT_EQ(st.planesCut, 1);
    EXPECT_GT(st.splitEdges, 10);
    EXPECT_EQ(testing::badEdges(c), 0);  // closed, manifold, consistently oriented
    EXPECT_EQ(c.numFaces(), 2 * c.numVertices() - 4);
    EXPECT_EQ(nonConformingFaces(c, boxes), 0);
    // Outward, and the cut changes no geometry (splitting flat triangles), unless snapping.
    const Real v0 = signedVolume(s.V, s.F), v1 = signedVolume(c.V, c.F);
    EXPECT_GT(v1, 0);
    EXPECT_NEAR(v1 / v0, 1.0, snap == 0 ? 1e-12 : 1e-3);
    const std::vector<int> curve = boundaryCurve(c, boxes);
    EXPECT_GT(curve.size(), 10u);
    for (int v : curve) EXPECT_LE(std::abs(c.V(v, 2) - h), 1e-15) << v;
    // The fixed area is the area of the surface below the plane: the same with a fine cut of
    // a finer copy of the shape (to the faceting error).
    if (snap == 0) {
      const SurfaceMesh f = conformToBoxes(testing::ellipsoid(5, Vec3(0.08, 0.05, 0.03)), boxes);
      EXPECT_NEAR(fixedArea(c, boxes) / fixedArea(f, boxes), 1.0, 0.02);
    }
  }
}

TEST(ConformingSurface, DecimationKeepsTheBoundaryCurve) {
  const SurfaceMesh s = testing::ellipsoid(4, Vec3(0.08, 0.05, 0.03));  // 2562 vertices
  const Real h = -0.0171;
  const std::vector<Box> boxes = {bottomBox(h)};
  const SurfaceMesh c = conformToBoxes(s, boxes);
  DecimationStats st;
  const SurfaceMesh d = decimateQuadric(c, 300, boxes, &st);
  EXPECT_EQ(d.numVertices(), 300);
  EXPECT_EQ(d.numFaces(), 2 * 300 - 4);
  EXPECT_EQ(testing::badEdges(d), 0);
  EXPECT_GT(signedVolume(d.V, d.F), 0);
  EXPECT_EQ(nonConformingFaces(d, boxes), 0);
  const std::vector<int> curve = boundaryCurve(d, boxes);
  EXPECT_GE(curve.size(), 8u);
  EXPECT_LT(curve.size(), boundaryCurve(c, boxes).size());  // coarser, but there
  for (int v : curve) EXPECT_EQ(d.V(v, 2), h) << v;
  EXPECT_NEAR(fixedArea(d, boxes) / fixedArea(c, boxes), 1.0, 0.03);
  // Without the regions the same decimation does not keep the partition.
  const SurfaceMesh plain = decimateQuadric(c, 300);
  EXPECT_GT(nonConformingFaces(plain, boxes), 0);
}

TEST(SupportColumns, EqualGAssembledOverTheSupportFacesAlone) {
  const SurfaceMesh s = conformToBoxes(testing::icosphere(2, 0.05), {bottomBox(-0.021)});
  const std::vector<int> fixed = rowsInBox(s.V, bottomBox(-0.021));
  const SupportColumns sc = supportColumns(s, 5000, 0.4, fixed);
  ASSERT_GT(sc.nodes.size(), 5u);
  ASSERT_LT(sc.nodes.size(), fixed.size());
  // The support faces alone (an open surface, every vertex kept): G is a sum over elements,
  // so its columns of the boundary nodes are the support-side columns.
  std::vector<char> isFixed(s.numVertices(), 0);
  for (int j : fixed) isFixed[j] = 1;
  std::vector<Vec3i> faces;
  for (int f = 0; f < s.numFaces(); ++f)
    if (isFixed[s.F(f, 0)] && isFixed[s.F(f, 1)] && isFixed[s.F(f, 2)])
      faces.push_back(s.F.row(f).transpose());
  SurfaceMesh support;
  support.V = s.V;
  support.F.resize(Eigen::Index(faces.size()), 3);
  for (size_t f = 0; f < faces.size(); ++f) support.F.row(Eigen::Index(f)) = faces[f].transpose();
  const BemMatrices part = assembleBem(support, 5000, 0.4);
  const BemMatrices whole = assembleBem(s, 5000, 0.4);
  for (size_t k = 0; k < sc.nodes.size(); ++k) {
    const MatX expected = part.G.middleCols(3 * sc.nodes[k], 3);
    EXPECT_LT((sc.G.middleCols(3 * k, 3) - expected).norm(), 1e-12 * expected.norm());
    // ... and a proper part of the whole column (the node has free faces too).
    EXPECT_GT((whole.G.middleCols(3 * sc.nodes[k], 3) - expected).norm(), 0.05 * expected.norm());
  }
}

/// The load case of the sphere tests below: a peak traction of 200 Pa down on a 30 mm patch at
/// the top of a 50 mm sphere clamped in fixedBox, its reaction by support.
LossRatioCase topPatchCase(const Box& fixedBox, FixedSupport support) {
  LossRatioCase c;
  c.center = Vec3(0, 0, 0.05);
  c.radius = 0.03;
  c.traction = Vec3(0, 0, -200);
  c.fixedBox = fixedBox;
  c.support = support;
  return c;
}

TEST(SupportColumns, ExactClampConvergesFasterThanNodalClamp) {
  // Two conforming spheres (162 / 642 vertices cut at the same plane, which neither mesh has
  // vertices on): with the reaction on the support faces only both meshes clamp the same
  // cap, so the loss ratio between them is the discretisation error; the nodal clamp spreads
  // the reaction half an element beyond the cap, a different amount on each mesh.
  const Real h = -0.0317;
  const std::vector<Box> boxes = {bottomBox(h)};
  const SurfaceMesh coarse = conformToBoxes(testing::icosphere(2, 0.05), boxes);
  const SurfaceMesh fine = conformToBoxes(testing::icosphere(3, 0.05), boxes);
  const LossRatioResult r = bemLossRatio(coarse, fine, Material{5000, 0.45, 1000},
                                         topPatchCase(boxes[0], FixedSupport::SupportFaces));
  std::cout << "sphere 162/642 cut at z = " << h << ": R exact clamp " << r.ratio
            << ", nodal clamp " << r.ratioNodalClamp << "\n";
  EXPECT_GT(r.ratio, 1e-4);
  EXPECT_LT(r.ratio, 0.5 * r.ratioNodalClamp);
}

}  // namespace
}  // namespace deform::particle_bem

namespace deform::particle_bem {
namespace {

TEST(SingularSupport, ColumnsAreTheCorrectedSupportColumnsAndMeshesAgree) {
  // Same spheres as above. The corrected columns: boundary nodes Gs_j + delta_j, the other
  // fixed nodes of the curve faces G_j + delta_j; only fixed nodes touching the curve.
  const std::vector<Box> boxes = {bottomBox(-0.0317)};
  const SurfaceMesh coarse = conformToBoxes(testing::icosphere(2, 0.05), boxes);
  const SurfaceMesh fine = conformToBoxes(testing::icosphere(3, 0.05), boxes);
  const Material m{5000, 0.45, 1000};
  const std::vector<int> fixed = rowsInBox(coarse.V, boxes[0]);
  const BemMatrices bem = assembleBem(coarse, m.young, m.poisson);
  const SupportColumns sc = supportColumns(coarse, m.young, m.poisson, fixed);
  const SingularSupport corr = singularSupport(coarse, m.young, m.poisson, fixed);
  EXPECT_GT(corr.edgeFaces, 0);
  EXPECT_GT(corr.nodes.size(), sc.nodes.size());  // the curve nodes and their support neighbours
  for (int j : corr.nodes)
    EXPECT_TRUE(std::find(fixed.begin(), fixed.end(), j) != fixed.end()) << j;
  for (int j : sc.nodes)
    EXPECT_TRUE(std::find(corr.nodes.begin(), corr.nodes.end(), j) != corr.nodes.end()) << j;
  // w > 1 everywhere on those faces: the correction's diagonal blocks (a source on its own
  // faces, U* positive definite) are positive.
  for (size_t k = 0; k < corr.nodes.size(); ++k)
    EXPECT_GT((corr.delta.block<3, 3>(3 * corr.nodes[k], 3 * k).trace()), 0);
  const SupportColumns all = withSingularSupport(sc, bem.G, corr);
  ASSERT_EQ(all.nodes.size(), corr.nodes.size());
  for (size_t k = 0; k < all.nodes.size(); ++k) {
    const int j = all.nodes[k];
    const size_t c = std::find(corr.nodes.begin(), corr.nodes.end(), j) - corr.nodes.begin();
    const auto s = std::find(sc.nodes.begin(), sc.nodes.end(), j);
    const MatX base = s != sc.nodes.end() ? MatX(sc.G.middleCols(3 * (s - sc.nodes.begin()), 3))
                                          : MatX(bem.G.middleCols(3 * j, 3));
    EXPECT_LT((all.G.middleCols(3 * k, 3) - base - corr.delta.middleCols(3 * c, 3)).norm(),
              1e-12 * base.norm());
  }
  // Both meshes with the singular reaction still agree (a wrong weight or quadrature would
  // part them). Not asserted: that it beats linear reaction elements here -- on these spheres
  // it does not (1.9% against 1.4%), on the liver it does (history note, "Fourth pass").
  const LossRatioResult r =
      bemLossRatio(coarse, fine, m, topPatchCase(boxes[0], FixedSupport::SupportFacesSingular));
  std::cout << "sphere 162/642: R singular reaction " << r.ratio << ", linear reaction "
            << r.ratioSupportFaces << "\n";
  EXPECT_GT(r.ratio, 1e-4);
  EXPECT_LT(r.ratio, 0.03);
}

}  // namespace
}  // namespace deform::particle_bem
