#include "test_meshes.h"

#include <deform/geometry/phantom.h>
#include <deform/geometry/voxelize.h>
#include <deform/sdk/error.h>
#include <gtest/gtest.h>

namespace deform {
namespace {

using fem_hex_test::boxSurface;
using fem_hex_test::ellipsoidSurface;
using fem_hex_test::liverLike;

TEST(Voxelize, SphereVolumeIsBracketedByInsideAndAllCells) {
  const Real r = 0.05;
  const Real exact = 4.0 / 3.0 * M_PI * r * r * r;
  // Several cell sizes and centre offsets, so the grid cuts the sphere differently each time.
  for (Real h : {0.02, 0.011, 0.0073, 0.004}) {
    for (const Vec3& c : {Vec3(0, 0, 0), Vec3(0.0013, -0.0021, 0.0037)}) {
      const SurfaceMesh s = ellipsoidSurface(c, Vec3::Constant(r), 48, 96);
      const Real meshVolume = signedVolume(s.V, s.F);
      const VoxelGrid g = voxelize(s, h);
      const Real cell = h * h * h;
      EXPECT_LE(g.numInside() * cell, meshVolume) << "h=" << h;
      EXPECT_GE(g.numCells() * cell, exact) << "h=" << h;
      EXPECT_LE(g.numInside() * cell, exact) << "h=" << h;
      EXPECT_EQ(g.numInside() + g.numCrossing(), g.numCells());
    }
  }
}

TEST(Voxelize, EverySurfaceVertexIsInACrossingCell) {
  for (const SurfaceMesh& s :
       {liverLike(), boxSurface(Vec3(0, 0, 0), Vec3(0.1, 0.01, 0.01), Vec3i(10, 2, 2))}) {
    for (Real h : {0.02, 0.006, 0.0025}) {
      const VoxelGrid g = voxelize(s, h);
      for (int v = 0; v < s.numVertices(); ++v) {
        const Vec3i c = g.cellOf(s.V.row(v));
        ASSERT_TRUE(g.contains(c));
        EXPECT_EQ(g.at(c), CellState::Crossing) << "vertex " << v;
        Box b = g.cellBox(c);  // up to the rounding of origin + h * index
        b.lo.array() -= 1e-12 * h;
        b.hi.array() += 1e-12 * h;
        EXPECT_TRUE(b.contains(s.V.row(v).transpose()));
      }
    }
  }
}

TEST(Voxelize, RaysThroughMeshVerticesAndEdgesCountOnce) {
  // Cell centres at y, z in {0, 0.25, 0.5, 0.75, 1}: every ray passes exactly through vertices
  // and edges of the box's triangulation. A double or missed crossing would flip inside-ness.
  const SurfaceMesh s = boxSurface(Vec3(0, 0, 0), Vec3(1, 1, 1), Vec3i(4, 4, 4));
  const VoxelGrid g = voxelize(s, 0.25);
  ASSERT_EQ(g.dims, Vec3i(5, 5, 5));
  EXPECT_EQ(g.numInside(), 27);
  EXPECT_EQ(g.numCells(), 125);
  // Coarser triangulation (two big triangles per face) with diagonal edges under the rays.
  const SurfaceMesh s1 = boxSurface(Vec3(0, 0, 0), Vec3(1, 1, 1), Vec3i(1, 1, 1));
  const VoxelGrid g1 = voxelize(s1, 0.25);
  EXPECT_EQ(g1.numInside(), 27);
}

TEST(Voxelize, InwardOrientedSurfaceGivesTheSameCells) {
  SurfaceMesh s = liverLike();
  const VoxelGrid a = voxelize(s, 0.01);
  s.F.col(1).swap(s.F.col(2));
  const VoxelGrid b = voxelize(s, 0.01);
  EXPECT_EQ(a.numInside(), b.numInside());
  EXPECT_EQ(a.numCells(), b.numCells());
}

TEST(Voxelize, CellSizeForCountHitsTheTarget) {
  const SurfaceMesh s = liverLike();
  for (long long target : {100LL, 967LL, 5000LL}) {
    const Real h = cellSizeForCount(s, target);
    const long long n = voxelCount(s, h);
    EXPECT_NEAR(static_cast<double>(n), static_cast<double>(target), 0.03 * target)
        << "target " << target;
  }
  EXPECT_THROW(cellSizeForCount(s, 0), InputError);
}

// Issue 35 item 8: the stability scale group's cube (0.4 resolution, 300 cells) at 1 cm and 1 m
// lost 45 of its 343 cells (nine rows of five interior cells: rays through the mesh's vertex
// lines skipped one triangle of the edge they pass), so fem_hex's relative displacement there was
// 4.3 times the one at 10 cm. The same mesh in other units must give the same cells.
TEST(Voxelize, ScaledMeshGivesTheSameCells) {
  const SurfaceMesh cube = makePhantom("cube", 0.4);
  const Real h0 = cellSizeForCount(cube, 300);
  const VoxelGrid ref = voxelize(cube, h0);
  EXPECT_EQ(ref.numCells(), 343);
  for (Real s : {0.01, 0.1, 10.0, 1e-3, 3.7}) {
    SurfaceMesh scaled = cube;
    scaled.V *= s;
    const Real h = cellSizeForCount(scaled, 300);
    EXPECT_NEAR(h / s, h0, 1e-6 * h0) << "scale " << s;
    const VoxelGrid g = voxelize(scaled, h);
    EXPECT_EQ(g.numCells(), ref.numCells()) << "scale " << s;
    EXPECT_EQ(g.cells, ref.cells) << "scale " << s;
  }
}

TEST(Voxelize, BadInputThrows) {
  const SurfaceMesh s = liverLike();
  EXPECT_THROW(voxelize(s, 0.0), InputError);
  EXPECT_THROW(voxelize(s, -1.0), InputError);
  EXPECT_THROW(voxelize(s, 1e-7), InputError);  // far too many cells
  EXPECT_THROW(voxelize(SurfaceMesh{}, 0.01), InputError);
}

TEST(TriangleBoxOverlap, SeparatedAndTouching) {
  const Vec3 c(0, 0, 0), hs(0.5, 0.5, 0.5);
  // Triangle crossing the box through its middle.
  EXPECT_TRUE(triangleBoxOverlap(c, hs, Vec3(-2, -2, 0), Vec3(2, -2, 0), Vec3(0, 2, 0)));
  // Entirely above the box.
  EXPECT_FALSE(
      triangleBoxOverlap(c, hs, Vec3(1.2, 0, 0.8), Vec3(0, 1.2, 0.8), Vec3(0.7, 0.7, 1.5)));
  EXPECT_FALSE(triangleBoxOverlap(c, hs, Vec3(2, 0, 0), Vec3(0, 2, 0), Vec3(0, 0, 2)));
  EXPECT_TRUE(triangleBoxOverlap(c, hs, Vec3(1.4, 0, 0), Vec3(0, 1.4, 0), Vec3(0, 0, 1.4)));
  // Touching a face exactly.
  EXPECT_TRUE(triangleBoxOverlap(c, hs, Vec3(0.5, -1, -1), Vec3(0.5, 1, -1), Vec3(0.5, 0, 1)));
}

}  // namespace
}  // namespace deform
