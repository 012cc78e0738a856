// deformbench SDK: deform::SparseCholesky (CHOLMOD through Eigen) plus an allocation-free solve
// (cholmod_solve2 with workspaces kept between calls) and a float or half copy of a supernodal
// factor, the preconditioner of a conjugate-gradient solve (fem_hex's per-step PCG, reference_fem's
// inexact Newton). The triangular solves stream the whole factor: the float copy halves the bytes,
// the half copy halves them again; their dense triangles go a block of columns at a time.
#pragma once

#include <deform/kernels/sparse.h>

#include <cstdint>
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

  /// The number type of the preconditioner's copy of the factor. Float16: IEEE binary16, each
  /// column scaled by a power of two (11 significant bits; half the float copy's bytes).
  enum class Precision { Float32, Float16 };
  /// Copies the current supernodal factor's values to float or half (call after each
  /// factorize()). Returns false, and keeps no copy, when the factor is simplicial or failed.
  bool buildFloatFactor(Precision precision = Precision::Float32);
  bool hasFloatFactor() const { return !m_lf.empty() || !m_lh.empty(); }
  bool floatFactorIsHalf() const { return !m_lh.empty(); }
  /// Forgets the copy (solveFloatInto is then unavailable until the next build).
  void dropFloatFactor() {
    m_lf.clear();
    m_lh.clear();
  }
  /// x ~= A^{-1} b by the float or half copy: both triangular solves in single precision
  /// arithmetic (the copy's memory traffic, twice the vector lanes of double). A preconditioner,
  /// not a direct solve: its error grows with the condition of A. Requires hasFloatFactor(). No
  /// allocation. portable: the plain C++ loops whatever the CPU (for tests; otherwise AVX2 and
  /// F16C where the CPU has them).
  void solveFloatInto(const VecX& b, VecX& x, bool portable = false);

  /// IEEE binary16 from float rounded to nearest even, and back (exact): the half copy's
  /// conversions where the CPU has no F16C.
  static uint16_t toHalf(float f);
  static float fromHalf(uint16_t h);
  /// Whether this CPU converts halves in hardware (F16C). Without it the half copy's solves run
  /// the plain loops, many times slower than the float copy's.
  static bool halfIsFast();

 private:
  cholmod_dense* m_X = nullptr;
  cholmod_dense* m_Y = nullptr;
  cholmod_dense* m_E = nullptr;
  // The float or half copy: CHOLMOD's supernodal layout (column-major blocks, rows of each
  // supernode), its integer arrays copied, and the permutation; the column scales (the half
  // copy's, 1 for the float copy) and the reciprocal diagonal.
  std::vector<float> m_lf, m_y, m_t, m_scale, m_dinv;
  std::vector<uint16_t> m_lh;
  std::vector<int> m_super, m_pi, m_px, m_rows, m_perm;
};

}  // namespace deform
