// The corotational rotations of a block of elements at once: the warm-started steps of
// extractRotationInfo (hex_element.h) on vector lanes, which in a smooth motion are the whole
// extraction for nearly every element (a few steps below 1e-3 rad, the last one below the
// tolerance or a Newton step whose bound says it is the last). Elements that need more, or a
// larger step, take the scalar extractRotationInfo from their start; the lanes use its arithmetic
// (rotation_step.h), so every element gets the scalar path's bits.
#pragma once

namespace deform::fem_hex {

/// Lanes per block on this CPU: 8 (AVX-512F), 4 (AVX2) or 1 (no batch path).
int rotationBatchLanes();

/// One block of L = rotationBatchLanes() elements, structure of arrays with stride L:
/// F[k L + l] entry k (column-major) of element l's deformation gradient; q[k L + l] its
/// quaternion (w, x, y, z), updated in place; R[k L + l] (column-major) the rotation matrix of
/// the updated q. outcome[l]: 1 + the steps taken where the lane converged within maxSteps
/// steps, each below 1e-3 rad (extractRotationInfo's count of iterations is outcome - 1); 0 not
/// finished (q of that lane unchanged, R unspecified: take the scalar path from q). L > 1 only.
void rotationSteps(const double* F, double* q, double* R, signed char* outcome, double tolerance,
                   int maxSteps);

namespace detail {
/// The vector units (rotation_batch_avx2.cpp, rotation_batch_avx512.cpp); call only where the
/// CPU has the instructions.
void rotationStepsAvx2(const double* F, double* q, double* R, signed char* outcome,
                       double tolerance, int maxSteps);
void rotationStepsAvx512(const double* F, double* q, double* R, signed char* outcome,
                         double tolerance, int maxSteps);
}  // namespace detail

}  // namespace deform::fem_hex
