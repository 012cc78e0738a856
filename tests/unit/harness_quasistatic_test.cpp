// The runner solves a quasi-static model only at the compared instants (and where a grasp closes),
// while the interaction is still prepared every step.
#include "tet_lift_scene.h"

#include <deform_harness/runner.h>
#include <gtest/gtest.h>

namespace deform::harness {
namespace {

using deform::testing::RigidTestModel;
namespace fs = std::filesystem;

/// The tet lift, compared at its default instants.
using QuasiStaticFixture = deform::testing::TetLiftScene;

/// Runs the rigid test model declared with the given capabilities; returns the record and the
/// step() inputs the model received.
RunRecord runCounting(const QuasiStaticFixture& f, bool quasiStatic, std::vector<StepInput>* inputs,
                      std::vector<ParamSpec> params = {},
                      nlohmann::json given = nlohmann::json::object()) {
  ModelInfo info;
  info.name = "counting";
  info.version = "1";
  info.capabilities = {Capability::Grasp};
  if (quasiStatic) info.capabilities.push_back(Capability::QuasiStatic);
  info.params = std::move(params);
  info.create = [inputs]() -> std::unique_ptr<Model> {
    auto m = std::make_unique<RigidTestModel>();
    m->recordInto = inputs;
    return m;
  };
  Cache cache{fs::path()};
  const ParamValues values = resolveParams(info.params, given, "test", "/params");
  return runModel(info, values, f.scene, f.organ, cache);
}

TEST(QuasiStaticRunner, SolvesOnlyAtTheEndAndAtTheGraspClosing) {
  const QuasiStaticFixture f;
  std::vector<StepInput> inputs;
  const RunRecord r = runCounting(f, true, &inputs);
  ASSERT_EQ(r.status, RunStatus::Ok) << r.message;
  EXPECT_EQ(r.steps, 100) << "the run still covers the whole trajectory";
  // Step 10 ends at t = 0.1 s, where the jaws close (the state the grasp attaches to); step 100
  // is the end of the run, the only compared instant.
  ASSERT_EQ(inputs.size(), 2u);
  EXPECT_NEAR(inputs[0].time, 0.09, 1e-12);
  EXPECT_TRUE(inputs[0].grasps.empty()) << "the jaws are still open during step 10";
  EXPECT_NEAR(inputs[1].time, 0.99, 1e-12);
  ASSERT_EQ(inputs[1].grasps.size(), 1u) << "the grasp attached at 0.1 s though step() was idle";
  EXPECT_EQ(r.solvedSteps, 2);
  EXPECT_EQ(r.stepMs.size(), 2u);
  ASSERT_EQ(r.compared.size(), 1u);
  EXPECT_EQ(r.compared[0].step, 100);
  EXPECT_NEAR(r.finalSurface(3, 2) - 0.1, 0.02, 1e-12) << "the final solve sees the full lift";
}

TEST(QuasiStaticRunner, CompareAtInstantsAreTheSolveSteps) {
  QuasiStaticFixture f;
  f.scene.compareAt = {0.3, 0.5};
  EXPECT_EQ(quasiStaticSolveSteps(f.scene), (std::vector<int>{10, 30, 50}));
  EXPECT_EQ(quasiStaticSolveSteps(f.scene, 40), (std::vector<int>{10, 30}));
  std::vector<StepInput> inputs;
  const RunRecord r = runCounting(f, true, &inputs);
  ASSERT_EQ(inputs.size(), 3u);
  EXPECT_NEAR(inputs[1].time, 0.29, 1e-12);
  EXPECT_NEAR(inputs[2].time, 0.49, 1e-12);
  ASSERT_EQ(r.compared.size(), 2u);
  EXPECT_NEAR(r.compared[0].positions(3, 2) - 0.1, 0.008, 1e-12) << "tool at 0.3 s: +8 mm";
}

// Issue 35: an object (or instrument) with dynamics takes the tissue's reaction every step; a
// quasi-static model left idle between compared instants gave none, so on liver_instruments the
// box sank through the organ and the next solve found it deep inside.
TEST(QuasiStaticRunner, ASceneWithDynamicsIsSolvedEveryStep) {
  QuasiStaticFixture f;
  f.scene.compareAt = {0.3, 0.5};
  EXPECT_FALSE(f.scene.needsDynamics());
  ObjectSpec box;
  ShapePrimitive p;
  p.kind = ShapePrimitive::Kind::Box;
  p.halfExtents = Vec3::Constant(0.005);
  box.shape.parts.push_back(p);
  box.pos = Vec3(0.5, 0.5, 0.5);
  f.scene.objects.push_back(box);
  ASSERT_TRUE(f.scene.needsDynamics());
  std::vector<int> every(100);
  for (int k = 0; k < 100; ++k) every[size_t(k)] = k + 1;
  EXPECT_EQ(quasiStaticSolveSteps(f.scene), every);
  EXPECT_EQ(quasiStaticSolveSteps(f.scene, 40).size(), 40u);
}

TEST(QuasiStaticRunner, DynamicModelsAndDynamicSolveStepEveryStep) {
  const QuasiStaticFixture f;
  std::vector<StepInput> inputs;
  const RunRecord dynamic = runCounting(f, false, &inputs);
  EXPECT_EQ(inputs.size(), 100u);
  EXPECT_EQ(dynamic.solvedSteps, -1);
  inputs.clear();
  const std::vector<ParamSpec> solve = {
      ParamSpec::choice("solve", "quasi_static", {"quasi_static", "dynamic"}, "")};
  runCounting(f, true, &inputs, solve, {{"solve", "dynamic"}});
  EXPECT_EQ(inputs.size(), 100u) << "a quasi_static plugin run with solve=dynamic";
  inputs.clear();
  runCounting(f, true, &inputs, solve);
  EXPECT_EQ(inputs.size(), 2u);
}

}  // namespace
}  // namespace deform::harness
