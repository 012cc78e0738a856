// Scalar path and dispatch of explicit_rows.h (compiled with -ffp-contract=off, like the AVX2 and
// AVX-512 units, so that all round alike).
#include "explicit_rows.h"

#include <cmath>
#include <limits>

#if defined(__x86_64__) && defined(__GNUC__)
#define DEFORM_MS_HAVE_AVX512 1
#endif

namespace deform::massspring::rows {

namespace {

constexpr double kTiny2 = 1e-12 * 1e-12;  // tol::kDegenerateLength^2

void addSpringForcesScalar(const double* xv, const SpringArrays& s, std::size_t begin, double* f4,
                           long long* degenerate) {
  for (std::size_t i = begin; i < s.n; ++i) {
    const double* xa = xv + s.a[i];
    const double* xb = xv + s.b[i];
    const double d0 = xb[0] - xa[0], d1 = xb[1] - xa[1], d2 = xb[2] - xa[2];
    const double l2 = d0 * d0 + d1 * d1 + d2 * d2;
    if (l2 <= kTiny2) [[unlikely]] {
      ++*degenerate;
      continue;
    }
    const double l = std::sqrt(l2);
    const double il = 1.0 / l;
    const double vn = ((xb[4] - xa[4]) * d0 + (xb[5] - xa[5]) * d1 + (xb[6] - xa[6]) * d2) * il;
    const double m = (s.k[i] * (l - s.rest[i]) + s.c[i] * vn) * il;
    addSpringPair(f4 + s.a[i] / 2, f4 + s.b[i] / 2, m, d0, d1, d2);
  }
}

bool integrateScalar(double* xv, const double* f4, std::size_t n, const IntegrateArgs& p) {
  const double vmax = std::numeric_limits<double>::max();
  int ok = 1;
  for (std::size_t i = 0; i < n; ++i) {
    double* X = xv + 8 * i;
    double* V = X + 4;
    const double* F = f4 + 4 * i;
    const double w = p.w[i];
    for (int k = 0; k < 3; ++k) {
      if (w != 0.0) {
        const double a = F[k] * w + p.g[k] - p.alpha * V[k];
        if (p.symplectic) {
          V[k] += p.h * a;
          X[k] += p.h * V[k];
        } else {
          X[k] += p.h * V[k];
          V[k] += p.h * a;
        }
      }
      ok &= static_cast<int>(std::abs(X[k] - p.c[k]) <= p.half) &
            static_cast<int>(std::abs(V[k]) <= vmax);
    }
  }
  return ok != 0;
}

}  // namespace

Simd simdPath() {
#ifdef DEFORM_MS_HAVE_AVX512
  static const Simd kPath = __builtin_cpu_supports("avx512f") &&
                                    __builtin_cpu_supports("avx512vl") &&
                                    __builtin_cpu_supports("avx512dq")
                                ? Simd::Avx512
                            : __builtin_cpu_supports("avx2") ? Simd::Avx2
                                                             : Simd::Scalar;
  return kPath;
#else
  return Simd::Scalar;
#endif
}

long long addSpringForces(const double* xv, const SpringArrays& s, double* f4, Simd path) {
  long long degenerate = 0;
  std::size_t done = 0;
#ifdef DEFORM_MS_HAVE_AVX512
  if (path == Simd::Avx512) done = detail::addSpringForcesAvx512(xv, s, f4, &degenerate);
  if (path == Simd::Avx2) done = detail::addSpringForcesAvx2(xv, s, f4, &degenerate);
#else
  (void)path;
#endif
  addSpringForcesScalar(xv, s, done, f4, &degenerate);
  return degenerate;
}

long long addSpringForces(const double* xv, const SpringArrays& s, double* f4, bool simd) {
  return addSpringForces(xv, s, f4, simd ? simdPath() : Simd::Scalar);
}

bool integrate(double* xv, const double* f4, std::size_t n, const IntegrateArgs& args, Simd path) {
#ifdef DEFORM_MS_HAVE_AVX512
  // The update is four-wide either way: the AVX2 body serves AVX-512 CPUs too.
  if (path != Simd::Scalar) return detail::integrateAvx2(xv, f4, n, args);
#else
  (void)path;
#endif
  return integrateScalar(xv, f4, n, args);
}

bool integrate(double* xv, const double* f4, std::size_t n, const IntegrateArgs& args, bool simd) {
  return integrate(xv, f4, n, args, simd ? simdPath() : Simd::Scalar);
}

}  // namespace deform::massspring::rows
