// deformbench kernels: the batched tetrahedron volume constraint of the PBD volume network,
// C = V(x) - V0 with V = (x1 - x0) . ((x2 - x0) x (x3 - x0)) / 6 (Mueller et al. 2007, Sec. 4.4),
// projected colour by colour on the solver's padded positions (four T per particle: x, y, z, 0),
// float or double, like the distance constraints and the isometric hinges. The arithmetic is the
// one-at-a-time rule of plugins/pbd/pbd_constraints.h (projectTetVolume): gradients
// g1 = (x2-x0)x(x3-x0)/6, g2 = (x3-x0)x(x1-x0)/6, g3 = (x1-x0)x(x2-x0)/6, g0 = -(g1+g2+g3),
// dlambda = k (-C - alphaTilde lambda) / (sum_i w_i |g_i|^2 + alphaTilde), dx_i = w_i dlambda g_i;
// a tet whose sum_i |g_i|^2 is at or below its floor (collapsed to a point or a segment) or whose
// denominator is not positive is skipped and counted as degenerate. This header includes nothing
// with inline functions: the lane-generic arithmetic (src/tet_volume_math.h) is compiled with and
// without -mavx2 and reads the same struct.
#pragma once

#include <cstddef>

namespace deform::pbd {

/// A run of tet volume constraints as structure of arrays. p[k]: row offset 4 * particle of
/// corner k; w[k]: that particle's inverse mass this step; rest = V0 (m^3); floor = the
/// degenerate floor on sum_i |g_i|^2 (1e-20 |V0|^(4/3), computed once); alphaTilde = alpha / dt^2;
/// lambda the multipliers; k the per-iteration stiffness (1 for XPBD).
template <class T>
struct TetVolumeBatch {
  const int* p[4];
  const T* w[4];
  const T* rest;
  const T* floor;
  const T* alphaTilde;
  T* lambda;
  T k;
};

/// Projects tets [begin, end) of one colour: no two of them share a particle that moves, so
/// projecting them together equals projecting them one after the other in index order. With
/// simd, eight float or four double tets per AVX2 step where the CPU has AVX2, with the scalar
/// path's operations in the same order (no fused multiply-add), so every path gives the same
/// result bit for bit. Returns the number of degenerate (skipped) tets.
long long projectTetVolumeColour(float* x4, const TetVolumeBatch<float>& b, std::size_t begin,
                                 std::size_t end, bool simd = true);
long long projectTetVolumeColour(double* x4, const TetVolumeBatch<double>& b, std::size_t begin,
                                 std::size_t end, bool simd = true);

/// out[i] = V(x) of tets [begin, end) with exactly the arithmetic of projectTetVolumeColour() for
/// the same range and simd flag: rest volumes measured with it give C = 0 bit for bit at rest.
void tetVolumesColour(const float* x4, const TetVolumeBatch<float>& b, std::size_t begin,
                      std::size_t end, float* out, bool simd = true);
void tetVolumesColour(const double* x4, const TetVolumeBatch<double>& b, std::size_t begin,
                      std::size_t end, double* out, bool simd = true);

/// The floor on sum_i |g_i|^2 below which a tet of rest volume v0 counts as degenerate.
double tetVolumeGradientFloor(double v0);

/// Whether projectTetVolumeColour(simd = true) uses AVX2 on this CPU.
bool tetVolumeSimdAvailable();

}  // namespace deform::pbd
