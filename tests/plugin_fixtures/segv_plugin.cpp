// Fixture: a model that dies of SIGSEGV in init() or at its first step() (parameter "at"), for
// the run isolation tests: its run must become a failed row and the other models' results must
// be written.
#include <deform/sdk/registry.h>

#include <csignal>

#include "toy_model.h"

namespace {

using namespace deform;

class SegvModel final : public fixture::StillModel {
 public:
  void init(const ModelSetup& setup) override {
    m_at = setup.params.choice("at");
    if (m_at == "init") std::raise(SIGSEGV);
    StillModel::init(setup);
  }
  StepStatus step(const StepInput&) override {
    if (m_at == "step") std::raise(SIGSEGV);
    return StepStatus::Ok;
  }

 private:
  std::string m_at;
};

}  // namespace

DEFORM_PLUGIN(registry) {
  ModelInfo info = fixture::toyInfo("segv");
  info.description = "test fixture: raises SIGSEGV in init() or at its first step()";
  info.params = {ParamSpec::choice("at", "init", {"init", "step"}, "where it crashes")};
  info.create = [] { return std::make_unique<SegvModel>(); };
  registry.add(std::move(info));
}
