// reference_fem stops a quasi-static solve at the first accepted load step whose surface passes
// through itself away from the held nodes (`stop_at_fold`): the reference has no self-contact, so
// the rest of a dead load only deepens the fold. Two slabs clamped at one end, 1 cm apart; the
// upper one's free end pressed down through the lower one.
#include "../fem_hex/test_meshes.h"
#include "../support/fixtures.h"

#include <deform/engine/plugin_loader.h>
#include <deform/geometry/mesh_check.h>
#include <deform/sdk/model.h>
#include <gtest/gtest.h>

using namespace deform;

namespace {

Organ twoSlabs() {
  const SurfaceMesh lower =
      fem_hex_test::boxSurface(Vec3(0, 0, 0), Vec3(0.1, 0.02, 0.01), Vec3i(10, 2, 1));
  const SurfaceMesh upper =
      fem_hex_test::boxSurface(Vec3(0, 0, 0.02), Vec3(0.1, 0.02, 0.03), Vec3i(10, 2, 1));
  Organ o;
  o.source = "test:two slabs";
  o.surface.V.resize(lower.V.rows() + upper.V.rows(), 3);
  o.surface.V << lower.V, upper.V;
  o.surface.F.resize(lower.F.rows() + upper.F.rows(), 3);
  o.surface.F << lower.F, upper.F.array() + int(lower.V.rows());
  o.material = Material{5500, 0.3, 1000};
  Box clamp;
  clamp.lo = Vec3(-0.01, -0.01, -0.01);
  clamp.hi = Vec3(0.005, 0.03, 0.04);
  o.fixed.boxes.push_back(clamp);
  return o;
}

struct Outcome {
  NumericCounters numeric;
  long long freePairs = 0;  ///< of the final surface, away from the clamp
  Real tipDrop = 0;         ///< m, of the loaded vertices (mean)
};

Outcome pressDown(bool stopAtFold, long long newtonBudget = 0) {
  const Organ organ = twoSlabs();
  const ModelInfo& info = deform::testing::loader().load("reference_fem");
  ParamValues p = ParamValues::defaults(info.params);
  p.set("element_order", 1LL);
  p.set("elements", 1500LL);
  p.set("stop_at_fold", stopAtFold);
  // Six Newton iterations per load step: the whole load fails at once and is halved, so the solve
  // accepts states short of its load (a harder problem's Newton gets there by itself).
  p.set("max_newton_iterations", 6LL);
  p.set("max_solve_newton_iterations", newtonBudget);
  std::unique_ptr<Model> m = info.create();
  m->init(ModelSetup{organ, p, deform::testing::cache(), 0.01, Vec3::Zero()});
  StepInput in;
  in.dt = 0.01;
  // 2 mN down on the upper slab's free end: it ends 14 mm down, through the lower slab.
  for (int v = 0; v < organ.surface.V.rows(); ++v)
    if (organ.surface.V(v, 0) > 0.0999 && organ.surface.V(v, 2) > 0.0299)
      in.loads.push_back(PointLoad::onVertex(v, Vec3(0, 0, -0.002 / 3)));
  EXPECT_EQ(in.loads.size(), 3u);
  m->step(in);
  Outcome out;
  out.numeric = m->numericCounters();
  for (const PointLoad& l : in.loads)
    out.tipDrop += (organ.surface.V(l.surfaceVertex, 2) - m->surface()(l.surfaceVertex, 2)) / 3;
  const SelfIntersectionReport r =
      findSelfIntersections({m->surface(), organ.surface.F}, std::numeric_limits<int>::max());
  for (const auto& [a, b] : r.listed) {
    bool nearClamp = false;
    for (int t : {a, b})
      for (int k = 0; k < 3; ++k) nearClamp |= organ.surface.V(organ.surface.F(t, k), 0) < 0.03;
    out.freePairs += !nearClamp;
  }
  return out;
}

}  // namespace

TEST(ReferenceFemFold, ASolveStopsWhereItsSurfacePassesThroughItself) {
  const Outcome stopped = pressDown(true);
  EXPECT_EQ(stopped.numeric.at("solves_stopped_at_fold"), 1);
  EXPECT_EQ(stopped.numeric.at("unconverged_steps"), 1);
  EXPECT_GT(stopped.freePairs, 0) << "the state it stopped at is the first fold";
  EXPECT_GT(stopped.tipDrop, 0.01);

  const Outcome full = pressDown(false);
  EXPECT_EQ(full.numeric.at("solves_stopped_at_fold"), 0);
  EXPECT_EQ(full.numeric.at("solves_out_of_budget"), 0);
  EXPECT_GT(full.freePairs, 0);
  EXPECT_GT(full.tipDrop, stopped.tipDrop);
  EXPECT_GT(full.numeric.at("newton_iterations"), stopped.numeric.at("newton_iterations"));
}

// A budget of Newton iterations per solve (max_solve_newton_iterations) ends a solve that has not
// converged within it: not converged, counted apart, after exactly that many iterations.
TEST(ReferenceFemFold, ASolveGivesUpAtItsNewtonBudget) {
  const Outcome spent = pressDown(false, 4);
  EXPECT_EQ(spent.numeric.at("solves_out_of_budget"), 1);
  EXPECT_EQ(spent.numeric.at("unconverged_steps"), 1);
  EXPECT_EQ(spent.numeric.at("newton_iterations"), 4);
  EXPECT_EQ(spent.numeric.at("solves_stopped_at_fold"), 0);
}
