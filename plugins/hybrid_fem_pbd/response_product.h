// Hybrid FEM+PBD: the product y = Z lambda that applies the grasps' Lagrange multipliers to the
// control nodes (coarse_fem.h: Z = K^-1 C^T at the output dofs, #out by #rows, #rows = 3 per
// prescribed node). On the 8k liver Z is 16k by ~75 (10 MB in double) and is read once per step
// for ~1.2 M multiply-adds: the product is memory bound. Z is therefore stored in single
// precision (relative rounding 6e-8 per entry, far below the FEM's discretisation error) in
// blocks of kRows consecutive rows, column by column within a block, so that one step streams it
// once, contiguously; the sums are accumulated in double.
#pragma once

#include <deform/sdk/types.h>

#include <vector>

namespace deform::hybrid_fem_pbd {

struct BlockedResponse {
  static constexpr int kRows = 16;  ///< rows per block (two cache lines of floats per column)
  int rows = 0, cols = 0;
  /// ceil(rows / kRows) blocks, each cols x kRows floats: data[(b cols + j) kRows + r] =
  /// Z(b kRows + r, j); padding rows are 0.
  std::vector<float> data;

  int blocks() const { return (rows + kRows - 1) / kRows; }
  int paddedRows() const { return blocks() * kRows; }
  /// Stores Z (rows x cols, double), rounded to float.
  void assign(const MatX& Z);
  /// y[0 .. paddedRows()) = Z lambda (lambda: cols values). simd: AVX2+FMA where the CPU has
  /// it (the same sums, fused multiply-adds); otherwise one row block at a time in scalar code.
  void multiply(const double* lambda, double* y, bool simd = true) const;
};

/// Whether BlockedResponse::multiply(simd = true) uses AVX2 on this CPU.
bool responseSimdAvailable();

}  // namespace deform::hybrid_fem_pbd
