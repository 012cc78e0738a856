// The float and half copies of a supernodal factor (the PCG's preconditioner) against CHOLMOD's
// own double solve of the same factor.
#include <deform/kernels/cholesky_solver.h>

#include <gtest/gtest.h>
#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
#endif

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

namespace deform {
namespace {

/// The 7-point Laplacian of an n^3 grid plus `shift` I: SPD, with a supernodal factor at n = 12.
SparseMatrix gridLaplacian(int n, Real shift) {
  const auto id = [n](int i, int j, int k) { return (i * n + j) * n + k; };
  std::vector<Triplet> t;
  for (int i = 0; i < n; ++i)
    for (int j = 0; j < n; ++j)
      for (int k = 0; k < n; ++k) {
        const int a = id(i, j, k);
        t.emplace_back(a, a, 6.0 + shift);
        if (i + 1 < n) t.emplace_back(id(i + 1, j, k), a, -1.0);
        if (j + 1 < n) t.emplace_back(id(i, j + 1, k), a, -1.0);
        if (k + 1 < n) t.emplace_back(id(i, j, k + 1), a, -1.0);
      }
  SparseMatrix A(n * n * n, n * n * n);
  A.setFromTriplets(t.begin(), t.end());  // lower triangle, as the solver reads it
  return A;
}

/// Analyses and factorises A with the given kind of factor.
void factorise(CholeskySolver& chol, const SparseMatrix& A, CholeskySolver::Kind kind) {
  chol.setKind(kind);
  chol.analyzePattern(A);
  chol.factorize(A);
  ASSERT_EQ(chol.info(), Eigen::Success);
}

TEST(CholeskySolver, FloatSolveOfASupernodalFactorMatchesTheDoubleSolve) {
  const SparseMatrix A = gridLaplacian(12, 0.01);
  CholeskySolver chol;
  ASSERT_NO_FATAL_FAILURE(factorise(chol, A, CholeskySolver::Kind::Supernodal));
  ASSERT_TRUE(chol.buildFloatFactor());
  std::mt19937 rng(7);
  std::uniform_real_distribution<Real> u(-1, 1);
  VecX b(A.rows());
  for (Eigen::Index i = 0; i < b.size(); ++i) b[i] = u(rng);
  VecX xd, xf;
  ASSERT_TRUE(chol.solveInto(b, xd));
  chol.solveFloatInto(b, xf);
  EXPECT_LT((xf - xd).norm(), 1e-4 * xd.norm());
  EXPECT_GT((xf - xd).norm(), 0.0);  // it did run in float
  // A solve of the matrix itself: A x = b.
  const SparseMatrix full = A.selfadjointView<Eigen::Lower>();
  EXPECT_LT((full * xf - b).norm(), 1e-4 * b.norm());
}

#if defined(__x86_64__) && defined(__GNUC__)
/// F16C's own conversion of one float (rounded to nearest even).
__attribute__((target("f16c"))) uint16_t f16cHalf(float f) {
  return _cvtss_sh(f, _MM_FROUND_TO_NEAREST_INT);
}
#endif

/// A random right-hand side of A's size.
VecX randomVector(Eigen::Index n) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<Real> u(-1, 1);
  VecX b(n);
  for (Eigen::Index i = 0; i < n; ++i) b[i] = u(rng);
  return b;
}

// The half copy (11 significant bits) solves to about the precision of its values, and both
// copies' vectorised paths agree with the plain loops to float round-off. The 12^3 grid's widest
// supernode spans many triangle blocks.
TEST(CholeskySolver, HalfSolveAndEveryPathMatchTheDoubleSolve) {
  const SparseMatrix A = gridLaplacian(12, 1.0);
  CholeskySolver chol;
  ASSERT_NO_FATAL_FAILURE(factorise(chol, A, CholeskySolver::Kind::Supernodal));
  const VecX b = randomVector(A.rows());
  VecX xd;
  ASSERT_TRUE(chol.solveInto(b, xd));
  for (const auto precision :
       {CholeskySolver::Precision::Float32, CholeskySolver::Precision::Float16}) {
    const bool half = precision == CholeskySolver::Precision::Float16;
    ASSERT_TRUE(chol.buildFloatFactor(precision));
    EXPECT_EQ(chol.floatFactorIsHalf(), half);
    VecX fast, plain;
    chol.solveFloatInto(b, fast);
    chol.solveFloatInto(b, plain, true);
    const Real error = (fast - xd).norm() / xd.norm();
    EXPECT_LT(error, half ? 2e-3 : 1e-5) << half;
    EXPECT_GT(error, half ? 1e-5 : 0.0) << half;  // it did run in that precision
    EXPECT_LT((fast - plain).norm(), 1e-5 * xd.norm()) << half;
  }
  chol.dropFloatFactor();
  EXPECT_FALSE(chol.hasFloatFactor());
}

// binary16 rounding: to nearest, ties to even, through the subnormals and up to infinity; every
// half value converts to float and back unchanged.
TEST(CholeskySolver, HalfConversionRoundsToNearestEven) {
  const auto half = [](float f) { return CholeskySolver::toHalf(f); };
  EXPECT_EQ(half(1.0f), 0x3c00);
  EXPECT_EQ(half(1.0f + std::ldexp(1.0f, -11)), 0x3c00);      // a tie: to the even 1
  EXPECT_EQ(half(1.0f + 3 * std::ldexp(1.0f, -11)), 0x3c02);  // a tie: to the even 1 + 2^-9
  EXPECT_EQ(half(1.0f + std::ldexp(1.0f, -11) + std::ldexp(1.0f, -20)), 0x3c01);
  EXPECT_EQ(half(-2.0f), 0xc000);
  EXPECT_EQ(half(std::ldexp(1.0f, -24)), 0x0001);  // the smallest subnormal
  EXPECT_EQ(half(std::ldexp(1.0f, -25)), 0x0000);  // a tie: to zero
  EXPECT_EQ(half(3 * std::ldexp(1.0f, -25)), 0x0002);
  EXPECT_EQ(half(std::ldexp(1.0f, -14) - std::ldexp(1.0f, -26)), 0x0400);  // up to the normals
  EXPECT_EQ(half(65504.0f), 0x7bff);
  EXPECT_EQ(half(65519.0f), 0x7bff);
  EXPECT_EQ(half(65520.0f), 0x7c00);  // a tie: to infinity
  EXPECT_EQ(half(INFINITY), 0x7c00);
  EXPECT_TRUE(std::isnan(CholeskySolver::fromHalf(half(NAN))));
  for (uint32_t h = 0; h < 0x10000; ++h) {
    if ((h & 0x7c00u) == 0x7c00u && (h & 0x3ffu)) continue;  // NaN
    ASSERT_EQ(half(CholeskySolver::fromHalf(uint16_t(h))), h) << h;
  }
#if defined(__x86_64__) && defined(__GNUC__)
  // The copy is converted by F16C where the CPU has it: the same rounding.
  if (CholeskySolver::halfIsFast()) {
    for (uint64_t bits = 0; bits < (uint64_t(1) << 32); bits += 65521) {
      float f;
      const uint32_t b = uint32_t(bits);
      std::memcpy(&f, &b, 4);
      if (std::isnan(f)) continue;
      ASSERT_EQ(half(f), f16cHalf(f)) << f;
    }
  }
#endif
}

TEST(CholeskySolver, NoFloatCopyOfASimplicialFactor) {
  const SparseMatrix A = gridLaplacian(5, 1.0);
  CholeskySolver chol;
  ASSERT_NO_FATAL_FAILURE(factorise(chol, A, CholeskySolver::Kind::Simplicial));
  EXPECT_FALSE(chol.buildFloatFactor());
  EXPECT_FALSE(chol.hasFloatFactor());
}

}  // namespace
}  // namespace deform
