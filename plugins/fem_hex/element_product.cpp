// multiplyElements (element_product.h): the scalar path, and the run-time choice of the AVX2 one.
// Compiled with -ffp-contract=off (CMakeLists.txt): no fused multiply-add, as on the AVX2 path.
#include "element_product.h"

namespace deform::fem_hex {

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

}  // namespace

void multiplyElements(const double* K0, const double* U, double* KU, int E) {
#if defined(DEFORM_FEM_HEX_AVX2)
  static const bool kAvx2 = __builtin_cpu_supports("avx2");
  if (kAvx2) {
    detail::multiplyElementsAvx2(K0, U, KU, E);
    return;
  }
#endif
  multiplyElementsScalar(K0, U, KU, E);
}

}  // namespace deform::fem_hex
