#include "response_product.h"

#include "batched_projection.h"

#include <algorithm>

#ifdef DEFORM_HYBRID_AVX2
#include "batched_projection_avx2.h"
#endif

namespace deform::hybrid_fem_pbd {

void BlockedResponse::assign(const MatX& Z) {
  rows = static_cast<int>(Z.rows());
  cols = static_cast<int>(Z.cols());
  data.assign(static_cast<size_t>(paddedRows()) * static_cast<size_t>(cols), 0.0f);
  for (int b = 0; b < blocks(); ++b)
    for (int j = 0; j < cols; ++j) {
      float* d = data.data() + (static_cast<size_t>(b) * cols + j) * kRows;
      for (int r = 0; r < kRows && b * kRows + r < rows; ++r)
        d[r] = static_cast<float>(Z(b * kRows + r, j));
    }
}

void BlockedResponse::multiply(const double* lambda, double* y, bool simd) const {
#ifdef DEFORM_HYBRID_AVX2
  static const bool kAvx2 = responseSimdAvailable();
  if (simd && kAvx2) {
    batched::blockedResponseAvx2(data.data(), blocks(), cols, lambda, y);
    return;
  }
#endif
  (void)simd;
  for (int b = 0; b < blocks(); ++b) {
    double acc[kRows] = {};
    const float* d = data.data() + static_cast<size_t>(b) * cols * kRows;
    for (int j = 0; j < cols; ++j, d += kRows)
      for (int r = 0; r < kRows; ++r) acc[r] += static_cast<double>(d[r]) * lambda[j];
    std::copy(acc, acc + kRows, y + static_cast<size_t>(b) * kRows);
  }
}

bool responseSimdAvailable() {
  return surfaceSimdAvailable();  // the same AVX2 + FMA build and CPU check
}

}  // namespace deform::hybrid_fem_pbd
