// Google Benchmark: one mass-spring step on a liver-sized closed surface (~2.2k nodes, ~6.6k edge
// springs, as in the metaballs paper's Table 2 row with 6427 springs), under gravity with a grasp.
#include "explicit_rows.h"
#include "held_top.h"
#include "massspring_model.h"
#include "node_cholesky.h"

#include <deform/geometry/phantom.h>

#include <benchmark/benchmark.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

namespace {

using namespace deform;

void runMassSpring(benchmark::State& state, massspring::MassSpringConfig cfg) {
  massspring::MassSpringModel m;
  bench::timeLiverHeldTop(state, m, cfg, 1e-4, 1e-7);  // and where a step goes (<phase>_ms)
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

// The local/global integrator's global step alone: A X = B with A = M + h^2 L of the 8,122-node
// liver phantom's springs (edge + bending, h = 1 ms, no constrained nodes) and three right-hand
// sides, by NodeCholesky (node_cholesky.h) and by CHOLMOD's supernodal solve.
SparseMatrix liverSystemMatrix() {
  Organ o;
  o.source = "phantom:liver";
  o.surface = makePhantom("liver");
  massspring::MassSpringModel m;
  m.init(o, massspring::MassSpringConfig{});
  const Real h2 = 1e-6;
  std::vector<Triplet> t;
  for (Eigen::Index i = 0; i < m.masses().size(); ++i) t.emplace_back(i, i, m.masses()[i]);
  for (const massspring::Spring& s : m.springs()) {
    t.emplace_back(s.a, s.a, h2 * s.k);
    t.emplace_back(s.b, s.b, h2 * s.k);
    t.emplace_back(s.a, s.b, -h2 * s.k);
    t.emplace_back(s.b, s.a, -h2 * s.k);
  }
  SparseMatrix A(m.masses().size(), m.masses().size());
  A.setFromTriplets(t.begin(), t.end());
  return A;
}

MatX liverRightHandSides(Eigen::Index n) {
  MatX B(n, 3);
  for (Eigen::Index i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) B(i, c) = std::sin(0.37 * double(i) + 1.3 * c);
  return B;
}

void BM_LiverGlobalSolveNodeCholesky(benchmark::State& state) {
  const SparseMatrix A = liverSystemMatrix();
  massspring::NodeCholesky chol;
  chol.factor(A);
  const MatX B = liverRightHandSides(A.rows());
  std::vector<massspring::Row4> Z(A.rows());
  for (auto _ : state) {
    for (Eigen::Index k = 0; k < A.rows(); ++k) {
      const int i = chol.perm()[k];
      Z[k] = {{B(i, 0), B(i, 1), B(i, 2), 0.0}};
    }
    chol.solveInPlace(Z.data());
    benchmark::DoNotOptimize(Z.data());
  }
  state.counters["nnz_L"] = double(chol.factorNonZeros());
  state.SetLabel("ordering " + chol.ordering());
}

void BM_LiverGlobalSolveCholmodSupernodal(benchmark::State& state) {
  const SparseMatrix A = liverSystemMatrix();
  installCholmodAllocator();
  SparseCholesky chol;
  chol.compute(A);
  const MatX B = liverRightHandSides(A.rows());
  MatX X;
  for (auto _ : state) {
    X = chol.solve(B);
    benchmark::DoNotOptimize(X.data());
  }
}

// The explicit integrators' spring pass alone (explicit_rows.h) on the 8,122-node liver phantom
// (48,720 edge + bending springs, the default scene's organ), positions perturbed from rest and
// velocities nonzero: arg 1 the AVX-512 path where the CPU has it, 0 the scalar one.
void BM_LiverSpringPass(benchmark::State& state) {
  Organ o;
  o.source = "phantom:liver";
  o.surface = makePhantom("liver");
  massspring::MassSpringModel m;
  m.init(o, massspring::MassSpringConfig{});
  const Eigen::Index N = m.masses().size();
  std::vector<double> buf(12 * N + 8, 0.0);
  const auto p = reinterpret_cast<std::uintptr_t>(buf.data());
  double* xv = buf.data() + ((64 - p % 64) % 64) / sizeof(double);  // rows on cache lines
  double* f4 = xv + 8 * N;
  for (Eigen::Index i = 0; i < N; ++i)
    for (int c = 0; c < 3; ++c) {
      xv[8 * i + c] = o.surface.V(i, c) * (1.0 + 1e-3 * std::sin(0.37 * double(i) + c));
      xv[8 * i + 4 + c] = 1e-3 * std::cos(0.91 * double(i) + c);
    }
  std::vector<int> a, b;
  std::vector<double> rest, k, c;
  for (const massspring::Spring& sp : m.springs()) {
    a.push_back(8 * sp.a);
    b.push_back(8 * sp.b);
    rest.push_back(sp.rest);
    k.push_back(sp.k);
    c.push_back(sp.c);
  }
  const massspring::rows::SpringArrays springs{a.data(), b.data(), rest.data(),
                                               k.data(), c.data(), a.size()};
  const bool simd = state.range(0) != 0;
  for (auto _ : state) {
    std::fill(f4, f4 + 4 * N, 0.0);
    benchmark::DoNotOptimize(massspring::rows::addSpringForces(xv, springs, f4, simd));
    benchmark::DoNotOptimize(f4);
  }
  state.counters["ns_per_spring"] =
      benchmark::Counter(double(a.size()) * 1e-9, benchmark::Counter::kIsIterationInvariantRate |
                                                      benchmark::Counter::kInvert);
  const massspring::rows::Simd path =
      simd ? massspring::rows::simdPath() : massspring::rows::Simd::Scalar;
  state.SetLabel(path == massspring::rows::Simd::Avx512 ? "avx512"
                 : path == massspring::rows::Simd::Avx2 ? "avx2"
                                                        : "scalar");
}

BENCHMARK(BM_LiverSpringPass)->Arg(1)->Arg(0)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_LiverGlobalSolveNodeCholesky)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_LiverGlobalSolveCholmodSupernodal)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_MassSpringExplicitEdgesOnly)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_MassSpringExplicitWithBending)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_MassSpringSymplecticWithBending)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_MassSpringImplicitWithBending)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
