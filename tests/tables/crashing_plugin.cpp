// Test-only plugin for the stability sweep: a model that crashes (SIGSEGV raised at its second
// step), hangs, or runs, so the sweep's child-process isolation can be tested. Never installed.
#include <deform/sdk/registry.h>

#include <csignal>
#include <thread>

#include "../plugin_fixtures/toy_model.h"

namespace {

using namespace deform;

class CrashingModel final : public fixture::StillModel {
 public:
  void init(const ModelSetup& setup) override {
    m_mode = setup.params.choice("mode");
    StillModel::init(setup);
  }
  StepStatus step(const StepInput&) override {
    if (++m_steps == 2) {
      if (m_mode == "segv") std::raise(SIGSEGV);
      if (m_mode == "hang")
        for (;;) std::this_thread::sleep_for(std::chrono::seconds(1));
    }
    return StepStatus::Ok;
  }
  void reset() override {
    StillModel::reset();
    m_steps = 0;
  }

 private:
  std::string m_mode;
  int m_steps = 0;
};

}  // namespace

DEFORM_PLUGIN(registry) {
  ModelInfo info;
  info.name = "crashy";
  info.description = "test fixture: raises SIGSEGV (or hangs) at its second step";
  info.citation = "none (test fixture)";
  info.version = "0";
  info.capabilities = {Capability::Grasp, Capability::PointForce, Capability::Gravity};
  info.params = {ParamSpec::choice("mode", "segv", {"segv", "hang", "ok"}, "what step 2 does")};
  info.create = [] { return std::make_unique<CrashingModel>(); };
  registry.add(std::move(info));
}
