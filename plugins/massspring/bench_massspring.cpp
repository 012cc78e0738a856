// Google Benchmark: one mass-spring step on a liver-sized closed surface (~2.2k nodes, ~6.6k edge
// springs, as in the metaballs paper's Table 2 row with 6427 springs), under gravity with a grasp.
#include "massspring_model.h"
#include "support/meshes.h"

#include <benchmark/benchmark.h>

namespace {

using namespace deform;

void runMassSpring(benchmark::State& state, massspring::MassSpringConfig cfg) {
  Organ o;
  o.source = "bench:liver-sized ellipsoid";
  o.surface = testing::liverSizedSurface();
  massspring::MassSpringModel m;
  m.init(o, cfg);
  StepInput in;
  in.dt = 1e-4;
  in.gravity = Vec3(0, 0, -9.81);
  GraspInput g;
  g.vertices = nearestVertices(o.surface.V, Vec3(0, 0, 0.04), 5);
  g.targets.resize(static_cast<Eigen::Index>(g.vertices.size()), 3);
  for (size_t k = 0; k < g.vertices.size(); ++k) g.targets.row(k) = o.surface.V.row(g.vertices[k]);
  in.grasps.push_back(g);
  for (int s = 0; s < 20; ++s) m.step(in);
  for (auto _ : state) {
    in.grasps[0].targets.col(2).array() += 1e-7;
    benchmark::DoNotOptimize(m.step(in));
  }
  state.counters["springs"] = static_cast<double>(m.counts().at("springs"));
}

void BM_MassSpringExplicitEdgesOnly(benchmark::State& s) {
  massspring::MassSpringConfig c;
  c.integrator = massspring::Integrator::ExplicitEuler;
  c.bendingRatio = 0.0;
  runMassSpring(s, c);
}
void BM_MassSpringExplicitWithBending(benchmark::State& s) {
  massspring::MassSpringConfig c;
  c.integrator = massspring::Integrator::ExplicitEuler;
  runMassSpring(s, c);
}
void BM_MassSpringSymplecticWithBending(benchmark::State& s) {
  runMassSpring(s, massspring::MassSpringConfig{});
}
void BM_MassSpringImplicitWithBending(benchmark::State& s) {
  massspring::MassSpringConfig c;
  c.integrator = massspring::Integrator::ImplicitEuler;
  runMassSpring(s, c);
}

BENCHMARK(BM_MassSpringExplicitEdgesOnly)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_MassSpringExplicitWithBending)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_MassSpringSymplecticWithBending)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_MassSpringImplicitWithBending)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
