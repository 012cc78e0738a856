#include "cholesky_solver.h"

#include <cstring>

namespace deform::fem_hex {

CholeskySolver::~CholeskySolver() {
  // Before the base class calls cholmod_finish on the common object.
  if (m_X) cholmod_free_dense(&m_X, &cholmod());
  if (m_Y) cholmod_free_dense(&m_Y, &cholmod());
  if (m_E) cholmod_free_dense(&m_E, &cholmod());
}

void CholeskySolver::setKind(Kind kind) {
  cholmod().supernodal = kind == Kind::Simplicial   ? CHOLMOD_SIMPLICIAL
                         : kind == Kind::Supernodal ? CHOLMOD_SUPERNODAL
                                                    : CHOLMOD_AUTO;
  // Retuned for OpenBLAS (libopenblas0-serial, Debian's BLAS here; the earlier 500 was for the
  // reference BLAS). bench_fem_hex on the liver phantom, median CPU per step, simplicial vs
  // supernodal: ties at 104 and 300 hexahedra (flops / nnz(L) = 69, 136), supernodal 10-18% faster
  // at 967-1000 (~250), 35% at 3000 (~490), and its refactorisation 4x faster at 967. So
  // supernodal wherever CHOLMOD's own default switch (40) puts it.
  cholmod().supernodal_switch = 40;
}

bool CholeskySolver::isSupernodal() const {
  return m_cholmodFactor && m_cholmodFactor->is_super;
}

bool CholeskySolver::solveInto(const VecX& b, VecX& x) {
  if (!m_cholmodFactor || !m_factorizationIsOk) return false;
  cholmod_dense B;
  std::memset(&B, 0, sizeof(B));
  B.nrow = static_cast<size_t>(b.size());
  B.ncol = 1;
  B.nzmax = B.nrow;
  B.d = B.nrow;
  B.x = const_cast<Real*>(b.data());
  B.xtype = CHOLMOD_REAL;
  B.dtype = CHOLMOD_DOUBLE;
  if (!cholmod_solve2(CHOLMOD_A, m_cholmodFactor, &B, nullptr, &m_X, nullptr, &m_Y, &m_E,
                      &cholmod())) {
    return false;
  }
  x.resize(b.size());
  std::memcpy(x.data(), m_X->x, sizeof(Real) * static_cast<size_t>(b.size()));
  return true;
}

}  // namespace deform::fem_hex
