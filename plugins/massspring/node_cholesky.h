// massspring kernels: a sparse Cholesky factor applied to three right-hand sides stored per node.
// The local/global integrator (massspring_liu.cpp) solves A X = B with a constant SPD N x N matrix
// A and an N x 3 right-hand side several times per step. CHOLMOD's supernodal solve spends most
// of that time packing panels for BLAS calls that are too narrow (3 columns) to pay off (on the
// 8,122-node liver: ~3 ms per solve, two thirds of it in OpenBLAS's copy routines). NodeCholesky
// keeps CHOLMOD's fill-reducing ordering and numerical factorisation, copies the factor once
// into compressed columns, and solves with one pass down and one pass up those columns, each
// entry updating a node's 4-vector (x, y, z, padding): one AVX2 operation in double.
#pragma once

#include <deform/kernels/sparse.h>

#include <memory>
#include <string>
#include <vector>

namespace deform::massspring {

/// One node's three coordinates (or right-hand sides) and a padding slot, 32-byte aligned.
struct alignas(32) Row4 {
  double v[4];
};

class NodeCholesky {
 public:
  NodeCholesky();
  ~NodeCholesky();
  NodeCholesky(const NodeCholesky&) = delete;
  NodeCholesky& operator=(const NodeCholesky&) = delete;

  /// Factorises the symmetric positive definite N x N matrix A (lower triangle read):
  /// P A P^T = L L^T. The first call analyses A's pattern (CHOLMOD's ordering, kept while the
  /// pattern stays the same); later calls refactorise. Throws std::runtime_error when A is not
  /// positive definite.
  void factor(const SparseMatrix& A);

  int size() const { return static_cast<int>(m_invDiag.size()); }
  /// perm()[k] is the row of A that row k of the solve arrays holds.
  const std::vector<int>& perm() const { return m_perm; }
  /// Solves A X = B in place. Z: #N rows; row k holds node perm()[k] (three right-hand sides and
  /// a fourth column that is solved too: keep it zero). B on entry, X on return.
  void solveInPlace(Row4* Z) const;

  /// Entries of L the solve reads, its diagonal included (CHOLMOD's supernodes store some
  /// explicit zeros).
  long long factorNonZeros() const { return m_nonZeros; }
  /// The fill-reducing ordering CHOLMOD chose: "amd", "metis", "nesdis", "colamd", "natural".
  std::string ordering() const { return m_ordering; }

  /// Columns col .. col + width - 1 of L with a common pattern below their diagonal block:
  /// `below` rows, listed from `rows`; their values from `values` (see node_cholesky.cpp).
  struct Supernode {
    int col, width, below, rows;
    long values;
  };

 private:
  struct Cholmod;  // CHOLMOD's symbolic and numerical factor (node_cholesky.cpp)
  std::unique_ptr<Cholmod> m_cholmod;
  std::vector<int> m_perm;
  std::vector<Supernode> m_super;
  std::vector<int> m_row;
  std::vector<float> m_val;
  std::vector<double> m_invDiag;  // 1 / L_jj
  long long m_nonZeros = 0;
  std::string m_ordering;
};

}  // namespace deform::massspring
