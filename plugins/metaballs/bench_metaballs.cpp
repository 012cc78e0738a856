// Google Benchmark of the metaballs model on the liver phantom (~8.1k surface vertices, ~580
// spheres): one step (PBD + Laplacian + volume + skinning) while a grasp drags the organ (with the
// AVX-512 kernels and with the scalar path), and the
// whole offline construction. Targets: step median <= 0.5 ms (paper: 7.5 ms), construction
// <= 10 s (paper: 2207 s).
#include "metaballs_model.h"

#include <benchmark/benchmark.h>
#include <deform/phantom.h>

#include <algorithm>
#include <filesystem>

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
  const MatX3 x0 = model.nodes();
  Eigen::Index top = 0;
  x0.col(2).maxCoeff(&top);
  StepInput in;
  in.dt = 1e-3;
  in.gravity = Vec3(0, 0, -9.81);
  GraspInput g;
  g.nodes = {int(top)};
  g.targets = x0.row(top);
  in.grasps = {g};
  model.setSimd(state.range(0) != 0);
  long long i = 0;
  MetaballsModel::Phases sum;
  for (auto _ : state) {
    in.grasps[0].targets(0, 2) = x0(top, 2) + 0.02 * std::min(1.0, double(i++) / 1000.0);
    benchmark::DoNotOptimize(model.step(in));
    const MetaballsModel::Phases& p = model.lastPhases();
    sum.pbd += p.pbd;
    sum.laplacian += p.laplacian;
    sum.volume += p.volume;
    sum.rotations += p.rotations;
    sum.skinning += p.skinning;
  }
  const Counts c = model.counts();
  state.counters["spheres"] = double(c.at("spheres"));
  state.counters["links"] = double(c.at("links"));
  state.counters["vertices"] = double(organ.surface.numVertices());
  // Mean phase times (wall) over the iterations.
  const double n = double(std::max<long long>(i, 1));
  state.counters["pbd_ms"] = sum.pbd / n;
  state.counters["laplacian_ms"] = sum.laplacian / n;
  state.counters["volume_ms"] = sum.volume / n;
  state.counters["rotations_ms"] = sum.rotations / n;
  state.counters["skinning_ms"] = sum.skinning / n;
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
