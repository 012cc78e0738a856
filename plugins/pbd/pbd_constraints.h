// PBD / XPBD constraint kernels of the PBD plugin. The update rule, the distance (stretch) and the
// dihedral (bending) kernels live in the shared core header deform/kernels/pbd_kernels.h (used by
// the hybrid FEM+PBD plugin too; see its header comment for the update rule and references); this
// file adds the plugin's own batched distance projection, the tetrahedron volume constraint and
// the global surface volume constraint.
#pragma once

#include <deform/kernels/pbd_kernels.h>
#include <deform/kernels/tet_volume_batch.h>
#include <deform/sdk/types.h>

#include <cmath>
#include <numbers>
#include <vector>

namespace deform::pbd {

/// A run of distance constraints in structure-of-arrays form, as the solver stores them: one
/// entry per constraint, with the per-step data alphaTilde = alpha/dt^2 and the multiplier scale
/// k / (w_a + w_b + alphaTilde) precomputed.
struct DistanceBatch {
  const int* a;
  const int* b;
  const Real* rest;
  const Real* alphaTilde;
  const Real* scale;
  Real* lambda;
  const Real* wa;  ///< inverse mass of a, per constraint
  const Real* wb;  ///< inverse mass of b, per constraint
};

/// Projects constraints [begin, end) of a batch whose constraints share no particle (one colour of
/// a greedy colouring), so that projecting them together equals projecting them one after the
/// other with projectDistance(). Positions x4 are padded to four doubles per particle
/// (x, y, z, 0) and the inverse masses come from batch.wa / batch.wb. With simd, on a CPU with
/// AVX-512 (F, VL, DQ) eight constraints are projected per vector step, with 1/|d| from a refined
/// reciprocal square root (equal to the scalar path to rounding); on a CPU with AVX2 only, four,
/// with the scalar path's arithmetic operation for operation (identical results). Either way a
/// particle costs one vector load and store instead of three scalar ones. Returns the number of
/// degenerate (skipped) constraints.
long long projectDistanceColourPadded(Real* x4, const DistanceBatch& batch, size_t begin,
                                      size_t end, bool simd = true);

/// Whether projectDistanceColourPadded(simd = true) uses AVX2 on this CPU.
bool distanceSimdAvailable();

/// The single-precision form of DistanceBatch (the solver's `precision = float32` state).
struct DistanceBatchF {
  const int* a;  ///< 4 * particle index: the offset of a's row in x4
  const int* b;  ///< 4 * particle index of b
  const float* rest;
  const float* alphaTilde;
  const float* scale;
  float* lambda;
  const float* wa;
  const float* wb;
};

/// The paths of projectDistanceColourPaddedF(): the scalar reference (std::sqrt and a division);
/// AVX2, eight constraints per vector step with the same exactly rounded sqrt and division, so
/// bit for bit the scalar path; AVX-512 (F, VL, DQ), sixteen per step with 1/|d| from rsqrt14
/// refined by one Newton step (relative error ~2^-27, below float rounding).
enum class FloatPath { Scalar, Avx2, Avx512 };

/// The fastest FloatPath this CPU runs (checked once per process).
FloatPath fastestFloatPath();

/// projectDistanceColourPadded() in single precision: x4 holds four floats per particle
/// (x, y, z, 0), 16-byte aligned, so 2.2k particles (35 KB) stay in a 48 KB L1 cache. simd takes
/// fastestFloatPath(), otherwise the scalar path. Returns the number of degenerate (skipped)
/// constraints.
long long projectDistanceColourPaddedF(float* x4, const DistanceBatchF& batch, size_t begin,
                                       size_t end, bool simd = true);

/// The same on a given path, which this CPU must run (path <= fastestFloatPath()): for tests.
long long projectDistanceColourPaddedF(float* x4, const DistanceBatchF& batch, size_t begin,
                                       size_t end, FloatPath path);

/// Whether fastestFloatPath() is AVX-512 on this CPU.
bool distanceSimdFloatAvailable();

/// len[i] = |x_a - x_b| for constraints [begin, end) of one colour (a, b: row offsets as in
/// DistanceBatchF), computed with exactly the arithmetic projectDistanceColourPaddedF() uses for
/// the same range and simd flag, so that rest lengths measured with it give C = 0 bit for bit at
/// rest.
void distanceLengthsColourF(const float* x4, const int* a, const int* b, size_t begin, size_t end,
                            float* len, bool simd = true);

/// Tetrahedron volume constraint C = V(x) - V0 with V = (x1-x0).((x2-x0)x(x3-x0)) / 6
/// (Mueller et al. 2007, Sec. 4.4 uses the same form for tetrahedra). Gradients:
/// g1 = (x2-x0)x(x3-x0)/6, g2 = (x3-x0)x(x1-x0)/6, g3 = (x1-x0)x(x2-x0)/6, g0 = -(g1+g2+g3).
struct TetVolumeConstraint {
  int p[4] = {0, 0, 0, 0};
  Real restVolume = 0;  ///< V0, m^3 (positive for a positively oriented tet)
  Real compliance = 0;  ///< alpha, m^5/N (XPBD: V0 / K); 0 for classic
};

inline bool projectTetVolume(const Vec3 x[4], const Real w[4], Real restVolume, Real alphaTilde,
                             Real k, Real& lambda, Vec3 dx[4]) {
  const Vec3 e1 = x[1] - x[0], e2 = x[2] - x[0], e3 = x[3] - x[0];
  Vec3 g[4];
  g[1] = e2.cross(e3) / 6.0;
  g[2] = e3.cross(e1) / 6.0;
  g[3] = e1.cross(e2) / 6.0;
  g[0] = -(g[1] + g[2] + g[3]);
  const Real vol = e1.dot(g[1]);
  Real denom = 0, gsum = 0;
  for (int i = 0; i < 4; ++i) {
    const Real g2 = g[i].squaredNorm();
    gsum += g2;
    denom += w[i] * g2;
  }
  // A tet collapsed to a point or a segment has vanishing gradients (|g|^2 ~ V0^(4/3) at rest).
  if (denom + alphaTilde <= 0 || gsum <= tetVolumeGradientFloor(restVolume)) return false;
  const Real dl = multiplierUpdate(vol - restVolume, denom, alphaTilde, k, lambda);
  lambda += dl;
  for (int i = 0; i < 4; ++i) dx[i] = w[i] * dl * g[i];
  return true;
}

/// The batch over tet fields kept one vector each (p[4], w[4]: arrays of four vectors), as the
/// solver stores them (deform/kernels/tet_volume_batch.h).
template <class T>
TetVolumeBatch<T> tetVolumeBatch(const std::vector<int>* p, const std::vector<T>* w,
                                 const std::vector<T>& rest, const std::vector<T>& floor,
                                 const std::vector<T>& alphaTilde, std::vector<T>& lambda, T k) {
  return {{p[0].data(), p[1].data(), p[2].data(), p[3].data()},
          {w[0].data(), w[1].data(), w[2].data(), w[3].data()},
          rest.data(),
          floor.data(),
          alphaTilde.data(),
          lambda.data(),
          k};
}

/// Global volume constraint of a closed, outward-oriented triangle surface, C = V(x) - V0 with
/// V = (1/6) sum_T x_a.(x_b x x_c) (Mueller et al. 2007, Sec. 4.4, Eq. for closed meshes), so
/// g_i = (1/6) sum over triangles T containing i of (x_b x x_c) with (i, b, c) T's vertices in
/// cyclic order; on a closed surface that equals (1/6) sum_T (x_b - x_a) x (x_c - x_a), one cross
/// product per triangle shared by its three vertices (the fan's other terms cancel).
///
/// x: #N by 3 positions, w: #N inverse masses, F: #F by 3 triangles, grad: #N by 3 scratch
/// (overwritten with the gradient), dx: #N by 3 output corrections. Returns false when no
/// particle can move or the gradient vanishes.
bool projectSurfaceVolume(const MatX3& x, const VecX& w, const MatX3i& F, Real restVolume,
                          Real alphaTilde, Real k, Real& lambda, MatX3& grad, MatX3& dx);

/// The same projection applied in place to x (the solver's form: no dx array).
bool projectSurfaceVolumeInPlace(MatX3& x, const VecX& w, const MatX3i& F, Real restVolume,
                                 Real alphaTilde, Real k, Real& lambda, MatX3& grad);

/// The same projection in place on n padded particles x4 (x, y, z, 0 each: the solver's packed
/// form), w: n inverse masses, grad4: 4 n doubles of scratch, left holding the gradient.
bool projectSurfaceVolumePadded(Real* x4, Eigen::Index n, const Real* w, const MatX3i& F,
                                Real restVolume, Real alphaTilde, Real k, Real& lambda,
                                Real* grad4);

/// The same on single-precision padded particles (16-byte aligned): the gradient and the
/// corrections in float, the volume, the denominator sum_i w_i |g_i|^2 and the multiplier in
/// double (sums of thousands of terms whose float rounding would bias C = V - V0). With simd (and
/// SSE2) the triangle pass works on whole rows, with the scalar path's operations in the same
/// order (identical results).
bool projectSurfaceVolumePaddedF(float* x4, Eigen::Index n, const Real* w, const MatX3i& F,
                                 Real restVolume, Real alphaTilde, Real k, Real& lambda,
                                 float* grad4, bool simd = true);

/// Signed volume (1/6) sum_T x_a . ((x_b - x_a) x (x_c - x_a)) of a closed surface on
/// single-precision padded particles, accumulated in double, with the arithmetic of
/// projectSurfaceVolumePaddedF() for the same simd flag: the rest volume V0 of the float path is
/// computed with this from the rounded rest positions, so that C = 0 exactly at rest.
Real surfaceVolumePaddedF(const float* x4, Eigen::Index n, const MatX3i& F, bool simd = true);

}  // namespace deform::pbd
