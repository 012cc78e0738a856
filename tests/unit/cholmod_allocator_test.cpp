// installCholmodAllocator (deform/kernels/sparse.h): CHOLMOD's allocation hooks keep their malloc
// contract (zeroed calloc, content-preserving realloc, frees of memory obtained before the
// hooks were installed) and a factorisation through them gives the same factor.
#include <deform/kernels/sparse.h>

#include <SuiteSparse_config.h>
#include <gtest/gtest.h>

#include <cstdlib>
#include <cstring>
#include <vector>

using namespace deform;

namespace {

constexpr size_t kLarge = size_t(5) << 20;  // above the 2 MiB threshold of the large blocks

/// A 1D Laplacian plus a diagonal shift: SPD, n x n, lower triangle.
SparseMatrix laplacian(int n) {
  std::vector<Triplet> t;
  for (int i = 0; i < n; ++i) {
    t.emplace_back(i, i, 2.5);
    if (i + 1 < n) t.emplace_back(i + 1, i, -1.0);
  }
  SparseMatrix A(n, n);
  A.setFromTriplets(t.begin(), t.end());
  return A;
}

VecX factorSolve(const SparseMatrix& A) {
  SparseCholesky chol;
  chol.compute(A);
  EXPECT_EQ(chol.info(), Eigen::Success);
  return chol.solve(VecX::LinSpaced(A.rows(), 0.0, 1.0));
}

}  // namespace

// First in the file: the factor before the hooks are installed is the baseline.
TEST(CholmodAllocator, FactorisesAsBefore) {
  // Large enough that CHOLMOD's factor and workspace go through the large blocks.
  const SparseMatrix A = laplacian(200000);
  const VecX x = factorSolve(A);
  installCholmodAllocator();
  const VecX y = factorSolve(A);
  const VecX z = factorSolve(A);  // reuses cached blocks
  EXPECT_EQ((x - y).lpNorm<Eigen::Infinity>(), 0.0);
  EXPECT_EQ((x - z).lpNorm<Eigen::Infinity>(), 0.0);
  const VecX r = A.selfadjointView<Eigen::Lower>() * x - VecX::LinSpaced(A.rows(), 0.0, 1.0);
  EXPECT_LT(r.norm(), 1e-10);
}

TEST(CholmodAllocator, KeepsTheMallocContract) {
  // A block from before the hooks (malloc's) must be freed and reallocated correctly after.
  void* before = SuiteSparse_config.malloc_func(1000);
  ASSERT_NE(before, nullptr);
  std::memset(before, 0x5a, 1000);
  installCholmodAllocator();
  installCholmodAllocator();                                 // idempotent
  before = SuiteSparse_config.realloc_func(before, kLarge);  // foreign pointer grows large
  ASSERT_NE(before, nullptr);
  for (size_t i = 0; i < 1000; ++i) ASSERT_EQ(static_cast<unsigned char*>(before)[i], 0x5a);

  // calloc of a large block is zero, also when it reuses a dirty freed block.
  for (int round = 0; round < 3; ++round) {
    auto* p = static_cast<unsigned char*>(SuiteSparse_config.calloc_func(kLarge / 8, 8));
    ASSERT_NE(p, nullptr);
    for (size_t i = 0; i < kLarge; i += 4093) ASSERT_EQ(p[i], 0) << "round " << round;
    ASSERT_EQ(p[kLarge - 1], 0);
    std::memset(p, 0xff, kLarge);
    SuiteSparse_config.free_func(p);
  }

  // realloc keeps the content across large -> larger -> smaller -> small.
  auto* q = static_cast<unsigned char*>(SuiteSparse_config.malloc_func(kLarge));
  ASSERT_NE(q, nullptr);
  for (size_t i = 0; i < kLarge; ++i) q[i] = static_cast<unsigned char>(i * 7);
  q = static_cast<unsigned char*>(SuiteSparse_config.realloc_func(q, 3 * kLarge));
  ASSERT_NE(q, nullptr);
  for (size_t i = 0; i < kLarge; i += 997) ASSERT_EQ(q[i], static_cast<unsigned char>(i * 7));
  q = static_cast<unsigned char*>(SuiteSparse_config.realloc_func(q, kLarge / 2));
  ASSERT_NE(q, nullptr);
  for (size_t i = 0; i < kLarge / 2; i += 997) ASSERT_EQ(q[i], static_cast<unsigned char>(i * 7));
  SuiteSparse_config.free_func(q);
  SuiteSparse_config.free_func(before);
  SuiteSparse_config.free_func(nullptr);  // a no-op, as free(NULL)
}

TEST(LargePageAllocator, LargeVectorsAreOnAlignedReusedBlocksAndSmallOnesOnMalloc) {
  using Vector = std::vector<int, LargePageAllocator<int>>;
  // 40 MiB: no other test here frees a block of 40-80 MiB, which the cache could hand out too.
  const size_t n = (size_t(40) << 20) / sizeof(int);
  const int* first = nullptr;
  {
    Vector v(n, 7);
    first = v.data();
    EXPECT_EQ(reinterpret_cast<uintptr_t>(first) % (size_t(2) << 20), 0u);  // 2 MiB aligned
    EXPECT_EQ(v[n - 1], 7);
  }
  Vector w(n, -1);  // the freed block comes back, its content overwritten
  EXPECT_EQ(w.data(), first);
  EXPECT_EQ(w[0], -1);
  EXPECT_EQ(w[n - 1], -1);
  Vector small(100, 3);  // under 2 MiB: malloc's, freed by free (ASan checks the pairing)
  EXPECT_EQ(small[99], 3);
  small.assign(2 * n, 5);  // grows into a large block
  EXPECT_EQ(small[2 * n - 1], 5);
  EXPECT_EQ(reinterpret_cast<uintptr_t>(small.data()) % (size_t(2) << 20), 0u);
}
