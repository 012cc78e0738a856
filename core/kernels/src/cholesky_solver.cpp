#include <deform/kernels/cholesky_solver.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#if defined(__x86_64__) && defined(__GNUC__)
#include <cpuid.h>
#include <immintrin.h>
#endif

namespace deform {

namespace {

// ---- The preconditioner's copies of a supernodal factor -------------------------------------
// CHOLMOD's supernodal layout: supernode s holds columns super[s] .. super[s+1]-1 as a
// column-major block of nsrow rows (the rows listed at rows[pi[s]..], the first nscol of them the
// block's own columns, a dense lower triangle) at lx + px[s]. The float copy holds the values as
// they are; the half copy holds column j as L(:, j) / s_j in IEEE binary16, s_j the power of two
// at or above the column's largest magnitude (an exact scaling; every stored value in [-1, 1]).
// Both keep scale[k] = s_k (1 for the float copy) and dinv[k] = 1 / L(k, k).

/// IEEE binary16 from float, rounded to nearest even (what F16C's vcvtps2ph does).
uint16_t floatToHalf(float f) {
  uint32_t x;
  std::memcpy(&x, &f, 4);
  const uint32_t sign = (x >> 16) & 0x8000u, a = x & 0x7fffffffu;
  if (a >= 0x7f800000u) return uint16_t(sign | (a > 0x7f800000u ? 0x7e00u : 0x7c00u));
  if (a >= 0x477ff000u) return uint16_t(sign | 0x7c00u);  // 65520 and above round to infinity
  if (a < 0x38800000u) {  // below 2^-14: a subnormal half, f 2^24 rounded (the scaling is exact)
    float m;
    std::memcpy(&m, &a, 4);
    return uint16_t(sign | uint32_t(std::nearbyint(m * 16777216.0f)));
  }
  const uint32_t rounded = a + 0xfffu + ((a >> 13) & 1u);  // to nearest, ties to even
  return uint16_t(sign | ((rounded - (112u << 23)) >> 13));
}

/// float from IEEE binary16 (exact).
float halfToFloat(uint16_t h) {
  const uint32_t e = (h >> 10) & 0x1fu, m = h & 0x3ffu;
  float r;
  if (e == 0) {
    r = std::ldexp(float(m), -24);
  } else {
    const uint32_t x = e == 31 ? (0x7f800000u | (m << 13)) : (((e + 112u) << 23) | (m << 13));
    std::memcpy(&r, &x, 4);
  }
  return (h & 0x8000u) ? -r : r;
}

/// The column operations the solves are made of, for stored values of type Ops::Value:
///   one(c)                      c[0] as float
///   axpy(c, a, y, n)            y[i] += a c[i]
///   axpy4(c, stride, a, y, n)   y[i] += a[0] c0[i] + ... + a[3] c3[i], c_q = c + q stride
///   dot(c, x, n)                the sum of c[i] x[i]
///   dot4(c, stride, x, n, d)    d[q] = the sum of c_q[i] x[i]
/// for i < n. Float: plain loops the compiler vectorises for the CPU it targets.
struct FloatOps {
  using Value = float;
  __attribute__((always_inline)) static float one(const float* c) { return *c; }
  __attribute__((always_inline)) static void axpy(const float* c, float a, float* y, int n) {
#pragma omp simd
    for (int i = 0; i < n; ++i) y[i] += c[i] * a;
  }
  __attribute__((always_inline)) static void axpy4(const float* c0, int stride, const float* a,
                                                   float* y, int n) {
    const float *c1 = c0 + stride, *c2 = c1 + stride, *c3 = c2 + stride;
    const float a0 = a[0], a1 = a[1], a2 = a[2], a3 = a[3];
#pragma omp simd
    for (int i = 0; i < n; ++i) y[i] += c0[i] * a0 + c1[i] * a1 + c2[i] * a2 + c3[i] * a3;
  }
  __attribute__((always_inline)) static float dot(const float* c, const float* x, int n) {
    float s = 0;
#pragma omp simd reduction(+ : s)
    for (int i = 0; i < n; ++i) s += c[i] * x[i];
    return s;
  }
  __attribute__((always_inline)) static void dot4(const float* c0, int stride, const float* x,
                                                  int n, float* d) {
    const float *c1 = c0 + stride, *c2 = c1 + stride, *c3 = c2 + stride;
    float s0 = 0, s1 = 0, s2 = 0, s3 = 0;
#pragma omp simd reduction(+ : s0, s1, s2, s3)
    for (int i = 0; i < n; ++i) {
      s0 += c0[i] * x[i];
      s1 += c1[i] * x[i];
      s2 += c2[i] * x[i];
      s3 += c3[i] * x[i];
    }
    d[0] = s0, d[1] = s1, d[2] = s2, d[3] = s3;
  }
};

/// The half copy's operations on any CPU (halfToFloat one value at a time).
struct HalfOps {
  using Value = uint16_t;
  static float one(const uint16_t* c) { return halfToFloat(*c); }
  static void axpy(const uint16_t* c, float a, float* y, int n) {
    for (int i = 0; i < n; ++i) y[i] += one(c + i) * a;
  }
  static void axpy4(const uint16_t* c0, int stride, const float* a, float* y, int n) {
    const uint16_t *c1 = c0 + stride, *c2 = c1 + stride, *c3 = c2 + stride;
    for (int i = 0; i < n; ++i)
      y[i] += one(c0 + i) * a[0] + one(c1 + i) * a[1] + one(c2 + i) * a[2] + one(c3 + i) * a[3];
  }
  static float dot(const uint16_t* c, const float* x, int n) {
    float s = 0;
    for (int i = 0; i < n; ++i) s += one(c + i) * x[i];
    return s;
  }
  static void dot4(const uint16_t* c0, int stride, const float* x, int n, float* d) {
    for (int q = 0; q < 4; ++q) d[q] = dot(c0 + size_t(q) * size_t(stride), x, n);
  }
};

/// The dense triangle's columns are taken kTriangleBlock at a time: within a block one column
/// after the other (a dependent chain), between blocks four columns per pass like the rows below.
constexpr int kTriangleBlock = 8;

/// The two triangular solves of L L^T y = y in single precision. t: workspace of at least the
/// largest nsrow.
template <class Ops>
__attribute__((always_inline)) inline void supernodalSolve(const typename Ops::Value* lx,
                                                           const float* scale, const float* dinv,
                                                           const int* super, const int* pi,
                                                           const int* px, const int* rows,
                                                           int nsuper, float* y, float* t) {
  using V = typename Ops::Value;
  float a[4];
  for (int s = 0; s < nsuper; ++s) {  // L z = y
    const int k1 = super[s], nscol = super[s + 1] - k1;
    const int nsrow = pi[s + 1] - pi[s], below = nsrow - nscol;
    const V* L = lx + px[s];
    const float *sc = scale + k1, *di = dinv + k1;
    const int* r = rows + pi[s] + nscol;
    float* X = y + k1;
    const auto col = [&](int j) { return L + size_t(j) * size_t(nsrow); };
    for (int j0 = 0; j0 < nscol; j0 += kTriangleBlock) {
      const int j1 = std::min(nscol, j0 + kTriangleBlock);
      for (int j = j0; j < j1; ++j) {
        X[j] *= di[j];
        const float xs = -sc[j] * X[j];
        for (int i = j + 1; i < j1; ++i) X[i] += Ops::one(col(j) + i) * xs;
      }
      // The rows of the triangle below the block.
      int j = j0;
      for (; j + 4 <= j1; j += 4) {
        for (int q = 0; q < 4; ++q) a[q] = -sc[j + q] * X[j + q];
        Ops::axpy4(col(j) + j1, nsrow, a, X + j1, nscol - j1);
      }
      for (; j < j1; ++j) Ops::axpy(col(j) + j1, -sc[j] * X[j], X + j1, nscol - j1);
    }
    // t = L21 X, four columns per pass over t, then scattered to the rows it belongs to.
    std::fill(t, t + below, 0.0f);
    int j = 0;
    for (; j + 4 <= nscol; j += 4) {
      for (int q = 0; q < 4; ++q) a[q] = sc[j + q] * X[j + q];
      Ops::axpy4(col(j) + nscol, nsrow, a, t, below);
    }
    for (; j < nscol; ++j) Ops::axpy(col(j) + nscol, sc[j] * X[j], t, below);
    for (int i = 0; i < below; ++i) y[r[i]] -= t[i];
  }
  for (int s = nsuper - 1; s >= 0; --s) {  // L^T x = z
    const int k1 = super[s], nscol = super[s + 1] - k1;
    const int nsrow = pi[s + 1] - pi[s], below = nsrow - nscol;
    const V* L = lx + px[s];
    const float *sc = scale + k1, *di = dinv + k1;
    const int* r = rows + pi[s] + nscol;
    float* X = y + k1;
    const auto col = [&](int j) { return L + size_t(j) * size_t(nsrow); };
    // X -= L21^T t, four columns per pass over t.
    for (int i = 0; i < below; ++i) t[i] = y[r[i]];
    int j = 0;
    for (; j + 4 <= nscol; j += 4) {
      Ops::dot4(col(j) + nscol, nsrow, t, below, a);
      for (int q = 0; q < 4; ++q) X[j + q] -= sc[j + q] * a[q];
    }
    for (; j < nscol; ++j) X[j] -= sc[j] * Ops::dot(col(j) + nscol, t, below);
    // The triangle, its last block first.
    for (int j0 = (nscol - 1) / kTriangleBlock * kTriangleBlock; j0 >= 0; j0 -= kTriangleBlock) {
      const int j1 = std::min(nscol, j0 + kTriangleBlock);
      for (j = j0; j + 4 <= j1; j += 4) {  // the rows below the block
        Ops::dot4(col(j) + j1, nsrow, X + j1, nscol - j1, a);
        for (int q = 0; q < 4; ++q) X[j + q] -= sc[j + q] * a[q];
      }
      for (; j < j1; ++j) X[j] -= sc[j] * Ops::dot(col(j) + j1, X + j1, nscol - j1);
      for (j = j1 - 1; j >= j0; --j) {
        float sum = 0;
        for (int i = j + 1; i < j1; ++i) sum += Ops::one(col(j) + i) * X[i];
        X[j] = (X[j] - sc[j] * sum) * di[j];
      }
    }
  }
}

#if defined(__x86_64__) && defined(__GNUC__)
#define DEFORM_F16C __attribute__((target("avx2,f16c"))) inline

/// HalfOps on AVX2 lanes, F16C converting eight halves to eight floats at once.
struct HalfF16cOps {
  using Value = uint16_t;
  DEFORM_F16C static float one(const uint16_t* p) { return _cvtsh_ss(*p); }
  DEFORM_F16C static __m256 eight(const uint16_t* p) {
    return _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(p)));
  }
  DEFORM_F16C static float sum(__m256 v) {
    __m128 s = _mm_add_ps(_mm256_castps256_ps128(v), _mm256_extractf128_ps(v, 1));
    s = _mm_add_ps(s, _mm_movehl_ps(s, s));
    s = _mm_add_ss(s, _mm_movehdup_ps(s));
    return _mm_cvtss_f32(s);
  }
  DEFORM_F16C static void axpy(const uint16_t* c, float a, float* y, int n) {
    const __m256 va = _mm256_set1_ps(a);
    int i = 0;
    for (; i + 8 <= n; i += 8)
      _mm256_storeu_ps(y + i,
                       _mm256_add_ps(_mm256_loadu_ps(y + i), _mm256_mul_ps(eight(c + i), va)));
    for (; i < n; ++i) y[i] += one(c + i) * a;
  }
  DEFORM_F16C static void axpy4(const uint16_t* c0, int stride, const float* a, float* y, int n) {
    const uint16_t *c1 = c0 + stride, *c2 = c1 + stride, *c3 = c2 + stride;
    const __m256 v0 = _mm256_set1_ps(a[0]), v1 = _mm256_set1_ps(a[1]), v2 = _mm256_set1_ps(a[2]),
                 v3 = _mm256_set1_ps(a[3]);
    int i = 0;
    for (; i + 8 <= n; i += 8) {
      const __m256 s01 =
          _mm256_add_ps(_mm256_mul_ps(eight(c0 + i), v0), _mm256_mul_ps(eight(c1 + i), v1));
      const __m256 s23 =
          _mm256_add_ps(_mm256_mul_ps(eight(c2 + i), v2), _mm256_mul_ps(eight(c3 + i), v3));
      _mm256_storeu_ps(y + i, _mm256_add_ps(_mm256_loadu_ps(y + i), _mm256_add_ps(s01, s23)));
    }
    for (; i < n; ++i)
      y[i] += one(c0 + i) * a[0] + one(c1 + i) * a[1] + one(c2 + i) * a[2] + one(c3 + i) * a[3];
  }
  DEFORM_F16C static float dot(const uint16_t* c, const float* x, int n) {
    __m256 acc = _mm256_setzero_ps();
    int i = 0;
    for (; i + 8 <= n; i += 8)
      acc = _mm256_add_ps(acc, _mm256_mul_ps(eight(c + i), _mm256_loadu_ps(x + i)));
    float s = sum(acc);
    for (; i < n; ++i) s += one(c + i) * x[i];
    return s;
  }
  DEFORM_F16C static void dot4(const uint16_t* c0, int stride, const float* x, int n, float* d) {
    const uint16_t *c1 = c0 + stride, *c2 = c1 + stride, *c3 = c2 + stride;
    __m256 s0 = _mm256_setzero_ps(), s1 = s0, s2 = s0, s3 = s0;
    int i = 0;
    for (; i + 8 <= n; i += 8) {
      const __m256 xi = _mm256_loadu_ps(x + i);
      s0 = _mm256_add_ps(s0, _mm256_mul_ps(eight(c0 + i), xi));
      s1 = _mm256_add_ps(s1, _mm256_mul_ps(eight(c1 + i), xi));
      s2 = _mm256_add_ps(s2, _mm256_mul_ps(eight(c2 + i), xi));
      s3 = _mm256_add_ps(s3, _mm256_mul_ps(eight(c3 + i), xi));
    }
    d[0] = sum(s0), d[1] = sum(s1), d[2] = sum(s2), d[3] = sum(s3);
    for (; i < n; ++i) {
      d[0] += one(c0 + i) * x[i], d[1] += one(c1 + i) * x[i];
      d[2] += one(c2 + i) * x[i], d[3] += one(c3 + i) * x[i];
    }
  }
};

__attribute__((target("avx2"))) void solveFloatAvx2(const float* lx, const float* scale,
                                                    const float* dinv, const int* super,
                                                    const int* pi, const int* px, const int* rows,
                                                    int nsuper, float* y, float* t) {
  supernodalSolve<FloatOps>(lx, scale, dinv, super, pi, px, rows, nsuper, y, t);
}

__attribute__((target("avx2,f16c"))) void solveHalfF16c(const uint16_t* lx, const float* scale,
                                                        const float* dinv, const int* super,
                                                        const int* pi, const int* px,
                                                        const int* rows, int nsuper, float* y,
                                                        float* t) {
  supernodalSolve<HalfF16cOps>(lx, scale, dinv, super, pi, px, rows, nsuper, y, t);
}

/// n floats to halves, eight at a time (rounded to nearest even, as floatToHalf).
__attribute__((target("avx2,f16c"))) void toHalfF16c(const float* in, size_t n, uint16_t* out) {
  size_t i = 0;
  for (; i + 8 <= n; i += 8)
    _mm_storeu_si128(reinterpret_cast<__m128i*>(out + i),
                     _mm256_cvtps_ph(_mm256_loadu_ps(in + i), _MM_FROUND_TO_NEAREST_INT));
  for (; i < n; ++i) out[i] = floatToHalf(in[i]);
}
#endif

void solveFloatPortable(const float* lx, const float* scale, const float* dinv, const int* super,
                        const int* pi, const int* px, const int* rows, int nsuper, float* y,
                        float* t) {
  supernodalSolve<FloatOps>(lx, scale, dinv, super, pi, px, rows, nsuper, y, t);
}

void solveHalfPortable(const uint16_t* lx, const float* scale, const float* dinv, const int* super,
                       const int* pi, const int* px, const int* rows, int nsuper, float* y,
                       float* t) {
  supernodalSolve<HalfOps>(lx, scale, dinv, super, pi, px, rows, nsuper, y, t);
}

bool haveAvx2() {
#if defined(__x86_64__) && defined(__GNUC__)
  static const bool yes = __builtin_cpu_supports("avx2");
  return yes;
#else
  return false;
#endif
}

bool haveF16c() {
#if defined(__x86_64__) && defined(__GNUC__)
  // F16C is CPUID leaf 1, ECX bit 29 (clang's __builtin_cpu_supports has no name for it).
  static const bool yes = [] {
    unsigned a = 0, b = 0, c = 0, d = 0;
    return haveAvx2() && __get_cpuid(1, &a, &b, &c, &d) && (c & bit_F16C) != 0;
  }();
  return yes;
#else
  return false;
#endif
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

bool CholeskySolver::buildFloatFactor(Precision precision) {
  m_lf.clear();
  m_lh.clear();
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
  int widest = 0;
  for (int s = 0; s < nsuper; ++s) widest = std::max(widest, m_pi[size_t(s) + 1] - m_pi[size_t(s)]);
  m_scale.assign(L->n, 1.0f);
  m_dinv.assign(L->n, 1.0f);
  if (precision == Precision::Float32) {
    m_lf.assign(x, x + m_px.back());
  } else {
    // Rows j.. of each column (the rows above are the block's unused upper triangle, stored as
    // zero), scaled by a power of two to at most 1 in magnitude.
    m_lh.assign(size_t(m_px.back()), 0);
    std::vector<float> column(static_cast<size_t>(widest));
    for (int s = 0; s < nsuper; ++s) {
      const int k1 = m_super[size_t(s)], nscol = m_super[size_t(s) + 1] - k1;
      const int nsrow = m_pi[size_t(s) + 1] - m_pi[size_t(s)];
      for (int j = 0; j < nscol; ++j) {
        const size_t at = size_t(m_px[size_t(s)]) + size_t(j) * size_t(nsrow) + size_t(j);
        const int count = nsrow - j;
        double largest = 0;
        for (int i = 0; i < count; ++i) largest = std::max(largest, std::abs(x[at + size_t(i)]));
        int e = 0;
        std::frexp(largest, &e);  // largest = m 2^e with m in [0.5, 1)
        const double scale = largest > 0 && std::isfinite(largest) ? std::ldexp(1.0, e) : 1.0;
        m_scale[size_t(k1 + j)] = static_cast<float>(scale);
        for (int i = 0; i < count; ++i) column[size_t(i)] = float(x[at + size_t(i)] / scale);
#if defined(__x86_64__) && defined(__GNUC__)
        if (haveF16c()) {
          toHalfF16c(column.data(), size_t(count), m_lh.data() + at);
          continue;
        }
#endif
        for (int i = 0; i < count; ++i) m_lh[at + size_t(i)] = floatToHalf(column[size_t(i)]);
      }
    }
  }
  // The reciprocal diagonal of the copy as stored (the solves multiply by it).
  for (int s = 0; s < nsuper; ++s) {
    const int k1 = m_super[size_t(s)], nscol = m_super[size_t(s) + 1] - k1;
    const int nsrow = m_pi[size_t(s) + 1] - m_pi[size_t(s)];
    for (int j = 0; j < nscol; ++j) {
      const size_t at = size_t(m_px[size_t(s)]) + size_t(j) * size_t(nsrow) + size_t(j);
      const float d = m_lh.empty() ? m_lf[at] : m_scale[size_t(k1 + j)] * halfToFloat(m_lh[at]);
      m_dinv[size_t(k1 + j)] = 1.0f / d;
    }
  }
  m_t.assign(size_t(widest), 0.0f);
  m_y.assign(L->n, 0.0f);
  return true;
}

void CholeskySolver::solveFloatInto(const VecX& b, VecX& x, bool portable) {
  // L L^T = P A P^T with (P A P^T)(i, j) = A(perm[i], perm[j]).
  const size_t n = m_perm.size();
  for (size_t k = 0; k < n; ++k) m_y[k] = static_cast<float>(b[m_perm[k]]);
  const int nsuper = static_cast<int>(m_super.size()) - 1;
  const auto run = [&](auto kernel, const auto* values) {
    kernel(values, m_scale.data(), m_dinv.data(), m_super.data(), m_pi.data(), m_px.data(),
           m_rows.data(), nsuper, m_y.data(), m_t.data());
  };
  const bool vector = !portable;
#if !(defined(__x86_64__) && defined(__GNUC__))
  const auto solveHalfF16c = solveHalfPortable;
  const auto solveFloatAvx2 = solveFloatPortable;
#endif
  if (!m_lh.empty()) {
    run(vector && haveF16c() ? solveHalfF16c : solveHalfPortable, m_lh.data());
  } else {
    run(vector && haveAvx2() ? solveFloatAvx2 : solveFloatPortable, m_lf.data());
  }
  x.resize(b.size());
  for (size_t k = 0; k < n; ++k) x[m_perm[k]] = m_y[k];
}

uint16_t CholeskySolver::toHalf(float f) {
  return floatToHalf(f);
}
float CholeskySolver::fromHalf(uint16_t h) {
  return halfToFloat(h);
}
bool CholeskySolver::halfIsFast() {
  return haveF16c();
}

}  // namespace deform
