// Same input, same mesh, bit for bit, whatever the process did before: clipSurfaceByBoxes
// (box_clip.h) and tetrahedralize (tet_mesher.h) on the liver phantom minus the fixed boxes of
// scenes/liver_grasp_lift.json, at the size the reference_fem plugin used in the shipped-scenes
// conformance test (20,000 target tets, its default until issue G1). CGAL's corefinement orders its
// output by heap addresses, so before the clip canonicalised it, a second clip after other
// allocations gave a different cap (a different vertex count) and the mesh cache held whichever
// mesh the first run happened to build.
#include <deform/geometry/box_clip.h>
#include <deform/geometry/phantom.h>
#include <deform/geometry/tet_mesher.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <memory>
#include <vector>

using namespace deform;

namespace {

const std::vector<Box> kLiverBoxes = {Box{Vec3(-0.11, -0.08, -0.05), Vec3(0.11, -0.035, 0.05)},
                                      Box{Vec3(-0.11, -0.08, -0.05), Vec3(0.11, 0.03, -0.032)}};

/// Leaves the heap in a different state: blocks of pseudo-random sizes, every other one freed.
std::vector<std::unique_ptr<char[]>> churnHeap(std::uint32_t seed, int blocks) {
  std::vector<std::unique_ptr<char[]>> kept;
  for (int i = 0; i < blocks; ++i) {
    seed = seed * 1664525u + 1013904223u;
    auto p = std::make_unique<char[]>(16 + seed % 4000);
    p[0] = char(i);
    if (i % 2) kept.push_back(std::move(p));
  }
  return kept;
}

BoxClipOptions pluginClipOptions(const SurfaceMesh& s) {
  BoxClipOptions o;
  o.capEdgeLength = edgeLengthForElements(signedVolume(s.V, s.F), 20000);
  return o;
}

void expectSameClip(const BoxClipResult& a, const BoxClipResult& b) {
  ASSERT_EQ(a.surface.V.rows(), b.surface.V.rows());
  ASSERT_EQ(a.surface.F.rows(), b.surface.F.rows());
  EXPECT_TRUE((a.surface.V.array() == b.surface.V.array()).all());
  EXPECT_TRUE((a.surface.F.array() == b.surface.F.array()).all());
  EXPECT_EQ(a.capFace, b.capFace);
  EXPECT_EQ(a.inputToClipped, b.inputToClipped);
}

}  // namespace

TEST(BoxClipDeterminism, SameClipWhateverTheHeapHistory) {
  const SurfaceMesh liver = makePhantom("liver", 0.3);
  const BoxClipOptions o = pluginClipOptions(liver);
  const BoxClipResult first = clipSurfaceByBoxes(liver, kLiverBoxes, o);
  // Other clips and allocations in between, kept alive while clipping again.
  const SurfaceMesh other = makePhantom("liver", 0.5);
  std::vector<BoxClipResult> keep;
  for (std::uint32_t seed : {1u, 2u, 3u}) {
    SCOPED_TRACE(seed);
    const auto churn = churnHeap(seed, 3000 * int(seed));
    keep.push_back(clipSurfaceByBoxes(other, {kLiverBoxes[0]}, o));
    expectSameClip(first, clipSurfaceByBoxes(liver, kLiverBoxes, o));
  }
}

TEST(BoxClipDeterminism, SameTetMeshOfTheClippedSurfaceTwice) {
  // Gmsh runs in a child forked from this process, so its heap starts as this one's: mesh the
  // same clipped surface after different allocation histories.
  const SurfaceMesh liver = makePhantom("liver", 0.3);
  const BoxClipResult clip = clipSurfaceByBoxes(liver, kLiverBoxes, pluginClipOptions(liver));
  TetMeshOptions t;
  t.targetElements = 20000;
  t.refineSurface = true;
  const TetMeshResult a = tetrahedralize(clip.surface, t);
  const auto churn = churnHeap(7, 20000);
  const TetMeshResult b = tetrahedralize(clip.surface, t);
  ASSERT_EQ(a.mesh.V.rows(), b.mesh.V.rows());
  ASSERT_EQ(a.mesh.T.rows(), b.mesh.T.rows());
  EXPECT_TRUE((a.mesh.V.array() == b.mesh.V.array()).all());
  EXPECT_TRUE((a.mesh.T.array() == b.mesh.T.array()).all());
}
