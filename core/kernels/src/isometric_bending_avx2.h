// Internal: the AVX2 (and AVX-512) entry points of the batched isometric bending projection
// (isometric_bending_avx2.cpp). Each projects (measure == nullptr) or measures whole vector
// groups from begin on and returns how many hinges it handled; the caller does the tail.
#pragma once

#include <cstddef>

#include "isometric_bending_math.h"

namespace deform::pbd::isobatch {

std::size_t rangeAvx2(float* x4, const View<float>& b, std::size_t begin, std::size_t end,
                      float* measure, long long* degenerate);
std::size_t rangeAvx2(double* x4, const View<double>& b, std::size_t begin, std::size_t end,
                      double* measure, long long* degenerate);
/// Sixteen float hinges per step, projection only (isometric_bending_avx512.cpp, AVX-512F/VL/DQ).
std::size_t rangeAvx512(float* x4, const View<float>& b, std::size_t begin, std::size_t end,
                        long long* degenerate);

}  // namespace deform::pbd::isobatch
