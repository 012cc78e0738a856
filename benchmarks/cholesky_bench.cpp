// Google Benchmark of the preconditioner's triangular solves (deform/kernels/cholesky_solver.h):
// one forward and one backward solve with a supernodal factor, as fem_hex's PCG and reference_fem's
// inexact Newton apply it once per CG iteration. The matrix has fem_hex's pattern on the
// 967-hexahedron liver's scale: three unknowns per node of an n^3 grid, each node coupled to its
// 26 neighbours (trilinear hexahedra), n = 10: 3,000 unknowns (the liver's system has 3,261 and
// 548k factor non-zeros). Arguments: precision (0 CHOLMOD's double solve, 1 the float copy, 2 the
// half copy) and plain loops (1) or the CPU's vector units (0). Time per pair of solves;
// "bytes_per_solve" is the copy's size.
#include <benchmark/benchmark.h>
#include <deform/kernels/cholesky_solver.h>

#include <random>
#include <vector>

namespace {

using namespace deform;

SparseMatrix hexPattern(int n) {
  const auto id = [n](int i, int j, int k) { return (i * n + j) * n + k; };
  std::vector<Triplet> t;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < n; ++k)
        for (int di = -1; di <= 1; ++di)
          for (int dj = -1; dj <= 1; ++dj)
            for (int dk = -1; dk <= 1; ++dk) {
              const int a = i + di, b = j + dj, c = k + dk;
              if (a < 0 || b < 0 || c < 0 || a >= n || b >= n || c >= n) continue;
              const int p = id(i, j, k), q = id(a, b, c);
              for (int x = 0; x < 3; ++x)
                for (int y = 0; y < 3; ++y) {
                  const int r = 3 * p + x, s = 3 * q + y;
                  if (r < s) continue;  // the lower triangle, as the solver reads it
                  t.emplace_back(r, s, r == s ? 27.5 : (x == y ? -1.0 : 0.05));
                }
            }
  SparseMatrix A(3 * n * n * n, 3 * n * n * n);
  A.setFromTriplets(t.begin(), t.end());
  return A;
}

void BM_PreconditionerSolve(benchmark::State& state) {
  static const SparseMatrix A = hexPattern(10);
  const int precision = static_cast<int>(state.range(0));
  const bool plain = state.range(1) != 0;
  CholeskySolver chol;
  chol.setKind(CholeskySolver::Kind::Supernodal);
  chol.analyzePattern(A);
  chol.factorize(A);
  if (chol.info() != Eigen::Success) {
    state.SkipWithError("factorisation failed");
    return;
  }
  if (precision > 0 &&
      !chol.buildFloatFactor(precision == 2 ? CholeskySolver::Precision::Float16
                                            : CholeskySolver::Precision::Float32)) {
    state.SkipWithError("no supernodal factor");
    return;
  }
  std::mt19937 rng(3);
  std::uniform_real_distribution<Real> u(-1, 1);
  VecX b(A.rows()), x;
  for (Eigen::Index i = 0; i < b.size(); ++i) b[i] = u(rng);
  for (auto _ : state) {
    if (precision == 0) {
      chol.solveInto(b, x);
    } else {
      chol.solveFloatInto(b, x, plain);
    }
    benchmark::DoNotOptimize(x.data());
  }
  const double entries = double(chol.cholmod().lnz);
  state.counters["factor_nonzeros"] = entries;
  state.counters["bytes_per_solve"] = entries * (precision == 0 ? 8 : precision == 1 ? 4 : 2);
}
BENCHMARK(BM_PreconditionerSolve)
    ->ArgNames({"precision", "plain"})
    ->Args({0, 0})
    ->Args({1, 0})
    ->Args({2, 0})
    ->Args({1, 1})
    ->Args({2, 1})
    ->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
