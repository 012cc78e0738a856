// The 8-lane path of rotation_batch.h. Compiled with -mavx512f -ffp-contract=off (CMakeLists.txt)
// and entered only after a run-time CPU check (rotation_batch.cpp).
// GCC 12 reports -W(maybe-)uninitialized inside its own AVX-512 intrinsics (their
// _mm512_undefined_* pass-through operands, GCC bug 105593, fixed in GCC 13).
#if !defined(__clang__) && __GNUC__ < 13
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
#pragma GCC diagnostic ignored "-Wuninitialized"
#endif
#include <deform/kernels/simd_lanes_avx512.h>

#include "rotation_batch.h"
#include "rotation_batch_lanes.h"

namespace deform::fem_hex::detail {

void rotationStepsAvx512(const double* F, double* q, double* R, signed char* outcome,
                         double tolerance, int maxSteps) {
  rotation::stepsOnLanes<simd::Avx512Double8>(F, q, R, outcome, tolerance, maxSteps);
}

}  // namespace deform::fem_hex::detail
