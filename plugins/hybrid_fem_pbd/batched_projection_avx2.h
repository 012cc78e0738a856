// Hybrid FEM+PBD: entry points of the AVX2 translation unit (batched_projection_avx2.cpp,
// compiled with -mavx2 -mfma and called only when the CPU supports AVX2). Each *RangeAvx2
// processes the largest multiple of the vector width (four doubles, eight floats) of the
// constraints of one colour in [begin, end) and returns how many it processed; *degenerate is
// increased by the degenerate ones.
#pragma once

#include <cstddef>

#include "batched_projection_math.h"

namespace deform::hybrid_fem_pbd::batched {

std::size_t stretchRangeAvx2(double* x4, const StretchView& s, std::size_t begin, std::size_t end,
                             long long* degenerate);
std::size_t bendRangeAvx2(double* x4, const BendView& h, std::size_t begin, std::size_t end,
                          long long* degenerate);
/// measure != nullptr: the lengths instead of the projection (see stretchGroup).
std::size_t stretchRangeAvx2(float* x4, const StretchViewF& s, std::size_t begin, std::size_t end,
                             float* measure, long long* degenerate);

/// BlockedResponse::multiply (response_product.h): y[b 16 + r] = sum_j data[(b cols + j) 16 + r]
/// lambda[j] for blocks b < blocks, accumulated in double.
void blockedResponseAvx2(const float* data, int blocks, int cols, const double* lambda, double* y);

}  // namespace deform::hybrid_fem_pbd::batched
