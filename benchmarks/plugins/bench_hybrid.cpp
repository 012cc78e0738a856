// Google Benchmark of the hybrid FEM+PBD model on the liver phantom with a ~2k-vertex fine
// surface (makePhantom("liver", 0.25)): per-step time under a constant 2 N point load, and the
// hybrid mesh construction (vertex-cover simplification + Gmsh tetrahedralisation) time.
// BM_HybridStep/<iterations>/<projection>/<precision>: projection 0 = Reference (the shared
// scalar kernels one by one, the implementation before batching), 1 = BatchedScalar, 2 = Batched
// (AVX2); precision 0 = float32 (default), 1 = float64, so one run measures before and after side
// by side. The kernels alone, on the default liver phantom (8,122 vertices, the bench scene's
// organ): BM_SurfaceSweeps/<float64>/<simd>/<skip> (10 sweeps of stretch + isometric bending;
// skip: the hinges' immovable slots are not updated, as in the model) and
// BM_GraspResponse/<kind> (Z lambda at the liver's control dofs: 0 = double Eigen product, the
// implementation before, 1 = float blocked scalar, 2 = float blocked AVX2).
#include <benchmark/benchmark.h>
#include <deform/geometry/phantom.h>

#include <chrono>
#include <random>

#include "hybrid_model.h"
#include "response_product.h"
#include "support/organs.h"

namespace {

using namespace deform;

Organ liverOrgan() {
  return testing::phantomWithFixedBottom("liver", 0.25, 0.15);
}

void BM_HybridConstruction(benchmark::State& state) {
  const Organ organ = liverOrgan();
  for (auto _ : state) {
    hybrid_fem_pbd::HybridModel m;
    m.init(organ, hybrid_fem_pbd::HybridConfig(), nullptr);  // no cache: the full construction
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
  hybrid_fem_pbd::HybridModel m;
  hybrid_fem_pbd::HybridConfig cfg;
  cfg.iterations = static_cast<int>(state.range(0));
  cfg.projection = static_cast<hybrid_fem_pbd::SurfaceProjection>(state.range(1));
  cfg.precision = static_cast<hybrid_fem_pbd::HybridPrecision>(state.range(2));
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
    ->ArgNames({"iterations", "projection", "precision"})
    ->Args({10, 0, 1})
    ->Args({10, 1, 1})
    ->Args({10, 2, 1})
    ->Args({10, 1, 0})
    ->Args({10, 2, 0})
    ->Args({5, 2, 0})
    ->Args({2, 2, 0})
    ->Args({1, 2, 0})
    ->Unit(benchmark::kMillisecond)
    ->Repetitions(5)
    ->ReportAggregatesOnly(true);

// The surface of the default liver phantom with two vertices in three immovable (about the share
// of control nodes on the liver: 5,460 of 8,122), displaced at random by a third of the mean edge:
// 10 sweeps of the default constraints (stretch + isometric bending) per iteration, from the same
// start each time.
struct SweepSetup {
  int n = 0;
  hybrid_fem_pbd::SurfaceBatches batches;
  MatX3 start;
  Vec3 origin;
};

const SweepSetup& sweepSetup(bool simd, bool skipImmovable) {
  static SweepSetup s[4];
  SweepSetup& out = s[(simd ? 1 : 0) + (skipImmovable ? 2 : 0)];
  if (out.n > 0) return out;
  const SurfaceMesh mesh = makePhantom("liver");
  const hybrid_fem_pbd::SurfaceConstraints c =
      hybrid_fem_pbd::buildSurfaceConstraints(mesh.V, mesh.F);
  out.n = mesh.numVertices();
  VecX w(out.n);
  for (int i = 0; i < out.n; ++i) w[i] = (i % 3 == 0) ? 1.0 : 0.0;
  out.batches = hybrid_fem_pbd::buildSurfaceBatches(c, hybrid_fem_pbd::activeConstraints(c, w), w,
                                                    1.0, 0.5, 10);
  // Without the skipping (the isometric kernel before it could skip): every slot marked movable.
  if (!skipImmovable) out.batches.hMovable.assign(out.batches.hMovable.size(), 0xF);
  hybrid_fem_pbd::addIsometricBending(out.batches, mesh.V);
  out.origin = boundingBox(mesh.V).center();
  hybrid_fem_pbd::addSinglePrecision(out.batches, mesh.V, out.origin, simd);
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-1, 1);
  const Real h = 0.3 * std::sqrt(surfaceArea(mesh.V, mesh.F) / mesh.numFaces());
  out.start = mesh.V;
  for (int i = 0; i < out.n; ++i)
    for (int a = 0; a < 3; ++a) out.start(i, a) += h * u(rng);
  return out;
}

void BM_SurfaceSweeps(benchmark::State& state) {
  const bool f32 = state.range(0) == 0, simd = state.range(1) != 0;
  const SweepSetup& s = sweepSetup(simd, state.range(2) != 0);
  std::vector<double> x4d(4 * size_t(s.n), 0.0), start4d = x4d;
  std::vector<float> x4f(4 * size_t(s.n), 0.0f), start4f = x4f;
  for (int i = 0; i < s.n; ++i)
    for (int a = 0; a < 3; ++a) {
      start4d[4 * size_t(i) + a] = s.start(i, a);
      start4f[4 * size_t(i) + a] = static_cast<float>(s.start(i, a) - s.origin[a]);
    }
  for (auto _ : state) {
    if (f32) {
      x4f = start4f;
      benchmark::DoNotOptimize(
          hybrid_fem_pbd::projectSurfaceBatchesF(x4f.data(), s.batches, 10, simd));
    } else {
      x4d = start4d;
      benchmark::DoNotOptimize(
          hybrid_fem_pbd::projectSurfaceBatches(x4d.data(), s.batches, 10, simd));
    }
  }
  state.counters["stretch"] = double(s.batches.sa.size());
  state.counters["hinges"] = double(s.batches.hCos0.size());
}
BENCHMARK(BM_SurfaceSweeps)
    ->ArgNames({"float64", "simd", "skip"})
    ->Args({1, 0, 0})
    ->Args({1, 1, 0})
    ->Args({1, 1, 1})
    ->Args({0, 0, 1})
    ->Args({0, 1, 0})
    ->Args({0, 1, 1})
    ->Unit(benchmark::kMicrosecond)
    ->Repetitions(5)
    ->ReportAggregatesOnly(true);

// Z lambda with the liver's sizes: 16,380 output dofs (5,460 control nodes) by 75 prescribed rows
// (25 grasped control nodes). Z is 9.8 MB in double, 4.9 MB in float: more than the L2 cache, so
// the product streams it from L3 or memory every step as the model does.
void BM_GraspResponse(benchmark::State& state) {
  constexpr int kRows = 16380, kCols = 75;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  MatX Z(kRows, kCols);
  VecX lambda(kCols);
  for (int j = 0; j < kCols; ++j) {
    lambda[j] = u(rng);
    for (int r = 0; r < kRows; ++r) Z(r, j) = 1e-4 * u(rng);
  }
  hybrid_fem_pbd::BlockedResponse b;
  b.assign(Z);
  VecX y(b.paddedRows());
  const int kind = static_cast<int>(state.range(0));
  for (auto _ : state) {
    if (kind == 0) {
      y.head(kRows).noalias() = Z * lambda;
    } else {
      b.multiply(lambda.data(), y.data(), kind == 2);
    }
    benchmark::DoNotOptimize(y.data());
    benchmark::ClobberMemory();
  }
  state.counters["MB_read"] = kind == 0 ? 8e-6 * kRows * kCols : 4e-6 * b.paddedRows() * kCols;
}
BENCHMARK(BM_GraspResponse)
    ->ArgName("kind")
    ->Arg(0)
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMicrosecond)
    ->Repetitions(5)
    ->ReportAggregatesOnly(true);

}  // namespace

BENCHMARK_MAIN();
