// Google Benchmark for particle_bem: the guided model's step on the liver phantom (284 and 1144
// coarse vertices = surface particles), the precomputation of M, and the pure particle step.
// Run: bench_particle_bem --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include "bem_assembly.h"
#include "particle_bem_model.h"
#include "surface_decimation.h"

#include <benchmark/benchmark.h>
#include <deform/geometry/phantom.h>
#include <deform/geometry/pressure_patch.h>
#include <deform/sdk/model.h>

#include <map>
#include <memory>
#include <string>
#include <tuple>

namespace {

using namespace deform;
using namespace deform::particle_bem;

Organ liver() {
  Organ organ;
  organ.source = "phantom:liver";
  organ.surface = makePhantom("liver");
  organ.material = Material{5500, 0.45, 1000};
  const Box b = boundingBox(organ.surface.V);
  Box f;
  f.lo = b.lo - Vec3::Constant(1);
  f.hi = b.hi + Vec3::Constant(1);
  f.hi[2] = b.lo[2] + 0.15 * b.size()[2];
  organ.fixed.boxes.push_back(f);
  return organ;
}

struct Setup {
  Organ organ = liver();
  ParamValues params = ParamValues::defaults(paramSpecs());
  Cache cache{Cache::defaultDir()};
  ParticleBemModel model;
  GraspInput grasp;
  MatX3 start;
  PointLoad load;
};

Setup& setup(int coarse, bool guided, const std::string& transfer, const std::string& patch) {
  static std::map<std::tuple<int, bool, std::string, std::string>, std::unique_ptr<Setup>> all;
  auto& s = all[{coarse, guided, transfer, patch}];
  if (s) return *s;
  s = std::make_unique<Setup>();
  s->params.set("surface_transfer", transfer);
  s->params.set("patch_traction", patch);
  s->params.set("coarse_vertices", (long long)coarse);
  s->params.set("guidance", guided);
  s->params.set("points", (long long)(guided ? 300 : coarse));
  s->model.init(ModelSetup{s->organ, s->params, s->cache, 1e-3, Vec3(0, 0, -9.81)});
  // As the harness defines them: a grasp of the surface vertices within 1 cm of the top, a 0.5 N
  // force 3 cm beside it spread over the default 1 cm pressure patch.
  const SurfaceMesh& S = s->organ.surface;
  Eigen::Index top = 0;
  S.V.col(2).maxCoeff(&top);
  const Vec3 p = S.V.row(top).transpose();
  s->grasp.vertices = graspedSurfaceVertices(S, p, 0.01);
  s->start.resize(Eigen::Index(s->grasp.vertices.size()), 3);
  for (size_t a = 0; a < s->grasp.vertices.size(); ++a)
    s->start.row(Eigen::Index(a)) = S.V.row(s->grasp.vertices[a]);
  s->load.surfaceVertex = nearestVertex(S.V, p + Vec3(0.03, 0, 0));
  s->load.force = Vec3(0, 0, -0.5);
  const SurfacePatch spread = pressurePatch(S, s->load.surfaceVertex, 0.01);
  s->load.vertices = spread.vertices;
  s->load.weights = spread.weights;
  return *s;
}

void stepBenchmark(benchmark::State& state, bool guided, const std::string& transfer = "gradient",
                   const std::string& patch = "consistent") {
  Setup& s = setup(int(state.range(0)), guided, transfer, patch);
  s.model.reset();
  int step = 0;
  std::map<std::string, double> phases;
  for (auto _ : state) {
    StepInput in;
    in.time = step * 1e-3;
    in.dt = 1e-3;
    in.gravity = Vec3(0, 0, -9.81);
    GraspInput g = s.grasp;
    g.targets = s.start.rowwise() + Vec3(0, 0, 1e-5 * (step % 1000)).transpose();
    in.grasps.push_back(std::move(g));
    in.loads.push_back(s.load);
    benchmark::DoNotOptimize(s.model.step(in));
    for (const auto& [k, v] : s.model.phaseTimes()) phases[k] += v;
    ++step;
  }
  for (const auto& [k, v] : phases) state.counters[k + "_ms"] = v / std::max(1, step);
  const Counts c = s.model.counts();
  state.counters["particles"] = double(c.at("particles"));
  if (guided) state.counters["M_MB"] = double(c.at("deformation_matrix_bytes")) / 1e6;
  state.counters["grasped"] = double(s.grasp.vertices.size());
}

void BM_GuidedStep(benchmark::State& state) {
  stepBenchmark(state, true);
}
BENCHMARK(BM_GuidedStep)->Arg(284)->Arg(1144)->Unit(benchmark::kMillisecond);

// The same with the lumped load tractions (patch_traction = lumped, the first version).
void BM_GuidedStepLumpedPatch(benchmark::State& state) {
  stepBenchmark(state, true, "gradient", "lumped");
}
BENCHMARK(BM_GuidedStepLumpedPatch)->Arg(284)->Arg(1144)->Unit(benchmark::kMillisecond);

// The same with the linear coarse -> fine transfer (surface_transfer = linear).
void BM_GuidedStepLinearTransfer(benchmark::State& state) {
  stepBenchmark(state, true, "linear");
}
BENCHMARK(BM_GuidedStepLinearTransfer)->Arg(284)->Arg(1144)->Unit(benchmark::kMillisecond);

void BM_ParticleStep(benchmark::State& state) {
  stepBenchmark(state, false);
}
BENCHMARK(BM_ParticleStep)->Arg(300)->Arg(1000)->Unit(benchmark::kMillisecond);

// Precomputation of M for a coarse liver surface (assembly + mixed LU + M), no cache.
void BM_Precompute(benchmark::State& state) {
  const Organ organ = liver();
  const SurfaceMesh coarse = decimateQuadric(organ.surface, int(state.range(0)));
  std::vector<int> fixed;
  for (int i = 0; i < coarse.numVertices(); ++i)
    if (organ.fixed.boxes[0].contains(coarse.V.row(i).transpose())) fixed.push_back(i);
  size_t bytes = 0;
  for (auto _ : state) {
    DeformationMatrix dm =
        computeDeformationMatrix(assembleBem(coarse, 5500, 0.45), coarse,
                                 vertexNormals(coarse.V, coarse.F), fixed, 5500, 0.45, 1000);
    bytes = dm.bytes();
    benchmark::DoNotOptimize(dm.M.data());
  }
  state.counters["M_MB"] = double(bytes) / 1e6;
  state.counters["coarse_vertices"] = coarse.numVertices();
}
BENCHMARK(BM_Precompute)->Arg(1144)->Iterations(1)->Unit(benchmark::kSecond);

}  // namespace

BENCHMARK_MAIN();
