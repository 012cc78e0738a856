// The 4-lane path of rotation_batch.h. Compiled with -mavx2 -ffp-contract=off (CMakeLists.txt)
// and entered only after a run-time CPU check (rotation_batch.cpp).
#include <immintrin.h>

namespace deform::fem_hex::rotation {

typedef double Lanes __attribute__((vector_size(32)));
inline Lanes lanesSqrt(Lanes x) {
  return (Lanes)_mm256_sqrt_pd((__m256d)x);
}

}  // namespace deform::fem_hex::rotation

#include "rotation_batch.h"
#include "rotation_batch_lanes.h"

namespace deform::fem_hex::detail {

void rotationStepsAvx2(const double* F, double* q, double* R, signed char* outcome,
                       double tolerance, int maxSteps) {
  rotation::stepsOnLanes<rotation::Lanes, 4>(F, q, R, outcome, tolerance, maxSteps);
}

}  // namespace deform::fem_hex::detail
