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

}  // namespace deform
