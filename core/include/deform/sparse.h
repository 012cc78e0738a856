// deformbench SDK: sparse matrices and the sparse Cholesky factorisation every implicit model
// uses: CHOLMOD's supernodal LL^T through Eigen's CholmodSupport module. Analyse the pattern once
// (analyzePattern), refactorise numerically when values change (factorize), check info().
#pragma once

#include <deform/types.h>

#include <Eigen/CholmodSupport>
#include <Eigen/SparseCore>

namespace deform {

using SparseMatrix = Eigen::SparseMatrix<Real, Eigen::ColMajor, int>;
using Triplet = Eigen::Triplet<Real, int>;

/// Supernodal CHOLMOD Cholesky of a symmetric positive definite matrix (lower triangle read).
using SparseCholesky = Eigen::CholmodSupernodalLLT<SparseMatrix, Eigen::Lower>;

/// While an object of this class lives, OpenMP parallel regions run on the calling thread only.
/// Why: CHOLMOD 3 (SuiteSparse 5, Debian 12) runs parts of its supernodal numerical
/// factorisation (cholmod_super_numeric) in OpenMP regions with a hard-coded num_threads(4),
/// which OMP_NUM_THREADS=1 does not limit; the project's numerics are single-threaded, and on a
/// shared 2-core machine those extra threads mostly wait for each other (measured on the 51k-tet
/// liver: 22k involuntary context switches and 0.9 s kernel time in one solve). Sets OpenMP's
/// max-active-levels to 0 (no region is active, so each runs with one thread) and restores it on
/// destruction; does nothing when the OpenMP runtime (libgomp) is not loaded. Wrap calls of
/// SparseCholesky::factorize / compute in it.
class SerialOpenMpScope {
 public:
  SerialOpenMpScope();
  ~SerialOpenMpScope();
  SerialOpenMpScope(const SerialOpenMpScope&) = delete;
  SerialOpenMpScope& operator=(const SerialOpenMpScope&) = delete;

 private:
  int m_saved = -1;  ///< previous max-active-levels, -1: nothing changed
};

}  // namespace deform
