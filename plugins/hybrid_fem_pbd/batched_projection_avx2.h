// Hybrid FEM+PBD: entry points of the AVX2 translation unit (batched_projection_avx2.cpp,
// compiled with -mavx2 -mfma and called only when the CPU supports AVX2). Each processes the
// largest multiple of four constraints of one colour in [begin, end) and returns how many it
// processed; *degenerate is increased by the degenerate ones.
#pragma once

#include <cstddef>

#include "batched_projection_math.h"

namespace deform::hybrid::batched {

std::size_t stretchRangeAvx2(double* x4, const StretchView& s, std::size_t begin, std::size_t end,
                             long long* degenerate);
std::size_t bendRangeAvx2(double* x4, const BendView& h, std::size_t begin, std::size_t end,
                          long long* degenerate);

}  // namespace deform::hybrid::batched
