// Google Benchmark: one PBD step on a liver-sized closed surface (~2.2k vertices, ~6.6k edges),
// 10 iterations, under gravity with the bottom pinned. Variants: stretch + volume (the metaballs
// paper's PBD baseline), + isometric bending (the default bending model), + dihedral bending,
// classic stiffness; the default (float32) solver and,
// for the first two, the double-precision one.
#include "held_top.h"
#include "pbd_model.h"

#include <benchmark/benchmark.h>

#include <map>
#include <string>

namespace {

using namespace deform;

void runPbd(benchmark::State& state, pbd::PbdConfig cfg) {
  pbd::PbdModel m;
  bench::timeLiverHeldTop(state, m, cfg, 1e-3, 1e-6);  // and where a step goes (<phase>_ms)
  const Counts c = m.counts();
  state.counters["nodes"] = static_cast<double>(c.at("nodes"));
  state.counters["constraints"] = static_cast<double>(c.at("constraints"));
}

// The default configuration with or without bending and the volume constraint.
pbd::PbdConfig variant(bool bending, bool volume) {
  pbd::PbdConfig c;
  c.bending = bending;
  c.volume = volume;
  return c;
}

pbd::PbdConfig withPrecision(pbd::PbdConfig c, pbd::Precision p) {
  c.precision = p;
  return c;
}

void BM_PbdStretchVolume(benchmark::State& s) {
  runPbd(s, variant(false, true));
}
void BM_PbdStretchVolumeBending(benchmark::State& s) {
  runPbd(s, variant(true, true));
}
void BM_PbdStretchVolumeDihedralBending(benchmark::State& s) {
  pbd::PbdConfig c = variant(true, true);
  c.bendingModel = pbd::BendingModel::Dihedral;
  runPbd(s, c);
}
void BM_PbdStretchOnly(benchmark::State& s) {
  runPbd(s, variant(false, false));
}
// The same two configurations with the double-precision solver (precision = float64).
void BM_PbdStretchOnlyF64(benchmark::State& s) {
  runPbd(s, withPrecision(variant(false, false), pbd::Precision::Float64));
}
void BM_PbdStretchVolumeF64(benchmark::State& s) {
  runPbd(s, withPrecision(variant(false, true), pbd::Precision::Float64));
}
void BM_PbdClassicStretchVolume(benchmark::State& s) {
  pbd::PbdConfig c = variant(false, true);
  c.mode = pbd::StiffnessMode::Classic;
  runPbd(s, c);
}

BENCHMARK(BM_PbdStretchOnly)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_PbdStretchVolume)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_PbdStretchOnlyF64)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_PbdStretchVolumeF64)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_PbdClassicStretchVolume)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_PbdStretchVolumeBending)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_PbdStretchVolumeDihedralBending)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
