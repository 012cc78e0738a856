// Self-intersection test speed (findSelfIntersections, mesh_check.h): the liver phantom at the
// default resolution (8122 vertices) and the cube phantom, and eval-data's Liver.stl (30726
// triangles) and liver-smooth.obj when ../shared/eval-data is present.
#include <benchmark/benchmark.h>
#include <deform/geometry/mesh_check.h>
#include <deform/geometry/mesh_io.h>
#include <deform/geometry/phantom.h>

#include <filesystem>

namespace deform {
namespace {

void run(benchmark::State& state, const SurfaceMesh& m) {
  long long pairs = 0, candidates = 0;
  for (auto _ : state) {
    const SelfIntersectionReport r = findSelfIntersections(m);
    pairs = r.pairs;
    candidates = r.candidates;
    benchmark::DoNotOptimize(pairs);
  }
  state.counters["triangles"] = double(m.numFaces());
  state.counters["candidates"] = double(candidates);
  state.counters["pairs"] = double(pairs);
}

void BM_Phantom(benchmark::State& state, const char* name) {
  run(state, makePhantom(name));
}
BENCHMARK_CAPTURE(BM_Phantom, liver, "liver")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_Phantom, cube, "cube")->Unit(benchmark::kMillisecond);

void BM_EvalData(benchmark::State& state, const char* name) {
  const std::string file =
      (std::filesystem::path(__FILE__).parent_path() / "../../shared/eval-data" / name).string();
  if (!std::filesystem::exists(file)) {
    state.SkipWithError("eval data not available");
    return;
  }
  run(state, readMesh(file).surface);
}
BENCHMARK_CAPTURE(BM_EvalData, Liver_stl, "Liver.stl")->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(BM_EvalData, liver_smooth_obj, "liver-smooth.obj")->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace deform

BENCHMARK_MAIN();
