// Internal: the AVX2 entry point of the batched tet volume projection (tet_volume_avx2.cpp). It
// projects (measure == nullptr) or measures whole vector groups from begin on and returns how
// many tets it handled; the caller does the tail.
#pragma once

#include <cstddef>

#include "tet_volume_math.h"

namespace deform::pbd::tetbatch {

std::size_t rangeAvx2(float* x4, const View<float>& b, std::size_t begin, std::size_t end,
                      float* measure, long long* degenerate);
std::size_t rangeAvx2(double* x4, const View<double>& b, std::size_t begin, std::size_t end,
                      double* measure, long long* degenerate);

}  // namespace deform::pbd::tetbatch
