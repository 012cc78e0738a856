#include "node_cholesky.h"

#include <algorithm>
#include <stdexcept>

namespace deform::massspring {

// Eigen's CHOLMOD wrapper keeps the factor protected; this gives NodeCholesky read access.
struct NodeCholesky::Cholmod : SparseCholesky {
  cholmod_factor* factor() { return m_cholmodFactor; }
};

namespace {

// may_alias: the rows are std::vector<Row4> storage, read and written through this type.
using V4 = double __attribute__((vector_size(32), may_alias));

// Forward (L y = b) then backward (L^T x = y) substitution, supernode by supernode, on rows of
// four doubles (the factor's values in float, widened as they are read). Per supernode: the
// strictly lower part of its diagonal block packed by rows (row j holds j values), then the
// rows below the block, w values each. No fused multiply-add on any path, so the AVX2 and the
// generic build agree bit for bit.
__attribute__((always_inline)) inline void substitute(V4* z, const NodeCholesky::Supernode* sn,
                                                      int nsuper, const int* rowIndex,
                                                      const float* val, const double* invDiag) {
  for (int s = 0; s < nsuper; ++s) {
    const int w = sn[s].width;
    V4* zc = z + sn[s].col;
    const double* id = invDiag + sn[s].col;
    const float* D = val + sn[s].values;
    for (int j = 0; j < w; ++j) {
      const float* Dj = D + j * (j - 1) / 2;
      V4 acc = zc[j];
      for (int i = 0; i < j; ++i) acc -= double(Dj[i]) * zc[i];
      zc[j] = acc * id[j];
    }
    const float* B = D + w * (w - 1) / 2;
    const int* rows = rowIndex + sn[s].rows;
    // z[rows[r]] -= sum_j B[r][j] zc[j], four rows at a time (each zc[j] loaded once for them).
    const int below = sn[s].below;
    int r = 0;
    for (; r + 4 <= below; r += 4) {
      const float* B0 = B + static_cast<long>(r) * w;
      const float* B1 = B0 + w;
      const float* B2 = B1 + w;
      const float* B3 = B2 + w;
      V4 a0 = {0, 0, 0, 0}, a1 = a0, a2 = a0, a3 = a0;
      for (int j = 0; j < w; ++j) {
        const V4 zj = zc[j];
        a0 += double(B0[j]) * zj;
        a1 += double(B1[j]) * zj;
        a2 += double(B2[j]) * zj;
        a3 += double(B3[j]) * zj;
      }
      z[rows[r]] -= a0;
      z[rows[r + 1]] -= a1;
      z[rows[r + 2]] -= a2;
      z[rows[r + 3]] -= a3;
    }
    for (; r < below; ++r) {
      const float* Br = B + static_cast<long>(r) * w;
      V4 acc = {0, 0, 0, 0};
      for (int j = 0; j < w; ++j) acc += double(Br[j]) * zc[j];
      z[rows[r]] -= acc;
    }
  }
  for (int s = nsuper - 1; s >= 0; --s) {
    const int w = sn[s].width, below = sn[s].below;
    V4* zc = z + sn[s].col;
    const double* id = invDiag + sn[s].col;
    const float* D = val + sn[s].values;
    const float* B = D + w * (w - 1) / 2;
    const int* rows = rowIndex + sn[s].rows;
    // zc[j] -= sum_r B[r][j] z[rows[r]], four columns at a time (accumulators in registers,
    // each z[rows[r]] loaded once for them).
    int j0 = 0;
    for (; j0 + 4 <= w; j0 += 4) {
      V4 a0 = {0, 0, 0, 0}, a1 = a0, a2 = a0, a3 = a0;
      for (int r = 0; r < below; ++r) {
        const float* Br = B + static_cast<long>(r) * w + j0;
        const V4 zr = z[rows[r]];
        a0 += double(Br[0]) * zr;
        a1 += double(Br[1]) * zr;
        a2 += double(Br[2]) * zr;
        a3 += double(Br[3]) * zr;
      }
      zc[j0] -= a0;
      zc[j0 + 1] -= a1;
      zc[j0 + 2] -= a2;
      zc[j0 + 3] -= a3;
    }
    for (; j0 < w; ++j0) {
      V4 a0 = {0, 0, 0, 0};
      for (int r = 0; r < below; ++r) a0 += double(B[static_cast<long>(r) * w + j0]) * z[rows[r]];
      zc[j0] -= a0;
    }
    for (int j = w - 1; j >= 0; --j) {
      const V4 zj = zc[j] * id[j];
      zc[j] = zj;
      const float* Dj = D + j * (j - 1) / 2;
      for (int i = 0; i < j; ++i) zc[i] -= double(Dj[i]) * zj;
    }
  }
}

__attribute__((target("avx2"))) void substituteAvx2(V4* z, const NodeCholesky::Supernode* sn,
                                                    int nsuper, const int* rowIndex,
                                                    const float* val, const double* invDiag) {
  substitute(z, sn, nsuper, rowIndex, val, invDiag);
}

void substituteGeneric(V4* z, const NodeCholesky::Supernode* sn, int nsuper, const int* rowIndex,
                       const float* val, const double* invDiag) {
  substitute(z, sn, nsuper, rowIndex, val, invDiag);
}

const char* orderingName(int ordering) {
  switch (ordering) {
    case CHOLMOD_NATURAL:
      return "natural";
    case CHOLMOD_GIVEN:
      return "given";
    case CHOLMOD_AMD:
      return "amd";
    case CHOLMOD_METIS:
      return "metis";
    case CHOLMOD_NESDIS:
      return "nesdis";
    case CHOLMOD_COLAMD:
      return "colamd";
    default:
      return "unknown";
  }
}

}  // namespace

NodeCholesky::NodeCholesky() = default;
NodeCholesky::~NodeCholesky() = default;

void NodeCholesky::factor(const SparseMatrix& A) {
  if (!m_cholmod) {
    installCholmodAllocator();
    m_cholmod = std::make_unique<Cholmod>();
    // Every ordering CHOLMOD has (AMD, METIS, nested dissection with several settings), keeping
    // the one with the least fill: on the 8k liver's springs AMD gives nnz(L) = 0.98 M, nested
    // dissection 0.67 M. The analysis runs once per pattern.
    m_cholmod->cholmod().nmethods = CHOLMOD_MAXMETHODS;
    SerialOpenMpScope serial;
    m_cholmod->analyzePattern(A);
  }
  {
    SerialOpenMpScope serial;
    m_cholmod->factorize(A);
  }
  if (m_cholmod->info() != Eigen::Success)
    throw std::runtime_error("NodeCholesky: the matrix is not positive definite");
  const cholmod_factor* F = m_cholmod->factor();
  if (!F->is_super || !F->is_ll || F->xtype != CHOLMOD_REAL)
    throw std::runtime_error("NodeCholesky: expected a real supernodal LL^T factor from CHOLMOD");
  const int n = static_cast<int>(F->n);
  const int nsuper = static_cast<int>(F->nsuper);
  const int* super = static_cast<const int*>(F->super);
  const int* pi = static_cast<const int*>(F->pi);
  const int* px = static_cast<const int*>(F->px);
  const int* ls = static_cast<const int*>(F->s);
  const double* lx = static_cast<const double*>(F->x);
  const int* perm = static_cast<const int*>(F->Perm);
  m_ordering = orderingName(F->ordering);
  m_perm.assign(perm, perm + n);
  m_invDiag.resize(n);
  m_super.resize(nsuper);
  m_row.clear();
  m_val.clear();
  m_nonZeros = 0;
  for (int s = 0; s < nsuper; ++s) {
    const int k1 = super[s], w = super[s + 1] - k1;
    const int nrow = pi[s + 1] - pi[s], below = nrow - w;
    const double* x = lx + px[s];  // column-major nrow x w, leading dimension nrow
    m_super[s] = {k1, w, below, static_cast<int>(m_row.size()), static_cast<long>(m_val.size())};
    for (int j = 0; j < w; ++j) {
      m_invDiag[k1 + j] = 1.0 / x[j + static_cast<long>(j) * nrow];
      for (int i = 0; i < j; ++i) m_val.push_back(static_cast<float>(x[j + long(i) * nrow]));
    }
    for (int r = 0; r < below; ++r) {
      m_row.push_back(ls[pi[s] + w + r]);
      for (int j = 0; j < w; ++j) m_val.push_back(static_cast<float>(x[w + r + long(j) * nrow]));
    }
    m_nonZeros += static_cast<long long>(w) * (w + 1) / 2 + static_cast<long long>(below) * w;
  }
}

void NodeCholesky::solveInPlace(Row4* Z) const {
  static const bool kAvx2 = __builtin_cpu_supports("avx2");
  static_assert(sizeof(Row4) == sizeof(V4) && alignof(Row4) >= alignof(V4));
  V4* z = reinterpret_cast<V4*>(Z);
  (kAvx2 ? substituteAvx2 : substituteGeneric)(z, m_super.data(), static_cast<int>(m_super.size()),
                                               m_row.data(), m_val.data(), m_invDiag.data());
}

}  // namespace deform::massspring
