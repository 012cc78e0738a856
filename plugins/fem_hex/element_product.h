// fem_hex's element pass (HexFemModel::applyAllElements) on the widest path the CPU has: every
// element's vector gathered and rotated back, KU = K0 U for all of them at once, the forces
// rotated and scattered. Each sum runs in the same order with separate multiplies and adds on
// every path (-ffp-contract=off), so the AVX2 paths give the scalar paths' bits.
#pragma once

namespace deform::fem_hex {

/// Whether this CPU runs fem_hex's AVX2 units (false where they are not built: x86-64 with GCC
/// or Clang only). The one CPU check behind every AVX2 path of the plugin.
bool hasAvx2Units();

/// KU = K0 U: K0 24 x 24, U and KU 24 x E, all column-major. Each entry is summed over K0's
/// columns in ascending order (the AVX2 path: four rows per register, two elements per pass).
void multiplyElements(const double* K0, const double* U, double* KU, int E);

/// The corotational gather: column e of U (24 x E, column-major) is element e's
/// u_i = R_e^T (a in_n) - b rest_n over its eight nodes n = hexes[8 e + i]; R: E column-major
/// 3 x 3 rotations; in, rest: 3 values per node. b = 0 skips the rest term.
void gatherRotated(const int* hexes, const double* R, const double* in, const double* rest,
                   double a, double b, double* U, int E);

/// The corotational scatter: out_n += (scale fill_e R_e) f_i for f = column e of KU and
/// n = hexes[8 e + i].
void scatterRotated(const int* hexes, const double* R, const double* KU, const double* fill,
                    double scale, double* out, int E);

namespace detail {
/// The AVX2 paths (element_product_avx2.cpp); call only where the CPU has AVX2.
void multiplyElementsAvx2(const double* K0, const double* U, double* KU, int E);
void gatherRotatedAvx2(const int* hexes, const double* R, const double* in, const double* rest,
                       double a, double b, double* U, int E);
void scatterRotatedAvx2(const int* hexes, const double* R, const double* KU, const double* fill,
                        double scale, double* out, int E);
}  // namespace detail

}  // namespace deform::fem_hex
