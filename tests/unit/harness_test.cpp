// The harness: error metrics on hand-made arrays, step statistics, the runner (status, timing
// records, divergence, failures, unsupported scenes, reset reproducibility) and results.json.
#include <deform/engine/interaction.h>
#include <deform/geometry/mesh_check.h>
#include <deform_harness/metrics.h>
#include <deform_harness/results.h>
#include <deform_harness/runner.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include "../support/temp_dir.h"
#include "tet_lift_scene.h"

namespace deform::harness {
namespace {

namespace fs = std::filesystem;
using deform::testing::RigidTestModel;
using nlohmann::json;

// ---------------------------------------------------------------------------------- metrics

MatX3 rows(std::initializer_list<Vec3> pts) {
  MatX3 m(static_cast<Eigen::Index>(pts.size()), 3);
  Eigen::Index i = 0;
  for (const Vec3& p : pts) m.row(i++) = p.transpose();
  return m;
}

TEST(Metrics, HandComputedSingleInstant) {
  const MatX3 rest = rows({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(2, 0, 0), Vec3(10, 0, 0)});
  const MatX3 ref = rest.rowwise() + Vec3(0, 0, 1).transpose();  // |u_ref| = 1 everywhere
  MatX3 model = ref;
  model.row(1) += Vec3(0, 3, 0).transpose();   // d = 3
  model.row(2) += Vec3(0, 0, -4).transpose();  // d = 4
  const ErrorMetrics e = computeErrors(model, ref, rest, Vec3(0, 0, 0), {2, 3, 10});
  EXPECT_DOUBLE_EQ(e.rmseAll, 2.5);  // sqrt((0 + 9 + 16 + 0) / 4)
  EXPECT_DOUBLE_EQ(e.max, 4.0);
  EXPECT_DOUBLE_EQ(e.lossRatio, 7.0 / 4.0);
  ASSERT_EQ(e.rmseNearest.size(), 3u);
  EXPECT_EQ(e.rmseNearest[0].first, 2);
  EXPECT_DOUBLE_EQ(e.rmseNearest[0].second, std::sqrt(9.0 / 2.0));
  EXPECT_DOUBLE_EQ(e.rmseNearest[1].second, std::sqrt(25.0 / 3.0));
  EXPECT_DOUBLE_EQ(e.rmseNearest[2].second, 2.5) << "k larger than #V covers every vertex";
  // The displacement rmse_k measures: the reference's, over the same vertices (|u_ref| = 1).
  ASSERT_EQ(e.referenceNearest.size(), 3u);
  EXPECT_EQ(e.referenceNearest[1].first, 3);
  EXPECT_DOUBLE_EQ(e.referenceNearest[1].second, 1.0);
  // The k nearest are taken on the REST surface around the focus: focus at the far vertex.
  const ErrorMetrics far = computeErrors(model, ref, rest, Vec3(10, 0, 0), {1});
  EXPECT_DOUBLE_EQ(far.rmseNearest[0].second, 0.0);
}

TEST(Metrics, PooledOverInstants) {
  const MatX3 rest = rows({Vec3(0, 0, 0), Vec3(1, 0, 0)});
  const MatX3 ref = rest.rowwise() + Vec3(0, 0, 2).transpose();
  MatX3 off = ref;
  off.row(0) += Vec3(1, 0, 0).transpose();
  const ErrorMetrics e = computeErrors(std::vector<MatX3>{off, ref}, std::vector<MatX3>{ref, ref},
                                       rest, Vec3(0, 0, 0), {1});
  EXPECT_EQ(e.instants, 2);
  EXPECT_DOUBLE_EQ(e.rmseAll, std::sqrt(1.0 / 4.0));
  EXPECT_DOUBLE_EQ(e.lossRatio, 1.0 / 8.0);
  EXPECT_DOUBLE_EQ(e.rmseNearest[0].second, std::sqrt(1.0 / 2.0));
  EXPECT_DOUBLE_EQ(e.referenceNearest[0].second, 2.0);
}

TEST(Metrics, ReferenceDisplacementOverTheSamplesOnly) {
  // The nearest vertex moves 3 in the reference, the far one 4: the k = 1 figure is the near
  // one's, and it reaches results.json and back.
  const MatX3 rest = rows({Vec3(0, 0, 0), Vec3(5, 0, 0)});
  MatX3 ref = rest;
  ref.row(0) += Vec3(0, 3, 0).transpose();
  ref.row(1) += Vec3(4, 0, 0).transpose();
  const ErrorMetrics e = computeErrors(rest, ref, rest, Vec3(0, 0, 0), {1, 2});
  EXPECT_DOUBLE_EQ(e.referenceNearest[0].second, 3.0);
  EXPECT_DOUBLE_EQ(e.referenceNearest[1].second, std::sqrt(25.0 / 2.0));
  RunRecord r;
  r.error = e;
  r.referenceModel = "reference_fem";
  const auto j = runJson(r);
  EXPECT_DOUBLE_EQ(j["error"]["reference_displacement_1"].get<double>(), 3.0);
  const RunRecord back = runFromJson(j);
  ASSERT_TRUE(back.error);
  EXPECT_EQ(back.error->referenceNearest, e.referenceNearest);
  EXPECT_EQ(back.error->rmseNearest, e.rmseNearest) << "rmse_k is not confused with them";
}

TEST(Results, PlateForcesAtEveryComparedInstant) {
  // Two compared instants, the first without a force (a model that reports none then).
  RunRecord r;
  r.compared.push_back(snapshotAt(10, 0.5, MatX3()));
  r.compared.push_back(snapshotAt(20, 1.0, MatX3()));
  r.compared[1].plateForces = {Vec3(0, 0, 2.5), Vec3(0.1, 0, -1)};
  SurfaceSnapshot both = snapshotAt(30, 1.5, MatX3());
  both.plateForces = {Vec3(0, 0, 3), Vec3(0, 0, -3)};
  r.compared.push_back(both);
  const auto j = runJson(r);
  ASSERT_EQ(j["plate_force_at"].size(), 2u);
  EXPECT_EQ(j["plate_force_at"][0]["t"].get<double>(), 1.0);
  EXPECT_EQ(j["plate_force_at"][0]["plate_force_N"][1][0].get<double>(), 0.1);
  EXPECT_EQ(j["plate_force_at"][1]["plate_force_N"][0][2].get<double>(), 3.0);
  EXPECT_EQ(j["plate_force_N"], j["plate_force_at"][1]["plate_force_N"]) << "the last instant";
}

TEST(Metrics, LossRatioWhenTheReferenceDoesNotMove) {
  const MatX3 rest = rows({Vec3(0, 0, 0), Vec3(1, 0, 0)});
  EXPECT_EQ(computeErrors(rest, rest, rest, Vec3::Zero(), {}).lossRatio, 0.0);
  const MatX3 moved = rest.rowwise() + Vec3(0, 0, 1).transpose();
  EXPECT_TRUE(std::isinf(computeErrors(moved, rest, rest, Vec3::Zero(), {}).lossRatio));
}

TEST(StepStats, WarmUpExcludedMedianP95) {
  std::vector<double> ms;
  for (int i = 1; i <= 100; ++i) ms.push_back(i);
  const StepStats s = stepStatistics(ms, 0.05);
  EXPECT_EQ(s.samples, 95);  // steps 1..5 are warm-up
  EXPECT_DOUBLE_EQ(s.median, 53);
  EXPECT_DOUBLE_EQ(s.mean, 53);
  EXPECT_DOUBLE_EQ(s.max, 100);
  EXPECT_DOUBLE_EQ(s.p95, 96);  // nearest rank ceil(0.95 * 95) = 91 -> 6 + 90
  const StepStats few = stepStatistics({3, 1, 2}, 0.05);
  EXPECT_EQ(few.samples, 3);
  EXPECT_DOUBLE_EQ(few.median, 2);
  EXPECT_DOUBLE_EQ(few.p95, 3);
  EXPECT_EQ(stepStatistics({}, 0.05).samples, 0);
  EXPECT_DOUBLE_EQ(median({4, 1, 3, 2}), 2.5);
}

// ----------------------------------------------------------------------------------- runner

struct Fixture : deform::testing::TetLiftScene {
  Fixture() {
    scene.name = "tet-lift";
    scene.compareAt = {0.5, 1.0};
    scene.nearest = {1, 2};
  }
  /// A fixed box around vertex 0 (the rigid test model does not hold it).
  void fixCorner() { organ.fixed.boxes.push_back(Box{Vec3(-1, -1, -1), Vec3(0.01, 0.01, 0.01)}); }
};

ModelInfo infoFor(std::function<void(RigidTestModel&)> configure, bool grasp = true,
                  int* created = nullptr) {
  ModelInfo info;
  info.name = "rigid";
  info.version = "1";
  info.capabilities = {Capability::PointForce};
  if (grasp) info.capabilities.push_back(Capability::Grasp);
  info.params = {ParamSpec::integer("iterations", 1, 1, 10, "unused")};
  info.create = [configure, created]() -> std::unique_ptr<Model> {
    if (created) ++*created;
    auto m = std::make_unique<RigidTestModel>();
    configure(*m);
    return m;
  };
  return info;
}

RunRecord runWith(const Fixture& f, std::function<void(RigidTestModel&)> configure,
                  bool grasp = true, int* created = nullptr) {
  Cache cache{fs::path()};
  const ModelInfo info = infoFor(std::move(configure), grasp, created);
  return runModel(info, ParamValues::defaults(info.params), f.scene, f.organ, cache);
}

TEST(Runner, OkRunRecordsEveryStepAndFollowsTheGrasp) {
  Fixture f;
  f.fixCorner();
  const RunRecord r = runWith(f, [](RigidTestModel&) {});
  ASSERT_EQ(r.status, RunStatus::Ok) << r.message;
  EXPECT_EQ(r.steps, 100);
  EXPECT_EQ(r.plannedSteps, 100);
  EXPECT_EQ(r.stepMs.size(), 100u);
  EXPECT_EQ(r.stepStats.samples, 95);
  EXPECT_LE(r.stepStats.median, r.stepStats.max);
  EXPECT_LE(r.stepStats.p95, r.stepStats.max);
  for (double ms : r.stepMs) EXPECT_GE(ms, 0.0);
  EXPECT_GE(r.precomputeS, 0.0);
  EXPECT_EQ(r.counts.at("nodes"), 4);
  EXPECT_EQ(r.fixedNodes, 1);
  // The rigid body lifts its fixed corner with everything else: the fixed region did not hold,
  // and the run says so.
  EXPECT_NEAR(r.fixedDrift, 0.02, 1e-12);
  bool noted = false;
  for (const std::string& n : r.notes)
    noted = noted || n.find("fixed region did not hold") != n.npos;
  EXPECT_TRUE(noted);
  EXPECT_EQ(runWith(Fixture{}, [](RigidTestModel&) {}).fixedDrift, 0.0) << "nothing fixed";
  EXPECT_DOUBLE_EQ(r.phaseMs.at("solve"), 0.5);
  EXPECT_EQ(r.params["iterations"], 1);
  ASSERT_EQ(r.compared.size(), 2u);
  EXPECT_EQ(r.compared[0].step, 50);
  EXPECT_NEAR(r.compared[0].positions(3, 2) - 0.1, 0.016, 1e-12);
  EXPECT_NEAR(r.finalSurface(0, 2), 0.02, 1e-12) << "rigid body lifted by 2 cm";
  EXPECT_EQ(r.finalFaces, f.organ.surface.F);
}

TEST(Runner, GraspResidualAndValidity) {
  const Fixture f;
  const RunRecord held = runWith(f, [](RigidTestModel&) {});
  EXPECT_NEAR(held.graspResidual, 0.0, 1e-12) << "the rigid body lands the grasped vertex";
  EXPECT_NEAR(held.graspTravel, 0.02, 1e-15);
  EXPECT_TRUE(held.valid) << held.invalidReason;
  EXPECT_TRUE(held.emptyGrasps.empty());
  EXPECT_FALSE(held.equilibrium);

  // A model that holds nothing: the grasped vertex stays while the tool lifts 2 cm, an RMS
  // residual of about half the lift, far above 10% of the travel.
  const RunRecord loose = runWith(f, [](RigidTestModel& m) { m.ignoreGrasps = true; });
  ASSERT_EQ(loose.status, RunStatus::Ok);
  EXPECT_GT(loose.graspResidual, 0.005);
  EXPECT_FALSE(loose.valid);
  EXPECT_NE(loose.invalidReason.find("grasp residual"), std::string::npos) << loose.invalidReason;

  const RunRecord diverged = runWith(f, [](RigidTestModel& m) { m.nanAtStep = 7; });
  EXPECT_FALSE(diverged.valid);
  EXPECT_EQ(diverged.invalidReason.rfind("diverged at step 7", 0), 0u) << diverged.invalidReason;
}

// Broken runs (issue 35 items 2, 3, 7): each is invalid with its reason, never ok in silence.

// Supports that hold: a fixed region that holds none of the model's nodes, or whose surface moves
// with the organ, makes the run invalid; a model's own count of what it pins is the one reported.
TEST(Runner, ASupportThatHoldsNothingIsInvalid) {
  Fixture f;
  f.organ.fixed.boxes.push_back(Box{Vec3(-1, -1, -1), Vec3(-0.5, -0.5, -0.5)});  // holds nothing
  const RunRecord empty = runWith(f, [](RigidTestModel&) {});
  ASSERT_EQ(empty.status, RunStatus::Ok) << empty.message;
  EXPECT_EQ(empty.fixedNodes, 0);
  EXPECT_FALSE(empty.valid);
  EXPECT_EQ(empty.invalidReason.rfind("the fixed region holds none of the model's nodes", 0), 0u)
      << empty.invalidReason;

  Fixture corner;
  corner.fixCorner();  // holds vertex 0, which the rigid body lifts with the rest
  const RunRecord lifted = runWith(corner, [](RigidTestModel&) {});
  EXPECT_EQ(lifted.fixedNodes, 1);
  EXPECT_FALSE(lifted.valid);
  EXPECT_EQ(lifted.invalidReason.rfind("the fixed region did not hold: its surface moved 20 mm, "
                                       "over 5% of the largest displacement (20 mm)",
                                       0),
            0u)
      << lifted.invalidReason;
  // A model that pins by its own rule reports the count; results take it.
  EXPECT_EQ(runWith(corner, [](RigidTestModel& m) { m.fixedNodes = 7; }).fixedNodes, 7);
  EXPECT_TRUE(runWith(Fixture{}, [](RigidTestModel&) {}).valid) << "nothing fixed, nothing to hold";

  // The 5% threshold itself.
  RunRecord r;
  r.fixedRegion = true;
  r.fixedNodes = 3;
  r.peakDisplacement = 0.010;
  r.fixedDrift = 0.00049;
  EXPECT_EQ(supportProblem(f.scene, r), "");
  r.fixedDrift = 0.00051;
  EXPECT_NE(supportProblem(f.scene, r), "");
  r.fixedRegion = false;
  EXPECT_EQ(supportProblem(f.scene, r), "") << "no fixed region: nothing to hold";
}

// Every early return of runModel() (unsupported, init threw, a surface of the wrong size) and
// every failure is invalid with its status and message as the reason.
TEST(Runner, FailedAndUnsupportedRunsAreNeverValid) {
  const Fixture f;
  const RunRecord unsupported = runWith(
      f, [](RigidTestModel&) {}, /*grasp=*/false);
  ASSERT_EQ(unsupported.status, RunStatus::Unsupported);
  EXPECT_FALSE(unsupported.valid);
  EXPECT_EQ(unsupported.invalidReason.rfind("unsupported (the scene's tool 0 (grasper)", 0), 0u)
      << unsupported.invalidReason;
  const RunRecord init = runWith(f, [](RigidTestModel& m) { m.throwInInit = true; });
  ASSERT_EQ(init.status, RunStatus::Failed);
  EXPECT_FALSE(init.valid);
  EXPECT_EQ(init.invalidReason.rfind("failed (init: ", 0), 0u) << init.invalidReason;
  const RunRecord rows = runWith(f, [](RigidTestModel& m) { m.shortSurface = true; });
  ASSERT_EQ(rows.status, RunStatus::Failed);
  EXPECT_FALSE(rows.valid);
  EXPECT_NE(rows.invalidReason.find("surface() has 3 rows, the organ has 4"), std::string::npos)
      << rows.invalidReason;
  const RunRecord step = runWith(f, [](RigidTestModel& m) { m.throwAtStep = 3; });
  EXPECT_FALSE(step.valid);
  EXPECT_EQ(step.invalidReason, "failed (step 3: injected failure)");
  // Whoever made the record, results.json never says valid: true for a run that did not end ok.
  RunRecord crashed;
  crashed.status = RunStatus::Failed;
  crashed.message = "SIGSEGV";
  const auto j = runJson(crashed);
  EXPECT_FALSE(j.at("valid").get<bool>());
  EXPECT_EQ(j.at("invalid_reason"), "failed (SIGSEGV)");
  invalidateIfNotOk(crashed);
  EXPECT_FALSE(crashed.valid);
}

// An instrument whose coupling blows up (here a dynamic grasper at k dt^2 / m = 6, above the
// limit 4 of ODE's step: parseScene() would refuse it, the struct is built by hand) stops the run
// at that step, diverged and invalid, before its forces reach the model.
TEST(Runner, AnExplodingInstrumentStopsTheRunAndIsInvalid) {
  Fixture f;
  ToolDynamics d;
  d.mass = 0.01;  // 0.012 kg with the jaws
  d.coupling.stiffness = 720;
  d.coupling.damping = 0;
  f.scene.tools[0].dynamics = d;
  EXPECT_NEAR(couplingStabilityNumber(d.coupling, 1.2 * d.mass, f.scene.dt), 6.0, 1e-12);
  Cache cache{fs::path()};
  ModelInfo info = infoFor([](RigidTestModel&) {});
  info.capabilities.push_back(Capability::ReactionForce);
  const RunRecord r = runModel(info, ParamValues::defaults(info.params), f.scene, f.organ, cache);
  ASSERT_EQ(r.status, RunStatus::Diverged) << r.message;
  EXPECT_NE(r.message.find("an object or instrument diverged: tools/0"), std::string::npos)
      << r.message;
  EXPECT_LT(r.steps, 30) << "stopped at the explosion, not at the end";
  EXPECT_FALSE(r.valid);

  d.coupling.stiffness = 200;  // k dt^2 / m = 1.7: stable
  f.scene.tools[0].dynamics = d;
  const RunRecord calm =
      runModel(info, ParamValues::defaults(info.params), f.scene, f.organ, cache);
  EXPECT_EQ(calm.status, RunStatus::Ok) << calm.message;
}

// Outrunning the tool: a note with the ratio when the surface moves over 1.5x the largest
// prescribed motion in a scene driven by prescribed motion alone.
TEST(Runner, ASurfaceThatOutrunsTheToolGetsANote) {
  Fixture f;
  RunRecord r;
  r.prescribedMotion = 0.010;
  r.peakDisplacement = 0.0185;
  EXPECT_EQ(outrunNote(f.scene, r),
            "the surface outran the tool: surface points moved up to 18.5 mm, 1.85x the largest "
            "prescribed motion (10 mm; over 1.5x in a quasi-static scene)");
  r.peakDisplacement = 0.0149;
  EXPECT_EQ(outrunNote(f.scene, r), "");
  r.peakDisplacement = 0.0185;
  LoadSpec force;
  f.scene.loads.push_back(force);
  EXPECT_EQ(outrunNote(f.scene, r), "") << "a point force is not bounded by any tool";
  // In a run: the rigid body lets go of the grasp and drifts 1 mm per step, 100 mm against the
  // tool's 20 mm lift.
  const RunRecord drifting = runWith(Fixture{}, [](RigidTestModel& m) {
    m.ignoreGrasps = true;
    m.drift = Vec3(0.001, 0, 0);
  });
  EXPECT_NEAR(drifting.prescribedMotion, 0.02, 1e-12);
  bool noted = false;
  for (const std::string& n : drifting.notes)
    noted |= n.rfind("the surface outran the tool", 0) == 0;
  EXPECT_TRUE(noted);
}

// A frozen solver (status ok, nothing moves) under a load is invalid; the same model in a scene
// that asks for no motion is not.
TEST(Runner, AModelThatDoesNotMoveUnderALoadIsInvalid) {
  Fixture f;
  f.scene.tools.clear();
  LoadSpec load;
  load.at = f.organ.surface.V.row(3).transpose();
  load.force = Vec3(0, 0, 1);
  f.scene.loads.push_back(load);
  const RunRecord frozen = runWith(f, [](RigidTestModel&) {});  // ignores loads: never moves
  ASSERT_EQ(frozen.status, RunStatus::Ok) << frozen.message;
  EXPECT_EQ(frozen.peakDisplacement, 0.0);
  EXPECT_GT(frozen.motionFloor, 0.0);
  EXPECT_FALSE(frozen.valid);
  EXPECT_EQ(frozen.invalidReason.rfind("did not move", 0), 0u) << frozen.invalidReason;

  const RunRecord moving = runWith(f, [](RigidTestModel& m) { m.drift = Vec3(0, 0, 1e-6); });
  EXPECT_NEAR(moving.peakDisplacement, 1e-4, 1e-12);
  EXPECT_TRUE(moving.valid) << moving.invalidReason;

  f.scene.loads.clear();
  const RunRecord still = runWith(f, [](RigidTestModel&) {});
  EXPECT_EQ(still.motionFloor, 0.0);
  EXPECT_TRUE(still.valid) << still.invalidReason;
}

// A solver that gave up on a solve (numeric "unconverged_steps" > 0, e.g. reference_fem's Newton)
// is invalid, not ok in silence; the same counter at zero changes nothing.
TEST(Runner, ARunWithUnconvergedSolvesIsInvalid) {
  Fixture f;
  const RunRecord gaveUp = runWith(f, [](RigidTestModel& m) { m.unconverged = 2; });
  ASSERT_EQ(gaveUp.status, RunStatus::Ok) << gaveUp.message;
  EXPECT_FALSE(gaveUp.valid);
  EXPECT_EQ(gaveUp.invalidReason, "2 solves did not converge");
  // reference_fem's counts of why: stopped at a fold, out of its Newton budget.
  const RunRecord why = runWith(f, [](RigidTestModel& m) {
    m.unconverged = 2;
    m.extraNumeric = {{"solves_stopped_at_fold", 0}, {"solves_out_of_budget", 1}};
  });
  EXPECT_EQ(why.invalidReason,
            "2 solves did not converge (1 gave up at its budget of Newton iterations "
            "(max_solve_newton_iterations))");
  const RunRecord converged = runWith(f, [](RigidTestModel&) {});
  EXPECT_TRUE(converged.valid) << converged.invalidReason;
}

// A tet network that turned over 0.5% of its tets inside out (numeric "inverted_tets" against
// counts "elements") is invalid; a few inverted slivers, or the counter without an element count,
// are not.
TEST(Runner, ARunThatInvertedOverHalfAPercentOfItsTetsIsInvalid) {
  Fixture f;
  const RunRecord folded = runWith(f, [](RigidTestModel& m) {
    m.elements = 4000;
    m.inverted = 21;
  });
  ASSERT_EQ(folded.status, RunStatus::Ok) << folded.message;
  EXPECT_FALSE(folded.valid);
  EXPECT_EQ(folded.invalidReason,
            "21 of 4000 tets inverted (over 0.5%): the network folded through itself");
  const RunRecord slivers = runWith(f, [](RigidTestModel& m) {
    m.elements = 4000;
    m.inverted = 20;
  });
  EXPECT_TRUE(slivers.valid) << slivers.invalidReason;
  const RunRecord uncounted = runWith(f, [](RigidTestModel& m) { m.inverted = 21; });
  EXPECT_TRUE(uncounted.valid) << uncounted.invalidReason;
}

TEST(Runner, EquilibriumComparisonStopsWhenSettled) {
  Fixture f;
  f.scene.compareAt.clear();
  f.scene.compareAtEquilibrium = true;
  // The tool stops at t = 0.6; the rigid body stops with it and is settled 20 quiet steps later.
  const RunRecord r = runWith(f, [](RigidTestModel&) {});
  ASSERT_EQ(r.status, RunStatus::Ok) << r.message;
  ASSERT_TRUE(r.settledAt.has_value());
  EXPECT_NEAR(*r.settledAt, 0.8, 1e-9);
  EXPECT_EQ(r.steps, 80);
  ASSERT_EQ(r.compared.size(), 1u);
  EXPECT_EQ(r.compared[0].step, 80);
  EXPECT_TRUE(r.valid);

  // A model that keeps moving (1 mm/s, no grasp to hold it) runs to the cap, is compared there
  // and is invalid.
  f.scene.tools.clear();
  const RunRecord drifting = runWith(f, [](RigidTestModel& m) { m.drift = Vec3(1e-5, 0, 0); });
  ASSERT_EQ(drifting.status, RunStatus::Ok);
  EXPECT_FALSE(drifting.settledAt.has_value());
  EXPECT_EQ(drifting.steps, 100);
  ASSERT_EQ(drifting.compared.size(), 1u);
  EXPECT_EQ(drifting.compared[0].step, 100);
  EXPECT_FALSE(drifting.valid);
  EXPECT_EQ(drifting.invalidReason, "did not settle");
}

/// The run diverged at `step`, and its message says `why`.
::testing::AssertionResult divergedAt(const RunRecord& r, int step, const std::string& why) {
  if (r.status != RunStatus::Diverged || r.steps != step ||
      r.message.find(why) == std::string::npos)
    return ::testing::AssertionFailure()
           << statusName(r.status) << " at step " << r.steps << ": " << r.message;
  return ::testing::AssertionSuccess();
}

TEST(Runner, NanIsDivergenceAtThatStep) {
  const Fixture f;
  const RunRecord r = runWith(f, [](RigidTestModel& m) { m.nanAtStep = 7; });
  EXPECT_TRUE(divergedAt(r, 7, "NaN"));
  EXPECT_NE(r.message.find("step 7"), std::string::npos) << r.message;
}

TEST(Runner, LeavingTheBoxIsDivergence) {
  const Fixture f;
  EXPECT_TRUE(
      divergedAt(runWith(f, [](RigidTestModel& m) { m.runawayAtStep = 3; }), 3, "divergence box"));
  EXPECT_TRUE(divergedAt(runWith(f, [](RigidTestModel& m) { m.reportDivergedAtStep = 4; }), 4, ""));
}

TEST(Runner, ExceptionsAreFailures) {
  const Fixture f;
  const RunRecord r = runWith(f, [](RigidTestModel& m) { m.throwAtStep = 3; });
  EXPECT_EQ(r.status, RunStatus::Failed);
  EXPECT_NE(r.message.find("step 3"), std::string::npos) << r.message;
  EXPECT_NE(r.message.find("injected failure"), std::string::npos) << r.message;
  const RunRecord i = runWith(f, [](RigidTestModel& m) { m.throwInInit = true; });
  EXPECT_EQ(i.status, RunStatus::Failed);
  EXPECT_NE(i.message.find("init: "), std::string::npos) << i.message;
  EXPECT_NE(i.message.find("cannot handle"), std::string::npos) << i.message;
}

TEST(Runner, MissingCapabilityIsUnsupportedWithoutRunning) {
  const Fixture f;
  int created = 0;
  const RunRecord r = runWith(
      f, [](RigidTestModel&) {}, /*grasp=*/false, &created);
  EXPECT_EQ(r.status, RunStatus::Unsupported);
  EXPECT_NE(r.message.find("grasp"), std::string::npos) << r.message;
  EXPECT_EQ(created, 0);
  EXPECT_TRUE(r.stepMs.empty());
}

TEST(Runner, APlateMovesTheModelAndMarkersWithoutTheCapabilityAreUnsupported) {
  Fixture f;
  f.scene.tools.clear();
  PlateSpec plate;  // holds the apex (0, 0, 0.1) and lifts it 1 cm
  plate.region = Box{Vec3(-1, -1, 0.05), Vec3(1, 1, 1)};
  plate.trajectory = {KeyFrame{0.0, Vec3::Zero(), false}, KeyFrame{1.0, Vec3(0, 0, 0.01), false}};
  f.scene.plates.push_back(plate);
  f.scene.markers.points = MatX3::Constant(1, 3, 0.01);
  const RunRecord r = runWith(f, [](RigidTestModel&) {});
  ASSERT_EQ(r.status, RunStatus::Ok) << r.message;
  EXPECT_TRUE(r.valid) << r.invalidReason;
  EXPECT_NEAR(r.finalSurface(3, 2), 0.11, 1e-12) << "the plate's vertex followed its offset";
  EXPECT_NEAR(r.graspTravel, 0.01, 1e-15) << "the plate's travel scales the residual test";
  EXPECT_EQ(r.markerStatus, "unsupported");
  EXPECT_NE(r.markerReason.find("does not have the markers capability"), std::string::npos)
      << r.markerReason;
  ASSERT_EQ(r.compared.size(), 2u);
  EXPECT_EQ(r.compared[1].markers.rows(), 0);
  // The results document says so, per run.
  const auto j = runJson(r);
  EXPECT_EQ(j["markers"]["status"], "unsupported");
  // A model without the grasp capability cannot hold a plate.
  const RunRecord no = runWith(
      f, [](RigidTestModel&) {}, /*grasp=*/false);
  EXPECT_EQ(no.status, RunStatus::Unsupported);
  EXPECT_NE(no.message.find("plates"), std::string::npos) << no.message;
}

TEST(Runner, ResetThenRerunReproducesBitForBit) {
  const Fixture f;
  RigidTestModel model;
  Cache cache{fs::path()};
  const ParamValues params;
  model.init(ModelSetup{f.organ, params, cache, f.scene.dt, f.scene.gravity});
  RunRecord a, b;
  simulate(model, f.scene, f.organ, RunOptions{}, a);
  model.reset();
  simulate(model, f.scene, f.organ, RunOptions{}, b);
  ASSERT_EQ(a.status, RunStatus::Ok);
  EXPECT_TRUE(a.finalSurface == b.finalSurface);
  EXPECT_FALSE(a.finalSurface == f.organ.surface.V);
}

TEST(Runner, MaxStepsAndComparedSteps) {
  Fixture f;
  RunOptions o;
  o.maxSteps = 10;
  Cache cache{fs::path()};
  const ModelInfo info = infoFor([](RigidTestModel&) {});
  const RunRecord r =
      runModel(info, ParamValues::defaults(info.params), f.scene, f.organ, cache, o);
  EXPECT_EQ(r.steps, 10);
  EXPECT_EQ(comparedSteps(f.scene), (std::vector<int>{50, 100}));
  EXPECT_EQ(comparedSteps(f.scene, 60), (std::vector<int>{50})) << "a run cut short at step 60";
  EXPECT_EQ(r.compared.size(), 0u) << "10 steps reach no compared instant";
  f.scene.compareAt.clear();
  EXPECT_EQ(comparedSteps(f.scene), (std::vector<int>{100}));
  EXPECT_EQ(comparedSteps(f.scene, 10), (std::vector<int>{10})) << "the end of a shortened run";
  const RunRecord shortRun =
      runModel(info, ParamValues::defaults(info.params), f.scene, f.organ, cache, o);
  ASSERT_EQ(shortRun.compared.size(), 1u);
  EXPECT_EQ(shortRun.compared[0].step, 10);
}

TEST(Runner, ErrorsAgainstTheReferenceRun) {
  const Fixture f;
  std::vector<RunRecord> runs;
  runs.push_back(runWith(f, [](RigidTestModel&) {}));
  runs.push_back(runWith(f, [](RigidTestModel&) {}));
  runs.back().isReference = true;
  runs.back().model = "exact";
  // Move the reference's last compared surface: the model is then off by 1 mm there.
  runs.back().compared[1].positions.rowwise() += Vec3(0.001, 0, 0).transpose();
  computeRunErrors(f.scene, f.organ, runs);
  ASSERT_TRUE(runs[0].error.has_value());
  EXPECT_FALSE(runs[1].error.has_value());
  EXPECT_EQ(runs[0].referenceModel, "exact");
  EXPECT_NEAR(runs[0].error->max, 0.001, 1e-12);
  EXPECT_NEAR(runs[0].error->rmseAll, std::sqrt(0.5) * 0.001, 1e-12);  // half the instants off
}

// A reference that is invalid or failed marks every model run (issue 33 item 7), and a failed
// one says why in the note that replaces the errors.
TEST(Runner, ErrorsAgainstAnInvalidReferenceAreMarked) {
  const Fixture f;
  std::vector<RunRecord> runs;
  runs.push_back(runWith(f, [](RigidTestModel&) {}));
  runs.push_back(runWith(f, [](RigidTestModel& m) { m.unconverged = 2; }));
  runs.back().isReference = true;
  runs.back().label = "ref";
  computeRunErrors(f.scene, f.organ, runs);
  ASSERT_TRUE(runs[0].error.has_value()) << "an invalid reference that ran still gives errors";
  ASSERT_TRUE(runs[0].referenceValid.has_value());
  EXPECT_FALSE(*runs[0].referenceValid);
  EXPECT_EQ(runs[0].referenceInvalidReason,
            "the reference ref is invalid: 2 solves did not converge");
  const auto j = runJson(runs[0]);
  EXPECT_FALSE(j.at("reference_valid").get<bool>());
  EXPECT_FALSE(runJson(runs[1]).contains("reference_valid")) << "not on the reference itself";

  runs[1] = runWith(f, [](RigidTestModel& m) { m.throwInInit = true; });
  runs[1].isReference = true;
  runs[1].label = "ref";
  runs[0].error.reset();
  runs[0].notes.clear();
  computeRunErrors(f.scene, f.organ, runs);
  EXPECT_FALSE(runs[0].error.has_value());
  EXPECT_FALSE(*runs[0].referenceValid);
  ASSERT_FALSE(runs[0].notes.empty());
  EXPECT_EQ(runs[0].notes.back().rfind("no error: the reference run is failed (init: ", 0), 0u)
      << runs[0].notes.back();

  runs[1] = runWith(f, [](RigidTestModel&) {});
  runs[1].isReference = true;
  computeRunErrors(f.scene, f.organ, runs);
  EXPECT_TRUE(*runs[0].referenceValid);
  EXPECT_TRUE(runJson(runs[0]).at("reference_valid").get<bool>());
}

// Issue 35: a model that moved by more than its size (or through its support) where the reference
// barely moves the organ collapsed: the run is invalid, not "ok" with a large error.
TEST(Runner, ACollapseWhereTheReferenceHoldsStillIsInvalid) {
  const Fixture f;
  std::vector<RunRecord> runs;
  runs.push_back(runWith(f, [](RigidTestModel&) {}));
  runs.push_back(runWith(f, [](RigidTestModel&) {}));
  runs.push_back(runWith(f, [](RigidTestModel&) {}));
  runs.back().isReference = true;
  runs.back().finalSurface = f.organ.surface.V;  // the reference: at rest
  runs[0].finalSurface = f.organ.surface.V;
  runs[0].finalSurface.col(2).array() -= 0.3;  // three times the 0.1 m tet's size, down
  runs[1].finalSurface = f.organ.surface.V;
  runs[1].finalSurface.col(2).array() -= 0.005;
  ASSERT_TRUE(runs[0].valid && runs[1].valid);
  computeRunErrors(f.scene, f.organ, runs);
  EXPECT_FALSE(runs[0].valid);
  EXPECT_EQ(runs[0].invalidReason.rfind("collapsed: moved by more than its size", 0), 0u)
      << runs[0].invalidReason;
  EXPECT_TRUE(runs[1].valid) << runs[1].invalidReason;
  // Where the reference moves the organ as far, the same run is valid.
  runs[2].finalSurface = runs[0].finalSurface;
  runs[0].valid = true;
  runs[0].invalidReason.clear();
  computeRunErrors(f.scene, f.organ, runs);
  EXPECT_TRUE(runs[0].valid) << runs[0].invalidReason;
}

// A surface that passes through itself is no state of a solid: a reference that ends there is
// invalid (its models read "against an invalid reference"), and a model's run says so in a note.
TEST(Runner, AReferenceWhoseSurfacePassesThroughItselfIsInvalid) {
  Fixture f;
  // Two 0.1 m cubes' surfaces in place of the tet: the grasp holds a corner of the first; corner
  // 15 of the second, 0.3 m away, is then pushed through its bottom face.
  const MatX3 corners =
      (MatX3(8, 3) << 0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0, 0, 0, 1, 1, 0, 1, 0, 1, 1, 1, 1, 1)
          .finished() *
      0.1;
  const MatX3i faces = (MatX3i(12, 3) << 0, 2, 3, 0, 3, 1, 4, 5, 7, 4, 7, 6, 0, 1, 5, 0, 5, 4, 2, 6,
                        7, 2, 7, 3, 0, 4, 6, 0, 6, 2, 1, 3, 7, 1, 7, 5)
                           .finished();
  f.organ.surface.V.resize(16, 3);
  f.organ.surface.V << corners, corners.rowwise() + Vec3(0.3, 0, 0).transpose();
  f.organ.surface.F.resize(24, 3);
  f.organ.surface.F << faces, faces.array() + 8;
  ASSERT_TRUE(findSelfIntersections(f.organ.surface).ok());
  MatX3 through = f.organ.surface.V;
  through.row(15) = Vec3(0.32, 0.03, -0.05).transpose();
  ASSERT_FALSE(findSelfIntersections({through, f.organ.surface.F}).ok());

  std::vector<RunRecord> runs(3);
  for (RunRecord& r : runs) {
    r.status = RunStatus::Ok;
    r.compared = {snapshotAt(50, 0.5, f.organ.surface.V), snapshotAt(100, 1.0, through)};
    r.finalSurface = through;
  }
  runs[1].compared[1].positions = f.organ.surface.V;  // this model stays clear
  runs[2].isReference = true;
  runs[2].label = "ref";
  computeRunErrors(f.scene, f.organ, runs);
  EXPECT_FALSE(runs[2].valid);
  EXPECT_EQ(runs[2].invalidReason.rfind("its surface passes through itself at t = 1 s (", 0), 0u)
      << runs[2].invalidReason;
  EXPECT_FALSE(*runs[0].referenceValid);
  EXPECT_TRUE(runs[0].valid) << "a model's own fold is a note";
  ASSERT_FALSE(runs[0].notes.empty());
  EXPECT_EQ(runs[0].notes.front().rfind("the surface passes through itself at t = 1 s", 0), 0u);
  EXPECT_TRUE(runs[1].notes.empty());

  // The same reference at rest throughout is valid.
  runs[2] = runs[1];
  runs[2].isReference = true;
  computeRunErrors(f.scene, f.organ, runs);
  EXPECT_TRUE(runs[2].valid) << runs[2].invalidReason;
  EXPECT_TRUE(*runs[0].referenceValid);

  // Where the grasp holds corner 15, every intersecting triangle touches a held vertex: a fold at
  // the edge of a rigid region the scene gives no contact, noted, the reference still valid.
  for (KeyFrame& k : f.scene.tools[0].trajectory) k.pos = Vec3(0.4, 0.1, 0.1);
  EXPECT_EQ(SelfIntersectionCheck(f.scene, f.organ)(through).free, 0);
  runs[2].compared[1].positions = through;
  computeRunErrors(f.scene, f.organ, runs);
  EXPECT_TRUE(runs[2].valid) << runs[2].invalidReason;
  ASSERT_FALSE(runs[2].notes.empty());
  EXPECT_EQ(runs[2].notes.back().rfind("the surface folds through itself at the edge of the held "
                                       "region at t = 1 s (",
                                       0),
            0u)
      << runs[2].notes.back();
}

TEST(Metrics, GraspSceneRmseKLeavesOutTheGraspedVertices) {
  // The grasp closes at the tet's apex (vertex 3, within its 5 mm radius): rmse_k is taken over
  // the vertices nearest the grasp that it does not hold (0, then 1), and results.json says so.
  const Fixture f;
  const MatX3& rest = f.organ.surface.V;
  const std::vector<int> held = rmseExcludedVertices(f.scene, rest);
  EXPECT_EQ(held, std::vector<int>{3});
  EXPECT_EQ(deform::graspedSurfaceVertices(rest, Vec3(0.05, 0.05, 0.05), 1e-4).size(), 1u)
      << "at least the nearest vertex";
  MatX3 model = rest;
  model(3, 0) += 0.001;  // error on the held vertex only: out of rmse_k
  model(0, 0) += 0.002;
  const Vec3 focus(0, 0, 0.1);
  const ErrorMetrics e = computeErrors({model}, {rest}, rest, focus, {1, 2}, held);
  EXPECT_EQ(e.nearestSamples, "nearest_ungrasped");
  EXPECT_DOUBLE_EQ(e.rmseNearest[0].second, 0.002);
  EXPECT_DOUBLE_EQ(e.rmseNearest[1].second, std::sqrt(0.5) * 0.002);
  EXPECT_DOUBLE_EQ(computeErrors(model, rest, rest, focus, {1}).rmseNearest[0].second, 0.001);
  // A scene with a load measures around the load: nothing is left out.
  Scene loaded = f.scene;
  loaded.loads.emplace_back();
  EXPECT_TRUE(rmseExcludedVertices(loaded, rest).empty());

  std::vector<RunRecord> runs;
  runs.push_back(runWith(f, [](RigidTestModel&) {}));
  runs.push_back(runWith(f, [](RigidTestModel&) {}));
  runs.back().isReference = true;
  computeRunErrors(f.scene, f.organ, runs);
  const auto j = runJson(runs[0]);
  EXPECT_EQ(j["error"]["rmse_k_samples"], "nearest_ungrasped");
  EXPECT_EQ(j["error"]["rmse_k_excluded_grasped"], 1);
}

// ---------------------------------------------------------------------------------- results

TEST(Results, SanitizedLabels) {
  EXPECT_EQ(sanitizeLabel("pbd(iterations=10)"), "pbd_iterations_10");
  EXPECT_EQ(sanitizeLabel("../../etc"), "_.._etc");
  EXPECT_EQ(sanitizeLabel("///"), "run");
  EXPECT_EQ(sanitizeLabel("fem-hex_2.0"), "fem-hex_2.0");
}

TEST(Results, WrittenAtomicallyAndParseable) {
  Fixture f;
  f.scene.surfaces = SurfaceOutput::Every;
  f.scene.surfaceEvery = 25;
  std::vector<RunRecord> runs;
  runs.push_back(runWith(f, [](RigidTestModel&) {}));
  runs.back().label = "rigid(a=1)";
  runs.push_back(runWith(f, [](RigidTestModel& m) { m.nanAtStep = 2; }));
  runs.back().label = "rigid nan";
  runs.push_back(runWith(f, [](RigidTestModel&) {}));
  runs.back().label = "ref";
  runs.back().isReference = true;
  computeRunErrors(f.scene, f.organ, runs);
  ASSERT_EQ(runs[0].series.size(), 5u);  // rest + every 25 steps of 100

  const fs::path out = fs::temp_directory_path() / "deform_results_test";
  fs::remove_all(out);
  fs::create_directories(out);
  writeRunSurfaces(out, f.scene, f.organ, runs);
  const auto doc = resultsJson(f.scene, f.organ, {"a log line"}, runs, machineInfo());
  const fs::path path = writeResults(out, doc);
  EXPECT_EQ(path, out / "results.json");

  std::ifstream in(path);
  const json back = json::parse(in);
  EXPECT_EQ(back["format"], "deformbench-results/1");
  EXPECT_EQ(back["scene"]["name"], "tet-lift");
  ASSERT_EQ(back["runs"].size(), 3u);
  const json& r0 = back["runs"][0];
  EXPECT_EQ(r0["status"], "ok");
  EXPECT_EQ(r0["label"], "rigid(a=1)");
  EXPECT_EQ(r0["steps"], 100);
  for (const char* k : {"median", "p95", "max", "mean"}) EXPECT_TRUE(r0["step_ms"][k].is_number());
  EXPECT_EQ(r0["counts"]["nodes"], 4);
  EXPECT_EQ(r0["error"]["reference"], "rigid");
  EXPECT_DOUBLE_EQ(r0["error"]["rmse_all"].get<double>(), 0.0);
  EXPECT_TRUE(r0["error"].contains("rmse_1"));
  EXPECT_TRUE(r0["error"].contains("rmse_2"));
  EXPECT_EQ(r0["final_surface"], "rigid_a_1/final.obj");
  EXPECT_TRUE(fs::exists(out / "rigid_a_1/final.obj"));
  EXPECT_TRUE(fs::exists(out / "rigid_a_1/surfaces.pvd"));
  EXPECT_TRUE(fs::exists(out / "rigid_a_1/surface_000050.vtp"));
  const json& r1 = back["runs"][1];
  EXPECT_EQ(r1["status"], "diverged");
  EXPECT_FALSE(r1.contains("error"));
  EXPECT_FALSE(r1.contains("final_surface"));
  EXPECT_EQ(back["runs"][2]["role"], "reference");
  EXPECT_FALSE(back["machine"]["timestamp"].get<std::string>().empty());
  // Nothing but results.json, the rest surface and the run folders: no temporary files left.
  EXPECT_TRUE(fs::exists(out / kRestSurfaceFile));
  for (const auto& entry : fs::directory_iterator(out)) {
    if (entry.is_regular_file()) {
      const std::string name = entry.path().filename().string();
      EXPECT_TRUE(name == "results.json" || name == kRestSurfaceFile) << name;
    }
  }
  fs::remove_all(out);
}

TEST(Results, NoReferenceMeansNoErrorKey) {
  const Fixture f;
  std::vector<RunRecord> runs;
  runs.push_back(runWith(f, [](RigidTestModel&) {}));
  computeRunErrors(f.scene, f.organ, runs);
  EXPECT_FALSE(runJson(runs[0]).contains("error"));
}

}  // namespace
}  // namespace deform::harness

// ------------------------------------------------------------- the whole pipeline, via a plugin
#ifdef DEFORM_FIXTURE_PLUGIN_DIR
namespace deform::harness {
namespace {

class Pipeline : public ::testing::Test {
 protected:
  void SetUp() override { m_dir = deform::testing::freshTestDir("deform_pipeline_"); }
  void TearDown() override { fs::remove_all(m_dir); }

  /// Toy scene on the cube phantom: a grasp on the top face lifting 1 cm.
  json scene() const {
    return json::parse(R"({
      "name": "toy-lift",
      "organ": {"mesh": "phantom:cube", "resolution": 0.3,
                "fixed": {"box": [[-1, -1, -1], [1, 1, -0.04]]}},
      "gravity": [0, 0, 0], "dt": 0.01, "duration": 0.5,
      "tools": [{"type": "grasper", "radius": 0.02,
                 "trajectory": [{"t": 0, "pos": [0, 0, 0.05], "jaw": "closed"},
                                {"t": 0.4, "pos": [0, 0, 0.06]}]}],
      "models": [{"plugin": "toy", "params": {"gain": 0.5}}],
      "reference": {"plugin": "toy", "label": "exact", "params": {}},
      "compare_at": [0.2, 0.5]
    })");
  }
  std::string write(const json& j) const {
    const fs::path p = m_dir / "scene.json";
    std::ofstream(p) << j.dump(2);
    return p.string();
  }
  BenchmarkOptions options() const {
    BenchmarkOptions o;
    o.outDir = m_dir / "out";
    o.cacheDir = fs::path();
    return o;
  }
  fs::path m_dir;
};

TEST_F(Pipeline, RunsModelsAndReferenceAndWritesResults) {
  PluginLoader loader({DEFORM_FIXTURE_PLUGIN_DIR});
  std::vector<std::string> explained;
  BenchmarkOptions o = options();
  o.explain = [&](const std::string& s) { explained.push_back(s); };
  const BenchmarkResult r = runBenchmark(write(scene()), loader, o);
  ASSERT_EQ(r.runs.size(), 2u);
  EXPECT_EQ(r.runs[0].label, "toy(gain=0.5)");
  EXPECT_EQ(r.runs[1].label, "exact");
  EXPECT_TRUE(r.runs[1].isReference);
  ASSERT_TRUE(r.runs[0].error.has_value());
  // gain 0.5 lags the tool: e <- (1 - g)(e + v) settles at e = v = 0.25 mm per step while the
  // tool moves (t = 0.2) and decays to ~0 after it stops (t = 0.5).
  EXPECT_GT(r.runs[0].error->max, 1e-4);
  EXPECT_LT(r.runs[0].error->max, 5e-4);
  EXPECT_GT(r.runs[0].error->lossRatio, 0.0);
  std::ifstream in(r.resultsPath);
  const json doc = json::parse(in);
  EXPECT_EQ(doc["scene"]["name"], "toy-lift");
  EXPECT_EQ(doc["scene"]["sha256"].get<std::string>().size(), 64u);
  EXPECT_EQ(doc["runs"][0]["params"]["gain"], 0.5);
  EXPECT_EQ(doc["runs"][0]["params"]["iterations"], 20) << "defaults are written too";
  EXPECT_EQ(doc["runs"][0]["error"]["reference"], "toy");
  EXPECT_TRUE(fs::exists(m_dir / "out" / doc["runs"][0]["final_surface"].get<std::string>()));
  const auto has = [&](const std::string& prefix) {
    return std::any_of(explained.begin(), explained.end(),
                       [&](const std::string& s) { return s.rfind(prefix, 0) == 0; });
  };
  EXPECT_TRUE(has("loaded plugin "));
  EXPECT_TRUE(has("built model toy(gain=0.5)"));
  EXPECT_TRUE(has("built reference exact"));
}

TEST_F(Pipeline, NoReferenceMeansNoError) {
  PluginLoader loader({DEFORM_FIXTURE_PLUGIN_DIR});
  BenchmarkOptions o = options();
  o.noReference = true;
  const BenchmarkResult r = runBenchmark(write(scene()), loader, o);
  ASSERT_EQ(r.runs.size(), 1u);
  EXPECT_FALSE(r.runs[0].error.has_value());
}

TEST_F(Pipeline, BadParameterStopsBeforeAnyOutput) {
  PluginLoader loader({DEFORM_FIXTURE_PLUGIN_DIR});
  json j = scene();
  j["models"][0]["params"]["gain"] = 2;
  try {
    runBenchmark(write(j), loader, options());
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.place(), "/models/0/params/gain");
    EXPECT_NE(std::string(e.what()).find("must be <= 1, got 2"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(m_dir / "out"));
}

TEST_F(Pipeline, MissingPluginAndOnlyFilter) {
  PluginLoader loader({DEFORM_FIXTURE_PLUGIN_DIR});
  json j = scene();
  j["models"][0]["plugin"] = "absent";
  EXPECT_THROW(runBenchmark(write(j), loader, options()), PluginError);
  EXPECT_FALSE(fs::exists(m_dir / "out"));

  BenchmarkOptions o = options();
  o.only = {"nothing"};
  EXPECT_THROW(runBenchmark(write(scene()), loader, o), InputError);
  o.only = {"toy(gain=0.5)"};
  EXPECT_EQ(runBenchmark(write(scene()), loader, o).runs.size(), 2u) << "the reference stays";
}

}  // namespace
}  // namespace deform::harness
#endif
