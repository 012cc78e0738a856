// Google Benchmark of the metaballs model on the liver phantom (~8.1k surface vertices, ~580
// spheres): one step (PBD + Laplacian + volume + skinning) while a grasp drags the organ (with the
// AVX-512 kernels and with the scalar path), and the
// whole offline construction. Targets: step median <= 0.5 ms (paper: 7.5 ms), construction
// <= 10 s (paper: 2207 s).
#include "metaballs_model.h"

#include <benchmark/benchmark.h>
#include <deform/geometry/phantom.h>

#include <algorithm>
#include <filesystem>
#include <vector>

namespace deform {}  // namespace deform

namespace {
using namespace deform;
using namespace deform::metaballs;

const SurfaceMesh& liver() {
  static const SurfaceMesh m = makePhantom("liver");
  return m;
}

void BM_MetaballsStep(benchmark::State& state) {
  Organ organ;
  organ.source = "phantom:liver";
  organ.surface = liver();
  const ParamValues params = ParamValues::defaults(metaballsParams());
  Cache cache(Cache::defaultDir());
  MetaballsModel model;
  model.init(ModelSetup{organ, params, cache, 1e-3, Vec3(0, 0, -9.81)});
  const MatX3 x0 = model.surface();
  Eigen::Index top = 0;
  x0.col(2).maxCoeff(&top);
  StepInput in;
  in.dt = 1e-3;
  in.gravity = Vec3(0, 0, -9.81);
  GraspInput g;
  g.vertices = {int(top)};
  g.targets = x0.row(top);
  in.grasps = {g};
  model.setSimd(state.range(0) != 0);
  long long i = 0;
  std::vector<MetaballsModel::Phases> phases;
  phases.reserve(1 << 16);
  for (auto _ : state) {
    in.grasps[0].targets(0, 2) = x0(top, 2) + 0.02 * std::min(1.0, double(i++) / 1000.0);
    benchmark::DoNotOptimize(model.step(in));
    if (phases.size() < phases.capacity()) phases.push_back(model.lastPhases());
  }
  const Counts c = model.counts();
  state.counters["spheres"] = double(c.at("spheres"));
  state.counters["links"] = double(c.at("links"));
  state.counters["vertices"] = double(organ.surface.numVertices());
  // Median phase times (wall) over the steps: robust to the preemptions of a loaded machine.
  auto median = [&](double MetaballsModel::Phases::*f) {
    std::vector<double> v;
    for (const auto& p : phases) v.push_back(p.*f);
    if (v.empty()) return 0.0;
    std::nth_element(v.begin(), v.begin() + long(v.size() / 2), v.end());
    return v[v.size() / 2];
  };
  state.counters["pbd_ms"] = median(&MetaballsModel::Phases::pbd);
  state.counters["laplacian_ms"] = median(&MetaballsModel::Phases::laplacian);
  state.counters["volume_ms"] = median(&MetaballsModel::Phases::volume);
  state.counters["rotations_ms"] = median(&MetaballsModel::Phases::rotations);
  state.counters["skinning_ms"] = median(&MetaballsModel::Phases::skinning);
}
// Argument: 1 = AVX-512 kernels where the CPU has them, 0 = scalar path (same results).
BENCHMARK(BM_MetaballsStep)
    ->Arg(1)
    ->Arg(0)
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(5)
    ->ReportAggregatesOnly(true);

void BM_MetaballsConstruction(benchmark::State& state) {
  ConstructionParams p = constructionParams(ParamValues::defaults(metaballsParams()));
  Metaballs mb;
  for (auto _ : state) {
    mb = constructMetaballs(liver(), p);
    benchmark::DoNotOptimize(mb.spheres.radii.data());
  }
  state.counters["spheres"] = mb.report.spheres;
  state.counters["links"] = mb.report.links;
  state.counters["hollow_before"] = double(mb.report.hollowBefore);
  state.counters["hollow_after"] = double(mb.report.hollowAfter);
}
BENCHMARK(BM_MetaballsConstruction)
    ->Unit(benchmark::kSecond)
    ->Iterations(1)
    ->Repetitions(3)
    ->ReportAggregatesOnly(true);
}  // namespace

BENCHMARK_MAIN();
