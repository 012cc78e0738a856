// Google Benchmark of the bending kernels alone: one Gauss-Seidel sweep over every hinge of the
// 8,122-vertex liver phantom (24k hinges, greedy-coloured so that a colour shares no particle),
// on padded positions as the solvers keep them. Isometric (deform/kernels/isometric_bending.h) in
// float and double, vectorised (AVX2 where the CPU has it) and scalar; the dihedral angle
// (deform/kernels/pbd_kernels.h, projectDihedral) one hinge at a time as the PBD plugin projects
// it. The isometric sweeps also run with two vertices in three immovable and the movable-slot
// pattern passed (fixed:1), as the hybrid model projects them.
// Time per sweep; the per-hinge cost is in the "ns_per_hinge" counter.
#include <benchmark/benchmark.h>
#include <deform/geometry/phantom.h>
#include <deform/kernels/isometric_bending.h>
#include <deform/kernels/pbd_kernels.h>
#include <deform/sdk/mesh.h>

#include <algorithm>
#include <bit>
#include <cstdint>
#include <numeric>
#include <vector>

namespace {

using namespace deform;

struct Hinges {
  SurfaceMesh s = makePhantom("liver");
  std::vector<pbd::IsometricHinge> iso;  // colour order
  std::vector<pbd::DihedralConstraint> dih;
  std::vector<size_t> colours;  // starts, plus the end
  Hinges() {
    const MatX2i E = uniqueEdges(s.F);
    const MatX2i EF = edgeFaces(s.F, E);
    std::vector<pbd::IsometricHinge> all;
    for (Eigen::Index e = 0; e < E.rows(); ++e) {
      const int f0 = EF(e, 0), f1 = EF(e, 1);
      if (f0 < 0 || f1 < 0) continue;
      int k = 0;
      while (s.F(f0, k) == E(e, 0) || s.F(f0, k) == E(e, 1)) ++k;
      int j = 0;
      while (s.F(f1, j) == E(e, 0) || s.F(f1, j) == E(e, 1)) ++j;
      pbd::IsometricHinge h;
      h.p[0] = s.F(f0, k);
      h.p[2] = s.F(f0, (k + 1) % 3);
      h.p[3] = s.F(f0, (k + 2) % 3);
      h.p[1] = s.F(f1, j);
      Vec3 x[4];
      for (int i = 0; i < 4; ++i) x[i] = s.V.row(h.p[i]);
      if (pbd::isometricHinge(x, h)) all.push_back(h);
    }
    // Greedy colouring (at most 64 colours; the liver needs far fewer).
    std::vector<std::uint64_t> used(s.numVertices(), 0);
    std::vector<std::pair<int, int>> key;
    for (size_t i = 0; i < all.size(); ++i) {
      std::uint64_t mask = 0;
      for (int n : all[i].p) mask |= used[n];
      const int c = std::countr_zero(~mask);
      for (int n : all[i].p) used[n] |= std::uint64_t(1) << c;
      key.emplace_back(c, int(i));
    }
    std::sort(key.begin(), key.end());
    for (size_t i = 0; i < key.size(); ++i) {
      if (i == 0 || key[i].first != key[i - 1].first) colours.push_back(i);
      iso.push_back(all[key[i].second]);
      pbd::DihedralConstraint d;
      std::copy(std::begin(iso.back().p), std::end(iso.back().p), d.p);
      Vec3 x[4], g[4];
      for (int k = 0; k < 4; ++k) x[k] = s.V.row(d.p[k]);
      pbd::dihedralAngle(x[0], x[1], x[2], x[3], d.restAngle, g);
      dih.push_back(d);
    }
    colours.push_back(iso.size());
  }
};

const Hinges& hinges() {
  static const Hinges h;
  return h;
}

// Arguments: simd; fixed = 1: two vertices in three immovable (w = 0, about the share of the
// hybrid model's control nodes), the hinges of each colour sorted by their movable-slot pattern
// and the pattern passed to the kernel, which then skips the slots immovable in a whole group.
template <class T>
void BM_IsometricSweep(benchmark::State& state) {
  const Hinges& H = hinges();
  const bool simd = state.range(0) != 0, fixed = state.range(1) != 0;
  const size_t n = H.iso.size();
  std::vector<T> x4(4 * H.s.numVertices(), T(0));
  for (int i = 0; i < H.s.numVertices(); ++i)
    for (int c = 0; c < 3; ++c) x4[4 * i + c] = static_cast<T>(H.s.V(i, c) * (1.0 + 1e-3 * c));
  auto pattern = [&](size_t i) {
    unsigned m = 0;
    for (int k = 0; k < 4; ++k)
      if (!fixed || H.iso[i].p[k] % 3 == 0) m |= 1u << k;
    return static_cast<unsigned char>(m);
  };
  std::vector<size_t> order(n);
  std::iota(order.begin(), order.end(), size_t(0));
  for (size_t c = 0; fixed && c + 1 < H.colours.size(); ++c)
    std::stable_sort(order.begin() + H.colours[c], order.begin() + H.colours[c + 1],
                     [&](size_t a, size_t b) { return pattern(a) < pattern(b); });
  std::vector<int> p[4];
  std::vector<T> K[4], wK[4], rest(n), at(n, T(0)), scale(n), lambda(n, T(0));
  std::vector<unsigned char> movable(n);
  for (size_t j = 0; j < n; ++j) {
    const size_t i = order[j];
    movable[j] = pattern(i);
    Real denom = 0;
    for (int k = 0; k < 4; ++k) {
      const Real w = (movable[j] >> k) & 1u ? 1.0 : 0.0;
      p[k].push_back(4 * H.iso[i].p[k]);
      K[k].push_back(static_cast<T>(H.iso[i].K[k]));
      wK[k].push_back(static_cast<T>(w * H.iso[i].K[k]));
      denom += w * H.iso[i].K[k] * H.iso[i].K[k];
    }
    rest[j] = static_cast<T>(H.iso[i].rest);
    scale[j] = denom > 0 ? static_cast<T>(0.5 / denom) : T(0);
  }
  pbd::IsometricBatch<T> b = pbd::isometricBatch(p, K, wK, rest, at, scale, lambda);
  if (fixed) b.movable = movable.data();
  for (auto _ : state) {
    for (size_t c = 0; c + 1 < H.colours.size(); ++c)
      benchmark::DoNotOptimize(
          pbd::projectIsometricColour(x4.data(), b, H.colours[c], H.colours[c + 1], simd));
    benchmark::ClobberMemory();
  }
  state.counters["hinges"] = double(n);
  state.counters["ns_per_hinge"] = benchmark::Counter(
      double(n), benchmark::Counter::kIsIterationInvariantRate | benchmark::Counter::kInvert);
}

void BM_DihedralSweep(benchmark::State& state) {
  const Hinges& H = hinges();
  MatX3 x = H.s.V;
  for (int c = 0; c < 3; ++c) x.col(c) *= 1.0 + 1e-3 * c;
  std::vector<Real> lambda(H.dih.size(), 0.0);
  const Real w[4] = {1, 1, 1, 1};
  for (auto _ : state) {
    for (size_t i = 0; i < H.dih.size(); ++i) {
      const pbd::DihedralConstraint& c = H.dih[i];
      Vec3 xs[4], dx[4];
      for (int k = 0; k < 4; ++k) xs[k] = x.row(c.p[k]);
      if (!pbd::projectDihedral(xs, w, c.restAngle, 0.0, 0.5, lambda[i], dx)) continue;
      for (int k = 0; k < 4; ++k) x.row(c.p[k]) += dx[k];
    }
    benchmark::ClobberMemory();
  }
  state.counters["hinges"] = double(H.dih.size());
  state.counters["ns_per_hinge"] =
      benchmark::Counter(double(H.dih.size()), benchmark::Counter::kIsIterationInvariantRate |
                                                   benchmark::Counter::kInvert);
}

/// The isometric sweep's variants, the same for float and double: vectorised and scalar with
/// every vertex movable, vectorised with two vertices in three immovable.
void isometricVariants(benchmark::internal::Benchmark* b) {
  b->ArgNames({"simd", "fixed"})->Args({1, 0})->Args({0, 0})->Args({1, 1});
}

BENCHMARK(BM_IsometricSweep<float>)->Apply(isometricVariants)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_IsometricSweep<double>)->Apply(isometricVariants)->Unit(benchmark::kMicrosecond);
BENCHMARK(BM_DihedralSweep)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
