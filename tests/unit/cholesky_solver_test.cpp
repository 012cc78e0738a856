// The float copy of a supernodal factor (the PCG's preconditioner) against CHOLMOD's own double
// solve of the same factor.
#include <deform/kernels/cholesky_solver.h>

#include <gtest/gtest.h>

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

TEST(CholeskySolver, NoFloatCopyOfASimplicialFactor) {
  const SparseMatrix A = gridLaplacian(5, 1.0);
  CholeskySolver chol;
  ASSERT_NO_FATAL_FAILURE(factorise(chol, A, CholeskySolver::Kind::Simplicial));
  EXPECT_FALSE(chol.buildFloatFactor());
  EXPECT_FALSE(chol.hasFloatFactor());
}

}  // namespace
}  // namespace deform
