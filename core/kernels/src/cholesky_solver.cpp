#include <deform/kernels/cholesky_solver.h>

#include <algorithm>
#include <cstring>

namespace deform {

namespace {

/// The two triangular solves of L L^T y = y on CHOLMOD's supernodal layout, in float. Supernode
/// s holds columns super[s] .. super[s+1]-1 as a column-major block of nsrow rows (the rows
/// listed at rows[pi[s]..], the first nscol of them the block's own columns) at lx + px[s].
/// t: workspace of at least the largest nsrow.
__attribute__((always_inline)) inline void supernodalSolveF(const float* lx, const int* super,
                                                            const int* pi, const int* px,
                                                            const int* rows, int nsuper, float* y,
                                                            float* t) {
  for (int s = 0; s < nsuper; ++s) {  // L z = y
    const int k1 = super[s], nscol = super[s + 1] - k1;
    const int nsrow = pi[s + 1] - pi[s], below = nsrow - nscol;
    const float* L = lx + px[s];
    const int* r = rows + pi[s] + nscol;
    float* X = y + k1;
    for (int j = 0; j < nscol; ++j) {
      const float* col = L + size_t(j) * size_t(nsrow);
      X[j] /= col[j];
      const float xj = X[j];
      for (int i = j + 1; i < nscol; ++i) X[i] -= col[i] * xj;
    }
    // t = L21 X, four columns per pass over t.
    std::fill(t, t + below, 0.0f);
    int j = 0;
    for (; j + 4 <= nscol; j += 4) {
      const float* c0 = L + size_t(j) * size_t(nsrow) + nscol;
      const float *c1 = c0 + nsrow, *c2 = c1 + nsrow, *c3 = c2 + nsrow;
      const float x0 = X[j], x1 = X[j + 1], x2 = X[j + 2], x3 = X[j + 3];
#pragma omp simd
      for (int i = 0; i < below; ++i) t[i] += c0[i] * x0 + c1[i] * x1 + c2[i] * x2 + c3[i] * x3;
    }
    for (; j < nscol; ++j) {
      const float* col = L + size_t(j) * size_t(nsrow) + nscol;
      const float xj = X[j];
#pragma omp simd
      for (int i = 0; i < below; ++i) t[i] += col[i] * xj;
    }
    for (int i = 0; i < below; ++i) y[r[i]] -= t[i];
  }
  for (int s = nsuper - 1; s >= 0; --s) {  // L^T x = z
    const int k1 = super[s], nscol = super[s + 1] - k1;
    const int nsrow = pi[s + 1] - pi[s], below = nsrow - nscol;
    const float* L = lx + px[s];
    const int* r = rows + pi[s] + nscol;
    float* X = y + k1;
    for (int i = 0; i < below; ++i) t[i] = y[r[i]];
    // X -= L21^T t, four columns per pass over t.
    int j = 0;
    for (; j + 4 <= nscol; j += 4) {
      const float* c0 = L + size_t(j) * size_t(nsrow) + nscol;
      const float *c1 = c0 + nsrow, *c2 = c1 + nsrow, *c3 = c2 + nsrow;
      float s0 = 0, s1 = 0, s2 = 0, s3 = 0;
#pragma omp simd reduction(+ : s0, s1, s2, s3)
      for (int i = 0; i < below; ++i) {
        s0 += c0[i] * t[i];
        s1 += c1[i] * t[i];
        s2 += c2[i] * t[i];
        s3 += c3[i] * t[i];
      }
      X[j] -= s0;
      X[j + 1] -= s1;
      X[j + 2] -= s2;
      X[j + 3] -= s3;
    }
    for (; j < nscol; ++j) {
      const float* col = L + size_t(j) * size_t(nsrow) + nscol;
      float sum = 0;
#pragma omp simd reduction(+ : sum)
      for (int i = 0; i < below; ++i) sum += col[i] * t[i];
      X[j] -= sum;
    }
    for (j = nscol - 1; j >= 0; --j) {
      const float* col = L + size_t(j) * size_t(nsrow);
      float sum = 0;
#pragma omp simd reduction(+ : sum)
      for (int i = j + 1; i < nscol; ++i) sum += col[i] * X[i];
      X[j] = (X[j] - sum) / col[j];
    }
  }
}

#if defined(__x86_64__) && defined(__GNUC__)
__attribute__((target("avx2"))) void supernodalSolveAvx2(const float* lx, const int* super,
                                                         const int* pi, const int* px,
                                                         const int* rows, int nsuper, float* y,
                                                         float* t) {
  supernodalSolveF(lx, super, pi, px, rows, nsuper, y, t);
}
#endif

void supernodalSolve(const float* lx, const int* super, const int* pi, const int* px,
                     const int* rows, int nsuper, float* y, float* t) {
#if defined(__x86_64__) && defined(__GNUC__)
  static const bool kAvx2 = __builtin_cpu_supports("avx2");
  if (kAvx2) return supernodalSolveAvx2(lx, super, pi, px, rows, nsuper, y, t);
#endif
  supernodalSolveF(lx, super, pi, px, rows, nsuper, y, t);
}

}  // namespace

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

bool CholeskySolver::buildFloatFactor() {
  m_lf.clear();
  const cholmod_factor* L = m_cholmodFactor;
  if (!L || !m_factorizationIsOk || !L->is_super || !L->is_ll || L->itype != CHOLMOD_INT ||
      L->xtype != CHOLMOD_REAL)
    return false;
  const int nsuper = static_cast<int>(L->nsuper);
  const auto copy = [](const void* p, size_t n, std::vector<int>& out) {
    const int* a = static_cast<const int*>(p);
    out.assign(a, a + n);
  };
  copy(L->super, size_t(nsuper) + 1, m_super);
  copy(L->pi, size_t(nsuper) + 1, m_pi);
  copy(L->px, size_t(nsuper) + 1, m_px);
  copy(L->s, size_t(m_pi.back()), m_rows);
  copy(L->Perm, L->n, m_perm);
  const double* x = static_cast<const double*>(L->x);
  m_lf.assign(x, x + m_px.back());
  int widest = 0;
  for (int s = 0; s < nsuper; ++s) widest = std::max(widest, m_pi[size_t(s) + 1] - m_pi[size_t(s)]);
  m_t.assign(size_t(widest), 0.0f);
  m_y.assign(L->n, 0.0f);
  return true;
}

void CholeskySolver::solveFloatInto(const VecX& b, VecX& x) {
  // L L^T = P A P^T with (P A P^T)(i, j) = A(perm[i], perm[j]).
  const size_t n = m_perm.size();
  for (size_t k = 0; k < n; ++k) m_y[k] = static_cast<float>(b[m_perm[k]]);
  supernodalSolve(m_lf.data(), m_super.data(), m_pi.data(), m_px.data(), m_rows.data(),
                  static_cast<int>(m_super.size()) - 1, m_y.data(), m_t.data());
  x.resize(b.size());
  for (size_t k = 0; k < n; ++k) x[m_perm[k]] = m_y[k];
}

}  // namespace deform
