// deformbench SDK: deform::SparseCholesky (CHOLMOD through Eigen) plus an allocation-free solve
// (cholmod_solve2 with workspaces kept between calls) and a float copy of a supernodal factor, the
// preconditioner of a conjugate-gradient solve (fem_hex's per-step PCG, reference_fem's inexact
// Newton). The triangular solves are memory-bound: the float copy halves the bytes they stream.
#pragma once

#include <deform/kernels/sparse.h>

#include <vector>

namespace deform {

class CholeskySolver : public SparseCholesky {
 public:
  CholeskySolver() = default;
  CholeskySolver(const CholeskySolver&) = delete;
  CholeskySolver& operator=(const CholeskySolver&) = delete;
  ~CholeskySolver();

  enum class Kind { Simplicial, Supernodal, Auto };
  /// CHOLMOD's factorisation kind; Auto lets CHOLMOD pick supernodal when flops / nnz(L) >= 40
  /// (CHOLMOD's default; measured right for OpenBLAS, see cholesky_solver.cpp).
  /// Call before analyzePattern().
  void setKind(Kind kind);
  bool isSupernodal() const;

  /// x = A^{-1} b. No allocation after the first call. Returns false if CHOLMOD failed.
  bool solveInto(const VecX& b, VecX& x);

  /// Copies the current supernodal factor's values to float (call after each factorize()).
  /// Returns false, and keeps no copy, when the factor is simplicial or failed.
  bool buildFloatFactor();
  bool hasFloatFactor() const { return !m_lf.empty(); }
  /// Forgets the float copy (solveFloatInto is then unavailable until the next build).
  void dropFloatFactor() { m_lf.clear(); }
  /// x ~= A^{-1} b by the float copy: both triangular solves in single precision (half the
  /// factor's memory traffic, twice the vector lanes). A preconditioner, not a direct solve: its
  /// error grows with the condition of A. Requires hasFloatFactor(). No allocation.
  void solveFloatInto(const VecX& b, VecX& x);

 private:
  cholmod_dense* m_X = nullptr;
  cholmod_dense* m_Y = nullptr;
  cholmod_dense* m_E = nullptr;
  // The float copy: CHOLMOD's supernodal layout (column-major blocks, rows of each supernode),
  // its integer arrays copied, and the permutation.
  std::vector<float> m_lf, m_y, m_t;
  std::vector<int> m_super, m_pi, m_px, m_rows, m_perm;
};

}  // namespace deform
