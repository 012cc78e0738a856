// fem_hex kernels: deform::SparseCholesky (CHOLMOD through Eigen) plus an allocation-free solve
// (cholmod_solve2 with workspaces kept between calls), for the per-step loop.
#pragma once

#include <deform/kernels/sparse.h>

namespace deform::fem_hex {

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

 private:
  cholmod_dense* m_X = nullptr;
  cholmod_dense* m_Y = nullptr;
  cholmod_dense* m_E = nullptr;
};

}  // namespace deform::fem_hex
