// AVX2 lanes for tet_volume_math.h: eight tets per __m256 (float) or four per __m256d (double).
// Compiled with -mavx2 -ffp-contract=off (core/kernels/CMakeLists.txt) and called only after a
// run-time CPU check (tet_volume.cpp); includes nothing but the intrinsics, the lanes of
// deform/kernels/simd_lanes_avx2.h, the internal-linkage math header and paired_groups.h.
#if defined(__x86_64__) && defined(__GNUC__)
#include <deform/kernels/simd_lanes_avx2.h>
#include <immintrin.h>

#include "paired_groups.h"
#include "tet_volume_avx2.h"
#include "tet_volume_math.h"

namespace deform::pbd::tetbatch {

namespace {

template <class L>
std::size_t range(typename L::T* x4, const View<typename L::T>& b, std::size_t begin,
                  std::size_t end, typename L::T* measure, long long* degenerate) {
  return simd::pairedGroups<L::kWidth, TetUpdate<L>>(
      begin, end, measure != nullptr, degenerate,
      [&](std::size_t i, TetUpdate<L>& u) { tetCompute<L>(x4, b, i, nullptr, u); },
      [&](std::size_t i, const TetUpdate<L>& u) { tetCommit<L>(x4, b, i, u); },
      [&](std::size_t i) { return tetGroup<L>(x4, b, i, measure); });
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

}  // namespace deform::pbd::tetbatch

#endif
