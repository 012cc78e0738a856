// fem_hex speed: time per implicit step on a liver-sized organ (grasp lifting the top, gravity,
// lower part pinned), by element count, formulation and solver. Each benchmark iteration is one
// step; the counters report the median step time (the results' headline) and per-phase
// means.
//
//   bench_fem_hex --benchmark_filter=Liver967
//   bench_fem_hex --benchmark_filter=Scaling
#include "hex_fem_model.h"

#include <deform/geometry/phantom.h>
#include <deform/sdk/model.h>

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <ctime>

namespace {

using namespace deform;
using namespace deform::fem_hex;

/// CPU time of this thread, µs (the machine is shared: wall time alone overstates a step's cost
/// when other processes take the core).
double threadCpuMicros() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return 1e6 * static_cast<double>(ts.tv_sec) + 1e-3 * static_cast<double>(ts.tv_nsec);
}

class BenchModel final : public HexFemModel {
 public:
  void init(const ModelSetup&) override {}
};

void runSteps(benchmark::State& state, long long elements, ElasticModel elastic,
              CorotationalSolver solver, CholeskySolver::Kind kind, bool allOrderings = true,
              Real tolerance = 1e-3, bool graspedPreconditioner = false) {
  Organ organ;
  organ.source = "phantom:liver";
  organ.surface = makePhantom("liver");
  HexFemConfig c;
  c.elements = elements;
  c.elastic = elastic;
  c.solver = solver;
  c.rayleighMass = 0.1;
  c.rayleighStiffness = 0.01;
  c.cholesky = kind;
  c.tryAllOrderings = allOrderings;
  c.pcgTolerance = tolerance;
  c.pcgPreconditioner =
      graspedPreconditioner ? PcgPreconditioner::RestGrasped : PcgPreconditioner::Rest;
  BenchModel m;
  m.initialize(organ, c, 1e-3, [](const MatX3& nodes) {
    std::vector<int> f;
    for (int n = 0; n < nodes.rows(); ++n)
      if (nodes(n, 2) < -0.03) f.push_back(n);
    return f;
  });
  GraspInput grasp;
  grasp.vertices = graspedSurfaceVertices(organ.surface, Vec3(0, 0, 0.045), 0.015);
  MatX3 rest(grasp.vertices.size(), 3);
  for (size_t k = 0; k < grasp.vertices.size(); ++k)
    rest.row(Eigen::Index(k)) = m.surface().row(grasp.vertices[k]);
  grasp.targets = rest;
  StepInput in;
  in.dt = 1e-3;
  in.gravity = Vec3(0, 0, -9.81);
  in.grasps = {grasp};
  m.step(in);  // the grasp closes: any refactorisation it causes is not a per-step cost
  std::vector<double> times, cpuTimes;
  times.reserve(1 << 16);
  cpuTimes.reserve(1 << 16);
  double assembly = 0, solve = 0, surface = 0;
  long long iterations = 0, step = 0;
  for (auto _ : state) {
    // Triangle wave: lift 2 cm over 500 steps, then back.
    const int phase = static_cast<int>(step % 1000);
    const Real lift = 0.02 * (phase < 500 ? phase : 1000 - phase) / 500.0;
    in.grasps[0].targets.col(2) = rest.col(2).array() + lift;
    const double c0 = threadCpuMicros();
    const auto t0 = std::chrono::steady_clock::now();
    const StepStatus s = m.step(in);
    times.push_back(
        std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
    cpuTimes.push_back(threadCpuMicros() - c0);
    if (s != StepStatus::Ok) {
      state.SkipWithError("diverged");
      break;
    }
    const PhaseTimes p = m.phaseTimes();
    assembly += p.at("assembly");
    solve += p.at("solve");
    surface += p.at("surface");
    iterations += m.lastIterations();
    ++step;
  }
  if (times.empty()) return;
  std::sort(times.begin(), times.end());
  std::sort(cpuTimes.begin(), cpuTimes.end());
  const double median = times[times.size() / 2];
  const double n = static_cast<double>(step);
  state.counters["hexes"] = static_cast<double>(m.grid().numHexes());
  state.counters["nodes"] = static_cast<double>(m.grid().numNodes());
  state.counters["median_us"] = median;
  state.counters["median_cpu_us"] = cpuTimes[cpuTimes.size() / 2];
  state.counters["us_per_hex"] = median / m.grid().numHexes();
  state.counters["assembly_us"] = 1e3 * assembly / n;
  state.counters["solve_us"] = 1e3 * solve / n;
  state.counters["surface_us"] = 1e3 * surface / n;
  state.counters["L_nnz"] = static_cast<double>(m.counts().at("cholesky_factor_nonzeros"));
  state.counters["flops_per_L_nnz"] =
      static_cast<double>(m.counts().at("cholesky_flops_per_factor_nonzero"));
  state.counters["supernodal"] = static_cast<double>(m.counts().at("cholesky_supernodal"));
  state.counters["cg_iters"] = static_cast<double>(iterations) / n;
}

CholeskySolver::Kind kindOf(long long k) {
  return k == 0   ? CholeskySolver::Kind::Simplicial
         : k == 1 ? CholeskySolver::Kind::Supernodal
                  : CholeskySolver::Kind::Auto;
}

// cholesky: 0 simplicial, 1 supernodal, 2 auto.
void Liver967(benchmark::State& state) {
  const auto elastic = state.range(0) ? ElasticModel::Corotational : ElasticModel::Linear;
  const auto solver = state.range(1) ? CorotationalSolver::Refactor : CorotationalSolver::Pcg;
  runSteps(state, 967, elastic, solver, kindOf(state.range(2)));
}
BENCHMARK(Liver967)
    ->ArgNames({"corot", "refactor", "cholesky"})
    ->ArgsProduct({{1}, {0, 1}, {0, 1, 2}})
    ->ArgsProduct({{0}, {0}, {0, 1, 2}})
    ->Unit(benchmark::kMicrosecond)
    ->MinTime(2.0);

void Tuning(benchmark::State& state) {
  runSteps(state, 967, ElasticModel::Corotational, CorotationalSolver::Pcg, kindOf(state.range(0)),
           state.range(1) != 0, std::pow(10.0, -static_cast<double>(state.range(2))),
           state.range(3) != 0);
}
BENCHMARK(Tuning)
    ->ArgNames({"cholesky", "all_orderings", "neg_log10_tol", "grasp_prec"})
    ->ArgsProduct({{0, 1}, {0, 1}, {4}, {0}})
    ->ArgsProduct({{2}, {1}, {3, 4, 5, 6}, {0, 1}})
    ->Unit(benchmark::kMicrosecond)
    ->MinTime(2.0);

void Scaling(benchmark::State& state) {
  runSteps(state, state.range(0), ElasticModel::Corotational,
           state.range(1) ? CorotationalSolver::Refactor : CorotationalSolver::Pcg,
           kindOf(state.range(2)));
}
BENCHMARK(Scaling)
    ->ArgNames({"elements", "refactor", "cholesky"})
    ->ArgsProduct({{100, 300, 1000, 3000, 10000}, {0}, {2}})
    ->ArgsProduct({{100, 300, 1000, 3000}, {0}, {0, 1}})
    ->ArgsProduct({{100, 300, 1000, 3000}, {1}, {2}})
    ->Unit(benchmark::kMicrosecond)
    ->MinTime(1.0);

}  // namespace

BENCHMARK_MAIN();
