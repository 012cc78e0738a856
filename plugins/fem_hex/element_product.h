// KU = K0 U, the product of the rest element stiffness with every element's vector at once
// (fem_hex's element pass, HexFemModel::applyAllElements), on the widest path the CPU has.
#pragma once

namespace deform::fem_hex {

/// KU = K0 U: K0 24 x 24, U and KU 24 x E, all column-major. Each entry is summed over K0's
/// columns in ascending order with separate multiplies and adds on every path, so the AVX2 path
/// (four rows per register, two elements per pass) gives the scalar path's bits.
void multiplyElements(const double* K0, const double* U, double* KU, int E);

namespace detail {
/// The AVX2 path of multiplyElements (element_product_avx2.cpp); call only where the CPU has it.
void multiplyElementsAvx2(const double* K0, const double* U, double* KU, int E);
}  // namespace detail

}  // namespace deform::fem_hex
