#include <deform/kernels/simd_lanes.h>
#include <deform/kernels/tet_volume_batch.h>

#include <cmath>

#include "tet_volume_math.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include "tet_volume_avx2.h"
#define DEFORM_TET_HAVE_AVX2 1
#endif

namespace deform::pbd {

namespace {

template <class T>
long long run(T* x4, const TetVolumeBatch<T>& b, std::size_t begin, std::size_t end, T* measure,
              bool simd) {
  long long degenerate = 0;
  std::size_t i = begin;
#ifdef DEFORM_TET_HAVE_AVX2
  static const bool kAvx2 = tetVolumeSimdAvailable();
  if (simd && kAvx2) i += tetbatch::rangeAvx2(x4, b, i, end, measure, &degenerate);
#else
  (void)simd;
#endif
  for (; i < end; ++i) degenerate += tetbatch::tetGroup<simd::ScalarLanes<T>>(x4, b, i, measure);
  return degenerate;
}

}  // namespace

long long projectTetVolumeColour(float* x4, const TetVolumeBatch<float>& b, std::size_t begin,
                                 std::size_t end, bool simd) {
  return run<float>(x4, b, begin, end, nullptr, simd);
}

long long projectTetVolumeColour(double* x4, const TetVolumeBatch<double>& b, std::size_t begin,
                                 std::size_t end, bool simd) {
  return run<double>(x4, b, begin, end, nullptr, simd);
}

void tetVolumesColour(const float* x4, const TetVolumeBatch<float>& b, std::size_t begin,
                      std::size_t end, float* out, bool simd) {
  // Measuring writes nothing to x4.
  run<float>(const_cast<float*>(x4), b, begin, end, out, simd);
}

void tetVolumesColour(const double* x4, const TetVolumeBatch<double>& b, std::size_t begin,
                      std::size_t end, double* out, bool simd) {
  run<double>(const_cast<double*>(x4), b, begin, end, out, simd);
}

double tetVolumeGradientFloor(double v0) {
  // |g|^2 ~ V0^(4/3) at rest: the gradients of a tet collapsed to a point or a segment vanish.
  const double scale = std::cbrt(std::abs(v0));
  return 1e-20 * scale * scale * scale * scale;
}

bool tetVolumeSimdAvailable() {
#ifdef DEFORM_TET_HAVE_AVX2
  return __builtin_cpu_supports("avx2");
#else
  return false;
#endif
}

}  // namespace deform::pbd
