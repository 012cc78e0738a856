// reference_fem with conform_fixed (opt-in): the tets fill the organ minus the fixed box, so
// the clamped boundary is the box face itself. Checked through the plugin: no node lies inside
// the box but the isolated ones of the surface vertices there, every node on the box is pinned
// (zero displacement after a loaded solve, P1 and P2), the surface vertices inside the box report
// their rest positions, a point load there is taken by the support; and conform_fixed = false
// keeps the old mesh (surface vertex i is node i, the nodes inside the box pinned).
#include "../support/fixtures.h"
#include "../support/organs.h"

#include <deform/engine/plugin_loader.h>
#include <deform/geometry/phantom.h>
#include <deform/sdk/cache.h>
#include <deform/sdk/error.h>
#include <deform/sdk/model.h>
#include <gtest/gtest.h>

#include <filesystem>

using namespace deform;

namespace {

using deform::testing::loader;

using deform::testing::cache;

/// The cube phantom with its bottom 23% fixed: a plane between grid rows, so the box cuts
/// triangles.
Organ cubeOrgan() {
  return deform::testing::phantomWithFixedBottom("cube", 0.5, 0.23);
}

bool strictlyInside(const Box& b, const Vec3& p) {
  return (p.array() > b.lo.array()).all() && (p.array() < b.hi.array()).all();
}

struct Result {
  MatX3 restNodes, nodes, surface;
  Counts counts;
};

Result run(const Organ& organ, bool conform, int order, bool loadInsideBox) {
  const ModelInfo& info = loader().load("reference_fem");
  ParamValues p = ParamValues::defaults(info.params);
  p.set("conform_fixed", conform);
  p.set("element_order", (long long)order);
  p.set("elements", (long long)1500);
  p.set("material", std::string("linear"));
  std::unique_ptr<Model> m = info.create();
  m->init(ModelSetup{organ, p, cache(), 0.01, Vec3(0, 0, -9.81)});
  Result r;
  r.restNodes = m->nodes();
  r.counts = m->counts();
  StepInput in;
  in.dt = 0.01;
  in.gravity = Vec3(0, 0, -9.81);
  // A sideways pull on the top centre, so everything above the clamp moves.
  const Box b = boundingBox(organ.surface.V);
  PointLoad top;
  top.surfaceVertex =
      nearestVertex(organ.surface.V, Vec3(b.center().x(), b.center().y(), b.hi.z()));
  top.force = Vec3(0.3, 0, 0);
  in.loads.push_back(PointLoad::onVertex(top.surfaceVertex, top.force));
  if (loadInsideBox) {
    PointLoad low;
    low.surfaceVertex =
        nearestVertex(organ.surface.V, Vec3(b.center().x(), b.center().y(), b.lo.z()));
    low.force = Vec3(0, 0, -5);
    in.loads.push_back(PointLoad::onVertex(low.surfaceVertex, low.force));
  }
  EXPECT_EQ(m->step(in), StepStatus::Ok);
  r.nodes = m->nodes();
  r.surface = m->surface();
  return r;
}

}  // namespace

TEST(ReferenceFemConformingFixed, CapNodesPinnedInsideVerticesAtRest) {
  const Organ organ = cubeOrgan();
  const Box& box = organ.fixed.boxes[0];
  for (const int order : {1, 2}) {
    SCOPED_TRACE("element_order " + std::to_string(order));
    const Result r = run(organ, true, order, true);
    ASSERT_EQ(r.nodes.rows(), r.restNodes.rows());
    int onCap = 0, insideNodes = 0;
    for (Eigen::Index n = 0; n < r.restNodes.rows(); ++n) {
      const Vec3 x = r.restNodes.row(n).transpose();
      if (strictlyInside(box, x)) {  // only the isolated nodes of the surface vertices there
        ++insideNodes;
        EXPECT_EQ((r.nodes.row(n) - r.restNodes.row(n)).norm(), 0.0) << "node " << n;
        continue;
      }
      if (!box.contains(x)) continue;
      ++onCap;
      // On the box: exactly on its top plane (the only face inside the organ), and not moved.
      EXPECT_EQ(x.z(), box.hi.z()) << "node " << n;
      EXPECT_EQ((r.nodes.row(n) - r.restNodes.row(n)).norm(), 0.0) << "node " << n;
    }
    EXPECT_GT(onCap, 10);
    int inside = 0;
    Real moved = 0;
    for (int v = 0; v < organ.surface.numVertices(); ++v) {
      const Vec3 x = organ.surface.V.row(v).transpose();
      if (box.contains(x)) {
        inside += strictlyInside(box, x);
        EXPECT_TRUE((r.surface.row(v).array() == organ.surface.V.row(v).array()).all()) << v;
      } else {
        moved = std::max(moved, (r.surface.row(v) - organ.surface.V.row(v)).norm());
      }
    }
    EXPECT_GT(inside, 0);
    // Every surface vertex is a node: those inside the box are isolated (in no tet) and pinned,
    // and no node of the tets is inside.
    EXPECT_EQ(r.counts.at("isolated_clamped_nodes"), inside);
    EXPECT_EQ(insideNodes, inside);
    EXPECT_GT(moved, 1e-4) << "the free part deforms";
    EXPECT_LT(moved, 0.05);
  }
}

TEST(ReferenceFemConformingFixed, OffKeepsEverySurfaceVertexANode) {
  const Organ organ = cubeOrgan();
  const Box& box = organ.fixed.boxes[0];
  const Result r = run(organ, false, 1, false);
  EXPECT_EQ(r.counts.at("isolated_clamped_nodes"), 0);
  int insideNodes = 0;
  for (Eigen::Index n = 0; n < r.restNodes.rows(); ++n) {
    if (!box.contains(r.restNodes.row(n).transpose())) continue;
    ++insideNodes;
    EXPECT_EQ((r.nodes.row(n) - r.restNodes.row(n)).norm(), 0.0);
  }
  EXPECT_GT(insideNodes, 0);
  // Surface vertex i is node i (the mesher's contract) in the old mode.
  for (int v = 0; v < organ.surface.numVertices(); ++v)
    EXPECT_TRUE((r.restNodes.row(v).array() == organ.surface.V.row(v).array()).all()) << v;
}

TEST(ReferenceFemConformingFixed, BoxAroundTheWholeOrganIsAnInputError) {
  Organ organ = cubeOrgan();
  const Box b = boundingBox(organ.surface.V);
  organ.fixed.boxes[0].hi = b.hi + Vec3::Constant(0.01);
  const ModelInfo& info = loader().load("reference_fem");
  ParamValues p = ParamValues::defaults(info.params);
  p.set("conform_fixed", true);
  std::unique_ptr<Model> m = info.create();
  try {
    m->init(ModelSetup{organ, p, cache(), 0.01, Vec3(0, 0, -9.81)});
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("phantom:cube"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("whole organ"), std::string::npos) << e.what();
  }
}
