#include <deform/kernels/isometric_bending.h>
#include <deform/kernels/simd_lanes.h>

#include <algorithm>
#include <cmath>
#include <type_traits>

#include "isometric_bending_math.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include "isometric_bending_avx2.h"
#define DEFORM_ISO_HAVE_AVX2 1
#endif

namespace deform::pbd {

namespace {

// cot of the angle at q between the edges to u and v.
Real cotAt(const Vec3& q, const Vec3& u, const Vec3& v) {
  const Vec3 a = u - q, b = v - q;
  return a.dot(b) / a.cross(b).norm();
}

// v and |v| (see the header comment); false when |v| = 0.
bool stencil(const Vec3 x[4], const Real K[4], Vec3& v, Real& len) {
  v = K[0] * x[0] + K[1] * x[1] + K[2] * x[2] + K[3] * x[3];
  len = v.norm();
  return len * len > tol::kDegenerateLength * tol::kDegenerateLength;
}

template <class T>
long long run(T* x4, const IsometricBatch<T>& b, size_t begin, size_t end, T* measure, bool simd) {
  const isobatch::View<T>& v = b;
  long long degenerate = 0;
  size_t i = begin;
#ifdef DEFORM_ISO_HAVE_AVX2
  static const bool kAvx2 = isometricSimdAvailable();
  if constexpr (std::is_same_v<T, float>) {
    // Projection of float hinges: sixteen per AVX-512 step first, the rest by AVX2 / scalar
    // (the same arithmetic, so the rest values measured by AVX2 stay exact).
    static const bool kAvx512 = kAvx2 && __builtin_cpu_supports("avx512f") &&
                                __builtin_cpu_supports("avx512vl") &&
                                __builtin_cpu_supports("avx512dq");
    if (simd && kAvx512 && measure == nullptr)
      i += isobatch::rangeAvx512(x4, v, i, end, &degenerate);
  }
  if (simd && kAvx2) i += isobatch::rangeAvx2(x4, v, i, end, measure, &degenerate);
#else
  (void)simd;
#endif
  for (; i < end; ++i) degenerate += isobatch::hingeGroup<simd::ScalarLanes<T>>(x4, v, i, measure);
  return degenerate;
}

}  // namespace

bool isometricHinge(const Vec3 x[4], IsometricHinge& h) {
  const Vec3 e = x[3] - x[2];
  const Real a0 = (x[2] - x[0]).cross(x[3] - x[0]).norm();
  const Real a1 = (x[3] - x[1]).cross(x[2] - x[1]).norm();
  constexpr Real kTiny = tol::kDegenerateLength * tol::kDegenerateLength;
  if (e.squaredNorm() <= kTiny || a0 <= kTiny || a1 <= kTiny) return false;
  // Wing j's triangle: angles at x2 (alpha) and x3 (beta); its share of v is
  // cot(beta) x2 + cot(alpha) x3 - (cot(alpha) + cot(beta)) x_j.
  const Real alpha0 = cotAt(x[2], x[3], x[0]), beta0 = cotAt(x[3], x[2], x[0]);
  const Real alpha1 = cotAt(x[2], x[3], x[1]), beta1 = cotAt(x[3], x[2], x[1]);
  Real K[4] = {-(alpha0 + beta0), -(alpha1 + beta1), beta0 + beta1, alpha0 + alpha1};
  for (const Real k : K)
    if (!std::isfinite(k)) return false;
  for (int i = 0; i < 4; ++i) h.K[i] = K[i];
  h.rest = isometricBendingLength(x, h.K);
  return true;
}

Real isometricHingeCompliance(Real young, Real poisson, Real thickness, Real areaSum) {
  const Real D = young * thickness * thickness * thickness / (12.0 * (1.0 - poisson * poisson));
  return areaSum / (3.0 * D);
}

Real isometricBendingLength(const Vec3 x[4], const Real K[4]) {
  Vec3 v;
  Real len;
  if (!stencil(x, K, v, len)) return 0.0;
  return len;
}

bool isometricBendingConstraint(const Vec3 x[4], const Real K[4], Real rest, Real& C,
                                Vec3 grad[4]) {
  Vec3 v;
  Real len;
  const bool ok = stencil(x, K, v, len);
  C = (ok ? len : 0.0) - rest;
  for (int i = 0; i < 4; ++i) grad[i] = ok ? Vec3((K[i] / len) * v) : Vec3::Zero();
  return ok;
}

bool projectIsometricBending(const Vec3 x[4], const Real w[4], const Real K[4], Real rest,
                             Real alphaTilde, Real k, Real& lambda, Vec3 dx[4]) {
  Real C;
  Vec3 g[4];
  const bool ok = isometricBendingConstraint(x, K, rest, C, g);
  if (!ok && rest != 0.0) return false;
  Real denom = 0;
  for (int i = 0; i < 4; ++i) denom += w[i] * K[i] * K[i];
  if (denom + alphaTilde <= 0) return false;
  // The update rule of pbd_kernels.h: dlambda = k (-C - alphaTilde lambda) / (sum w |g|^2 + at).
  const Real dl = ok ? k * (-C - alphaTilde * lambda) / (denom + alphaTilde) : 0.0;
  lambda += dl;
  for (int i = 0; i < 4; ++i) dx[i] = w[i] * dl * g[i];
  return true;
}

long long projectIsometricColour(float* x4, const IsometricBatch<float>& b, size_t begin,
                                 size_t end, bool simd) {
  return run<float>(x4, b, begin, end, nullptr, simd);
}

long long projectIsometricColour(double* x4, const IsometricBatch<double>& b, size_t begin,
                                 size_t end, bool simd) {
  return run<double>(x4, b, begin, end, nullptr, simd);
}

void isometricLengthsColour(const float* x4, const IsometricBatch<float>& b, size_t begin,
                            size_t end, float* out, bool simd) {
  // Measuring writes nothing to x4.
  run<float>(const_cast<float*>(x4), b, begin, end, out, simd);
}

void isometricLengthsColour(const double* x4, const IsometricBatch<double>& b, size_t begin,
                            size_t end, double* out, bool simd) {
  run<double>(const_cast<double*>(x4), b, begin, end, out, simd);
}

bool isometricSimdAvailable() {
#ifdef DEFORM_ISO_HAVE_AVX2
  return __builtin_cpu_supports("avx2");
#else
  return false;
#endif
}

}  // namespace deform::pbd
