// AVX2 lanes for isometric_bending_math.h: eight hinges per __m256 (float) or four per __m256d
// (double). Compiled with -mavx2 -ffp-contract=off (core/CMakeLists.txt) and called only after a
// run-time CPU check (isometric_bending.cpp); includes nothing but the intrinsics, the lanes of
// deform/kernels/simd_lanes_avx2.h, the internal-linkage math header and paired_groups.h.
#if defined(__x86_64__) && defined(__GNUC__)
#include <deform/kernels/simd_lanes_avx2.h>
#include <immintrin.h>

#include "isometric_bending_avx2.h"
#include "isometric_bending_math.h"
#include "paired_groups.h"

namespace deform::pbd::isobatch {

namespace {

template <class L>
std::size_t range(typename L::T* x4, const View<typename L::T>& b, std::size_t begin,
                  std::size_t end, typename L::T* measure, long long* degenerate) {
  return simd::pairedGroups<L::kWidth, HingeUpdate<L>>(
      begin, end, measure != nullptr, degenerate,
      [&](std::size_t i, HingeUpdate<L>& u) { hingeCompute<L>(x4, b, i, nullptr, u); },
      [&](std::size_t i, const HingeUpdate<L>& u) { hingeCommit<L>(x4, b, i, u); },
      [&](std::size_t i) { return hingeGroup<L>(x4, b, i, measure); });
}

}  // namespace

std::size_t rangeAvx2(float* x4, const View<float>& b, std::size_t begin, std::size_t end,
                      float* measure, long long* degenerate) {
  return range<simd::Avx2Float8>(x4, b, begin, end, measure, degenerate);
}

std::size_t rangeAvx2(double* x4, const View<double>& b, std::size_t begin, std::size_t end,
                      double* measure, long long* degenerate) {
  return range<simd::Avx2Double4>(x4, b, begin, end, measure, degenerate);
}

}  // namespace deform::pbd::isobatch

#endif
