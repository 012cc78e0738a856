// The step loop of the plugin benchmarks on the liver-sized organ held at its top
// (tests/support/organs.h): 20 warm-up steps, then one timed step per iteration with the grasp
// raised by `rise` (m) each time (the realistic case: kinematic nodes), and the model's mean
// wall time per phase as the counters <phase>_ms.
#pragma once

#include "support/organs.h"

#include <deform/sdk/model.h>

#include <benchmark/benchmark.h>

#include <map>
#include <string>

namespace deform::bench {

inline void timeHeldTopSteps(benchmark::State& state, Model& m, StepInput& in, Real rise) {
  for (int s = 0; s < 20; ++s) m.step(in);  // warm-up
  std::map<std::string, double> phaseSum;
  for (auto _ : state) {
    in.grasps[0].targets.col(2).array() += rise;
    benchmark::DoNotOptimize(m.step(in));
    for (const auto& [name, ms] : m.phaseTimes()) phaseSum[name] += ms;
  }
  for (const auto& [name, ms] : phaseSum)
    state.counters[name + "_ms"] = ms / static_cast<double>(state.iterations());
}

/// m initialised by its init(organ, config) on the liver-sized organ, held at its top and
/// stepped by dt (testing::heldTopInput), then timed by timeHeldTopSteps.
template <class NodeModel, class Config>
void timeLiverHeldTop(benchmark::State& state, NodeModel& m, const Config& config, Real dt,
                      Real rise) {
  const Organ o = testing::liverSizedOrgan();
  m.init(o, config);
  StepInput in = testing::heldTopInput(o, dt);
  timeHeldTopSteps(state, m, in, rise);
}

}  // namespace deform::bench
