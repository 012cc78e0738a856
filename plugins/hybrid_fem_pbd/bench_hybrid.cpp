// Google Benchmark of the hybrid FEM+PBD model on the liver phantom with a ~2k-vertex fine
// surface (makePhantom("liver", 0.25)): per-step time under a constant 2 N point load, and the
// hybrid mesh construction (vertex-cover simplification + Gmsh tetrahedralisation) time.
// BM_HybridStep/<iterations>/<projection>: projection 0 = Reference (the shared scalar kernels
// one by one, the implementation before batching), 1 = BatchedScalar, 2 = Batched (AVX2), so
// one run measures before and after side by side.
#include <benchmark/benchmark.h>
#include <deform/phantom.h>

#include <chrono>

#include "hybrid_model.h"

namespace {

using namespace deform;

Organ liverOrgan() {
  Organ o;
  o.source = "phantom:liver";
  o.surface = makePhantom("liver", 0.25);
  o.material = Material{5500, 0.3, 1000};
  const Box b = boundingBox(o.surface.V);
  Box fixed;
  fixed.lo = b.lo - Vec3::Constant(0.01);
  fixed.hi = Vec3(b.hi.x() + 0.01, b.hi.y() + 0.01, b.lo.z() + 0.15 * b.size().z());
  o.fixed.boxes.push_back(fixed);
  return o;
}

void BM_HybridConstruction(benchmark::State& state) {
  const Organ organ = liverOrgan();
  for (auto _ : state) {
    hybrid::HybridModel m;
    m.init(organ, hybrid::HybridConfig(), nullptr);  // no cache: the full construction
    benchmark::DoNotOptimize(m.surface().data());
    state.counters["fine_vertices"] = double(m.counts().at("nodes"));
    state.counters["coarse_vertices"] = double(m.counts().at("coarse_vertices"));
    state.counters["tets"] = double(m.counts().at("tets"));
    state.counters["constraints"] = double(m.counts().at("constraints"));
  }
}
BENCHMARK(BM_HybridConstruction)->Unit(benchmark::kMillisecond)->Iterations(3);

void BM_HybridStep(benchmark::State& state) {
  const Organ organ = liverOrgan();
  hybrid::HybridModel m;
  hybrid::HybridConfig cfg;
  cfg.iterations = static_cast<int>(state.range(0));
  cfg.projection = static_cast<hybrid::SurfaceProjection>(state.range(1));
  m.init(organ, cfg, nullptr);
  const Box b = boundingBox(organ.surface.V);
  StepInput in;
  in.dt = 1e-3;
  in.loads.push_back(PointLoad::onVertex(
      nearestVertex(organ.surface.V, Vec3(b.center().x(), b.center().y(), b.hi.z())),
      Vec3(0, 0, -2.0)));
  for (int i = 0; i < 50; ++i) m.step(in);  // warm-up (caches the load's K^-1 columns)
  double fem = 0, pbd = 0, load = 0;
  for (auto _ : state) {
    m.step(in);
    const PhaseTimes p = m.phaseTimes();
    fem += p.at("fem");
    pbd += p.at("pbd");
    load += p.at("load");
  }
  const double n = double(state.iterations());
  state.counters["fem_ms"] = fem / n;
  state.counters["pbd_ms"] = pbd / n;
  state.counters["load_ms"] = load / n;
  state.counters["fine_vertices"] = double(m.counts().at("nodes"));
  state.counters["active_stretch"] = double(m.batches().sa.size());
  state.counters["active_bending"] = double(m.batches().hCos0.size());
  state.counters["colours"] =
      double(m.batches().sColourStart.size() + m.batches().hColourStart.size() - 2);
}
BENCHMARK(BM_HybridStep)
    ->ArgNames({"iterations", "projection"})
    ->Args({10, 0})
    ->Args({10, 1})
    ->Args({10, 2})
    ->Args({5, 2})
    ->Args({2, 2})
    ->Args({1, 2})
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(5)
    ->ReportAggregatesOnly(true);

}  // namespace

BENCHMARK_MAIN();
