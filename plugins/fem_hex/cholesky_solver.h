// fem_hex kernels: deform::SparseCholesky (CHOLMOD through Eigen) plus an allocation-free solve
// (cholmod_solve2 with workspaces kept between calls), for the per-step loop.
#pragma once

#include <deform/sparse.h>

namespace deform::fem_hex {

class CholeskySolver : public SparseCholesky {
 public:
  CholeskySolver() = default;
  CholeskySolver(const CholeskySolver&) = delete;
  CholeskySolver& operator=(const CholeskySolver&) = delete;
  ~CholeskySolver();

  /// Use CHOLMOD's simplicial (true) or supernodal (false, the default) factorisation; call
  /// before analyzePattern().
  void setSimplicial(bool simplicial);

  /// x = A^{-1} b. No allocation after the first call. Returns false if CHOLMOD failed.
  bool solveInto(const VecX& b, VecX& x);

 private:
  cholmod_dense* m_X = nullptr;
  cholmod_dense* m_Y = nullptr;
  cholmod_dense* m_E = nullptr;
};

}  // namespace deform::fem_hex
