// Issue 35, "one plugin's crash takes down the rest": each run in a forked child
// (run_isolation.h) gives the same record as in process, a SIGSEGV in init() or step() is that
// run's failed row, and a plugin that crashes while registering is a PluginError naming the
// signal. Also the progress callback of long runs and the --retry-failed rule of child tasks.
#include <deform/engine/plugin_loader.h>
#include <deform/engine/scene.h>
#include <deform/internal/sanitizers.h>
#include <deform_harness/dispatch.h>
#include <deform_harness/run_isolation.h>
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>

#include "tet_lift_scene.h"

namespace deform::harness {
namespace {

namespace fs = std::filesystem;
using deform::testing::RigidTestModel;

struct LiftScene : deform::testing::TetLiftScene {
  LiftScene() {
    scene.compareAt = {0.5, 1.0};
    scene.nearest = {1, 2};
  }
};

ModelInfo rigidInfo() {
  ModelInfo info;
  info.name = "rigid";
  info.version = "1";
  info.capabilities = {Capability::Grasp, Capability::PointForce};
  info.create = [] { return std::make_unique<RigidTestModel>(); };
  return info;
}

// AddressSanitizer catches a child's SIGSEGV itself and exits instead of dying by the signal,
// so the crash tests run in the plain build only.
#if DEFORM_ASAN
#define SKIP_UNDER_ASAN() GTEST_SKIP() << "ASan handles the child's SIGSEGV itself"
#else
#define SKIP_UNDER_ASAN() (void)0
#endif

TEST(RunIsolation, TheChildsRecordEqualsTheInProcessOne) {
  const LiftScene f;
  Cache cache{fs::path()};
  const ModelInfo info = rigidInfo();
  const ParamValues params = ParamValues::defaults(info.params);
  const RunRecord here = runModel(info, params, f.scene, f.organ, cache);
  const RunRecord there = runModelIsolated(info, params, f.scene, f.organ, cache);
  ASSERT_EQ(there.status, RunStatus::Ok) << there.message;
  EXPECT_EQ(there.steps, here.steps);
  EXPECT_EQ(there.stepMs.size(), here.stepMs.size());
  EXPECT_EQ(there.finalSurface, here.finalSurface);
  ASSERT_EQ(there.compared.size(), here.compared.size());
  for (size_t i = 0; i < here.compared.size(); ++i)
    EXPECT_EQ(there.compared[i].positions, here.compared[i].positions);
  EXPECT_EQ(there.graspResidual, here.graspResidual);
  EXPECT_EQ(there.valid, here.valid);
  EXPECT_EQ(there.counts, here.counts);
  EXPECT_EQ(there.notes, here.notes);
  EXPECT_EQ(there.params, here.params);

  // And the bytes round trip: a record read back writes the same bytes.
  EXPECT_EQ(serializeRunRecord(deserializeRunRecord(serializeRunRecord(here))),
            serializeRunRecord(here));
  std::vector<char> cut = serializeRunRecord(here);
  cut.resize(cut.size() / 2);
  EXPECT_THROW(deserializeRunRecord(cut), std::runtime_error);
}

TEST(RunIsolation, ASegfaultInInitOrStepIsThatRunsFailedRow) {
  SKIP_UNDER_ASAN();
  PluginLoader loader({DEFORM_CRASHING_PLUGIN_DIR});
  const ModelInfo& info = loader.load("segv");
  const LiftScene f;
  Cache cache{fs::path()};
  for (const char* at : {"init", "step"}) {
    const ParamValues params = resolveParams(info.params, {{"at", at}}, "test", "/params");
    const RunRecord r = runModelIsolated(info, params, f.scene, f.organ, cache);
    EXPECT_EQ(r.status, RunStatus::Failed) << at;
    EXPECT_NE(r.message.find("SIGSEGV"), std::string::npos) << r.message;
    EXPECT_FALSE(r.valid) << at;
  }
}

TEST(RunIsolation, APluginThatCrashesWhileRegisteringIsAPluginErrorNamingTheSignal) {
  SKIP_UNDER_ASAN();
  PluginLoader loader({DEFORM_CRASHING_PLUGIN_DIR});
  try {
    loader.load("segv_register");
    FAIL() << "loaded";
  } catch (const PluginError& e) {
    EXPECT_NE(std::string(e.what()).find("SIGSEGV"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("deform_segv_register.so"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(loader.loadedFiles().empty());
  EXPECT_NO_THROW(loader.load("segv")) << "the other plugin of the folder loads";
}

TEST(RunIsolation, LongRunsReportTheirStepsAsTheyGo) {
  LiftScene f;
  f.scene.dt = 1e-4;  // 10000 steps
  Cache cache{fs::path()};
  const ModelInfo info = rigidInfo();
  RunOptions o;
  std::vector<int> seen;
  o.onStep = [&](int done, int total) {
    EXPECT_EQ(total, 10000);
    seen.push_back(done);
  };
  runModel(info, ParamValues::defaults(info.params), f.scene, f.organ, cache, o);
  EXPECT_EQ(seen, (std::vector<int>{4096, 8192}));
}

TEST(Dispatch, RetryFailedRunsAFailedChildTaskAgain) {
  const fs::path dir = fs::temp_directory_path() / ("retry_failed_" + std::to_string(::getpid()));
  fs::create_directories(dir);
  const nlohmann::ordered_json argv = {"deformbench", "run"};
  const auto outcome = [&](int waitStatus) {
    std::ofstream(dir / "outcome.json") << nlohmann::ordered_json{
        {"argv", argv},
        {"wait_status", waitStatus},
        {"timed_out", false},
        {"spawn_error", ""},
        {"wall_s", 1.0}}.dump();
  };
  nlohmann::ordered_json task = {{"kind", "child"},
                                 {"argv", argv},
                                 {"resume", true},
                                 {"outcome", (dir / "outcome.json").string()}};
  outcome(11);  // killed by SIGSEGV
  EXPECT_FALSE(resumedTaskResult(task).is_null()) << "--resume alone keeps the failed case";
  task["retry_failed"] = true;
  EXPECT_TRUE(resumedTaskResult(task).is_null()) << "--retry-failed runs it again";
  outcome(0);
  EXPECT_FALSE(resumedTaskResult(task).is_null()) << "a finished case stays";
  fs::remove_all(dir);
}

}  // namespace
}  // namespace deform::harness
