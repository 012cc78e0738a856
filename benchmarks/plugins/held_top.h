// The step loop of the plugin benchmarks on the liver-sized organ held at its top
// (tests/support/organs.h): 20 warm-up steps, then one timed step per iteration with the grasp
// raised by `rise` (m) each time (the realistic case: kinematic nodes), and the model's mean
// wall time per phase as the counters <phase>_ms.
#pragma once

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

}  // namespace deform::bench
