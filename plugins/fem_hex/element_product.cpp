// The element pass (element_product.h): the scalar paths, and the run-time choice of the AVX2
// ones. Compiled with -ffp-contract=off (CMakeLists.txt): no fused multiply-add, as on the AVX2
// paths.
#include "element_product.h"

namespace deform::fem_hex {

bool hasAvx2Units() {
#if defined(DEFORM_FEM_HEX_AVX2)
  static const bool kAvx2 = __builtin_cpu_supports("avx2");
  return kAvx2;
#else
  return false;
#endif
}

namespace {

void multiplyElementsScalar(const double* K0, const double* U, double* KU, int E) {
  for (int e = 0; e < E; ++e) {
    const double* u = U + 24 * e;
    double* out = KU + 24 * e;
    for (int i = 0; i < 24; ++i) out[i] = 0.0;
    for (int j = 0; j < 24; ++j) {
      const double* k = K0 + 24 * j;
      for (int i = 0; i < 24; ++i) out[i] = out[i] + k[i] * u[j];
    }
  }
}

void gatherRotatedScalar(const int* hexes, const double* R, const double* in, const double* rest,
                         double a, double b, double* U, int E) {
  for (int e = 0; e < E; ++e) {
    const double* r = R + 9 * e;  // r[row + 3 col]
    for (int i = 0; i < 8; ++i) {
      const int n = hexes[8 * e + i];
      const double v0 = a * in[3 * n], v1 = a * in[3 * n + 1], v2 = a * in[3 * n + 2];
      double* u = U + 24 * e + 3 * i;
      for (int c = 0; c < 3; ++c) {
        double x = r[3 * c] * v0;
        x = x + r[1 + 3 * c] * v1;
        x = x + r[2 + 3 * c] * v2;
        if (b != 0) x = x - b * rest[3 * n + c];
        u[c] = x;
      }
    }
  }
}

void scatterRotatedScalar(const int* hexes, const double* R, const double* KU, const double* fill,
                          double scale, double* out, int E) {
  for (int e = 0; e < E; ++e) {
    const double s = scale * fill[e];
    double sr[9];
    for (int k = 0; k < 9; ++k) sr[k] = s * R[9 * e + k];
    for (int i = 0; i < 8; ++i) {
      const double* f = KU + 24 * e + 3 * i;
      double* o = out + 3 * hexes[8 * e + i];
      for (int row = 0; row < 3; ++row) {
        double x = sr[row] * f[0];
        x = x + sr[row + 3] * f[1];
        x = x + sr[row + 6] * f[2];
        o[row] = o[row] + x;
      }
    }
  }
}

}  // namespace

void gatherRotated(const int* hexes, const double* R, const double* in, const double* rest,
                   double a, double b, double* U, int E) {
#if defined(DEFORM_FEM_HEX_AVX2)
  if (hasAvx2Units()) return detail::gatherRotatedAvx2(hexes, R, in, rest, a, b, U, E);
#endif
  gatherRotatedScalar(hexes, R, in, rest, a, b, U, E);
}

void scatterRotated(const int* hexes, const double* R, const double* KU, const double* fill,
                    double scale, double* out, int E) {
#if defined(DEFORM_FEM_HEX_AVX2)
  if (hasAvx2Units()) return detail::scatterRotatedAvx2(hexes, R, KU, fill, scale, out, E);
#endif
  scatterRotatedScalar(hexes, R, KU, fill, scale, out, E);
}

void multiplyElements(const double* K0, const double* U, double* KU, int E) {
#if defined(DEFORM_FEM_HEX_AVX2)
  if (hasAvx2Units()) return detail::multiplyElementsAvx2(K0, U, KU, E);
#endif
  multiplyElementsScalar(K0, U, KU, E);
}

}  // namespace deform::fem_hex
