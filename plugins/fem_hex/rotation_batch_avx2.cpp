// The 4-lane path of rotation_batch.h. Compiled with -mavx2 -ffp-contract=off (CMakeLists.txt)
// and entered only after a run-time CPU check (rotation_batch.cpp).
#include <deform/kernels/simd_lanes_avx2.h>

#include "rotation_batch.h"
#include "rotation_batch_lanes.h"

namespace deform::fem_hex::detail {

void rotationStepsAvx2(const double* F, double* q, double* R, signed char* outcome,
                       double tolerance, int maxSteps) {
  rotation::stepsOnLanes<simd::Avx2Double4>(F, q, R, outcome, tolerance, maxSteps);
}

}  // namespace deform::fem_hex::detail
