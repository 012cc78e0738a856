// The run-time choice of the batch path of rotation_batch.h.
#include "rotation_batch.h"

#include "element_product.h"

namespace deform::fem_hex {

int rotationBatchLanes() {
#if defined(DEFORM_FEM_HEX_AVX2)
  static const int kLanes = !hasAvx2Units() ? 1 : __builtin_cpu_supports("avx512f") ? 8 : 4;
  return kLanes;
#else
  return 1;
#endif
}

void rotationSteps(const double* F, double* q, double* R, signed char* outcome, double tolerance,
                   int maxSteps) {
#if defined(DEFORM_FEM_HEX_AVX2)
  if (rotationBatchLanes() == 8)
    return detail::rotationStepsAvx512(F, q, R, outcome, tolerance, maxSteps);
  if (rotationBatchLanes() == 4)
    return detail::rotationStepsAvx2(F, q, R, outcome, tolerance, maxSteps);
#endif
  (void)F, (void)q, (void)R, (void)outcome, (void)tolerance, (void)maxSteps;
}

}  // namespace deform::fem_hex
