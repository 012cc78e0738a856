// deformbench SDK: the isometric bending constraint shared by the PBD plugin and the hybrid
// FEM+PBD plugin. A hinge is the pair of triangles sharing an interior edge; its bending is
// measured by a constant linear stencil of its four vertices (Bergou, Wardetzky, Harmon, Zorin,
// Grinspun 2006, "A quadratic bending model for inextensible surfaces", SGP '06): with the wings
// x0 (triangle (x0, x2, x3)) and x1 (triangle (x1, x3, x2)) and the shared edge x2 -> x3 (the
// vertex order of DihedralConstraint in pbd_kernels.h),
//
//   v(x) = sum_i K_i x_i,   K = (-(c02 + c03), -(c12 + c13), c03 + c13, c02 + c12),
//
// where c_jk is the cotangent of the rest angle at x_k in the triangle of wing j. K depends on
// the rest shape only (it is computed once), sum_i K_i = 0, and each triangle's share
// (c03 x2 + c02 x3 - (c02 + c03) x0) is the vector from its wing to the foot of the wing's
// altitude, scaled to length |e|: for a hinge bent isometrically by theta from flat,
// |v| = 2 |e| sin(theta / 2). Bergou et al.'s flat-rest energy is E = 1/2 x^T Q x per coordinate
// with the constant 4 x 4 matrix Q = 3 D / (A0 + A1) K K^T (D the flexural rigidity, A0, A1 the
// rest areas).
//
// As a PBD/XPBD constraint (the position-based form of this energy, as in the PBD literature the
// issue cites, Kelager et al. 2010) we use the length of v against its rest value,
//
//   C(x) = |v(x)| - s0,   s0 = |v| at rest.
//
// With the compliance alpha = (A0 + A1) / (3 D) the XPBD energy C^2 / (2 alpha) is exactly
// Bergou et al.'s E for a flat rest shape (s0 = 0), and for small bends of a curved hinge it is
// the dihedral energy of pbd_kernels.h times cos^2(theta0 / 2). The gradient is g_i = K_i v / |v|
// (C is linear along v's direction), so sum_i w_i |g_i|^2 = sum_i w_i K_i^2 is a constant per
// hinge: a projection costs a 4-point stencil, one sqrt and one division, instead of the
// dihedral angle's two normals, atan2 and four gradient terms.
//
// Extension of our own: the rest value s0 (the paper's energy assumes a flat rest shape, and
// organ surfaces are curved). Limits: C sees |v| only, so the mirror image of a curved hinge
// (folded by -theta0) is at rest too; it is reached only through the flat state, which the
// constraint resists (C = -s0 there). A signed variant (the fold side from a triple product)
// was tried and dropped: where a flat hinge is sheared in its plane, v has an in-plane part and
// the sign flips with rounding, a discontinuity of C that made float and double runs part ways.
// C is not differentiable where v = 0 (a skipped projection when s0 != 0) and the stencil, fixed
// from the rest angles, also responds to large in-plane shear of the hinge.
#pragma once

#include <deform/kernels/isometric_batch.h>
#include <deform/sdk/types.h>

#include <cstddef>
#include <vector>

namespace deform::pbd {

/// One isometric bending hinge (see the header comment). p in the order of DihedralConstraint.
struct IsometricHinge {
  int p[4] = {0, 0, 0, 0};   ///< x0, x1 wings; x2, x3 shared edge
  Real K[4] = {0, 0, 0, 0};  ///< stencil weights (dimensionless)
  Real rest = 0;             ///< s0 = |v| at rest, m
  Real compliance = 0;       ///< alpha, m/N (XPBD); 0 for classic
};

/// Stencil weights K and rest value s0 of the hinge with rest positions x[4] (DihedralConstraint
/// order). False (h untouched) when a triangle is degenerate (zero area or edge).
bool isometricHinge(const Vec3 x[4], IsometricHinge& h);

/// XPBD compliance alpha = (A0 + A1) / (3 D), D = E t^3 / (12 (1 - nu^2)) (m/N): young E (Pa),
/// poisson nu, shell thickness t (m), areaSum = A0 + A1 (m^2).
Real isometricHingeCompliance(Real young, Real poisson, Real thickness, Real areaSum);

/// The length |v| of the stencil at x (m), see the header comment.
Real isometricBendingLength(const Vec3 x[4], const Real K[4]);

/// C(x) = |v| - rest and its gradient dC/dx_i (grad[4]). False (grad zero) where |v| = 0.
bool isometricBendingConstraint(const Vec3 x[4], const Real K[4], Real rest, Real& C, Vec3 grad[4]);

/// Projects one hinge (the update rule of pbd_kernels.h). x[4], w[4] in the order of h.p.
/// False, changing nothing, when degenerate (|v| = 0 with a nonzero rest value, or no particle
/// movable).
bool projectIsometricBending(const Vec3 x[4], const Real w[4], const Real K[4], Real rest,
                             Real alphaTilde, Real k, Real& lambda, Vec3 dx[4]);

/// The batch over hinge fields kept one vector each (p[4], K[4], wK[4]: arrays of four vectors).
template <class T>
IsometricBatch<T> isometricBatch(const std::vector<int>* p, const std::vector<T>* K,
                                 const std::vector<T>* wK, const std::vector<T>& rest,
                                 const std::vector<T>& alphaTilde, const std::vector<T>& scale,
                                 std::vector<T>& lambda) {
  return {{p[0].data(), p[1].data(), p[2].data(), p[3].data()},
          {K[0].data(), K[1].data(), K[2].data(), K[3].data()},
          {wK[0].data(), wK[1].data(), wK[2].data(), wK[3].data()},
          rest.data(),
          alphaTilde.data(),
          scale.data(),
          lambda.data()};
}

/// Projects hinges [begin, end) of one colour: no two of them share a particle that moves (an
/// immovable particle, wK = 0 in every hinge that holds it, may be shared), so projecting them
/// together equals projecting them one after the other. On a CPU with AVX2 eight (float) or four
/// (double) hinges go per vector step, with AVX-512 sixteen float hinges first, all with the
/// scalar path's operations in the same order (no fused multiply-add), so every path gives
/// identical results. Returns the number of degenerate (skipped) hinges.
long long projectIsometricColour(float* x4, const IsometricBatch<float>& b, size_t begin,
                                 size_t end, bool simd = true);
long long projectIsometricColour(double* x4, const IsometricBatch<double>& b, size_t begin,
                                 size_t end, bool simd = true);

/// out[i] = |v| of hinges [begin, end) with exactly the arithmetic of
/// projectIsometricColour() for the same range and simd flag (0 where |v|^2 is below the
/// degenerate threshold): rest values measured with it give C = 0 bit for bit at rest.
void isometricLengthsColour(const float* x4, const IsometricBatch<float>& b, size_t begin,
                            size_t end, float* out, bool simd = true);
void isometricLengthsColour(const double* x4, const IsometricBatch<double>& b, size_t begin,
                            size_t end, double* out, bool simd = true);

/// Whether projectIsometricColour(simd = true) uses AVX2 on this CPU (and AVX-512 for float
/// hinges where the CPU has AVX-512F/VL/DQ).
bool isometricSimdAvailable();

}  // namespace deform::pbd
