// Time to build each built-in phantom at resolution 1 (target: liver well under 100 ms).
#include <benchmark/benchmark.h>
#include <deform/geometry/phantom.h>

namespace {

void BM_MakePhantom(benchmark::State& state, const char* name) {
  int vertices = 0;
  for (auto _ : state) {
    const deform::SurfaceMesh m = deform::makePhantom(name, 1.0);
    vertices = m.numVertices();
    benchmark::DoNotOptimize(m.V.data());
  }
  state.counters["vertices"] = vertices;
}

BENCHMARK_CAPTURE(BM_MakePhantom, liver, "liver")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_MakePhantom, gallbladder, "gallbladder")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_MakePhantom, stomach, "stomach")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_MakePhantom, intestine, "intestine")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_MakePhantom, cube, "cube")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_MakePhantom, sphere, "sphere")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_MakePhantom, steak, "steak")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_MakePhantom, beam, "beam")->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
