// Metaballs plugin: the run-time solver kernels of Algorithm 3 (paper Sect. 5.3) in the layout the
// model steps with. Pan, Zhao, Zhao, Hao, Qin 2015, "Metaballs-based physical modeling and
// deformation of organs for virtual surgery", The Visual Computer 31,
// doi:10.1007/s00371-015-1092-2.
//
// Positions P4: (#S + 1) rows of 4 doubles (x, y, z, 0), row #S a dummy sphere with inverse mass 0
// that pads the constraint batches. The maths is that of pbd_constraints.h; these kernels only
// order and batch it:
//
// - Stretching, eqs. (6)-(8), in XPBD form with a stiffness factor k (classic PBD: alpha = 0):
//     dlambda = (k (d - |c_a - c_b|) - alpha~ lambda) / (w_a + w_b + alpha~),   lambda += dlambda,
//     c_a += w_a (dlambda / |c_a - c_b|) (c_a - c_b),   c_b -= w_b (dlambda / |c_a - c_b|) (c_a -
//     c_b)
//   (xpbd: k = 1; classic: alpha~ = 0 gives dc_a = -k w_a C n / (w_a + w_b), eq. 8). The links are
//   coloured so that no two links of one colour share a sphere; a colour is projected in groups of
//   eight (Gauss-Seidel across colours, independent inside). The AVX-512 path and the scalar path
//   evaluate the same operations in the same order per link (no fused multiply-add), so results
//   are bit-identical on every CPU.
// - Laplacian coordinates, eqs. (9)-(11), as the vector constraint of pbd_constraints.h with the
//   per-step constants (generalised inverse mass W, rotated R L_m) hoisted out of the iterations.
#pragma once

#include <deform/sdk/types.h>

#include <vector>

namespace deform::metaballs {

/// Links grouped by colour, each colour padded to a multiple of 8 with dummy links (a = b = the
/// dummy row). Arrays are in batch order (#B = padded link count).
struct StretchBatches {
  std::vector<int> a, b;         ///< #B sphere indices (dummy row for padding)
  std::vector<int> link;         ///< #B original link index, -1 for padding
  std::vector<Real> rest;        ///< #B rest length d (m)
  std::vector<Real> compliance;  ///< #B XPBD compliance alpha (m/N), 0 for padding
  std::vector<int> colourStart;  ///< #colours + 1 offsets into the arrays
  int numColours() const { return int(colourStart.size()) - 1; }
  int size() const { return int(a.size()); }
};

/// Greedy colouring in link order (deterministic). links: #L by 2; rest, compliance: #L;
/// dummy: the padding row index (= #S).
StretchBatches buildStretchBatches(const MatX2i& links, const std::vector<Real>& rest,
                                   const std::vector<Real>& compliance, int dummy);

/// Per-step data of the stretching kernel, #B each: inverse masses of both ends, alpha~ =
/// alpha/dt^2 (0 in classic mode) and the multipliers (zeroed at the start of every step).
struct StretchStepData {
  std::vector<Real> wa, wb, alphaTilde, lambda;
};

/// One Gauss-Seidel sweep over all colours. k: stiffness factor (1 for XPBD). simd: use AVX-512
/// when the CPU has it (same results either way). Returns the number of degenerate links
/// (|c_a - c_b| <= 1e-12 m with a movable end), which are skipped.
long long projectStretchSweep(const StretchBatches& batches, StretchStepData& data, Real* p4,
                              Real k, bool simd = true);

/// True when projectStretchSweep and skinning use the AVX-512 path on this CPU.
bool simdAvailable();

/// Sphere order for the Laplacian sweep: greedy distance-2 colouring (two constraints of one colour
/// share no sphere), colours one after the other, so that consecutive projections are independent
/// and overlap in the CPU. Deterministic. CSR adjacency (adjStart #S+1, adj) of the links.
std::vector<int> laplacianOrder(const std::vector<int>& adjStart, const std::vector<int>& adj);

/// Laplacian constraint data hoisted per step.
struct LaplacianStepData {
  std::vector<int> order;        ///< #S sweep order (laplacianOrder)
  std::vector<Real> W;           ///< #S: w_m + sum_i w_i / n^2 (0: skip)
  std::vector<Real> invDenom;    ///< #S: 1 / (W + alpha~)
  std::vector<Real> coef;        ///< #adj: w_i / n for neighbour i of m
  std::vector<Real> target;      ///< #S*4: R L_m (row of 4, last 0)
  std::vector<Real> alphaTilde;  ///< #S: compliance / dt^2 (0 in classic mode)
  std::vector<Real> lambda;      ///< #S*4: XPBD multipliers (zeroed every step)
};

/// One Gauss-Seidel sweep of the Laplacian constraints in data.order:
///   C = c_m - mean(c_i) - R L_m,  dl = (-k C - alpha~ lambda) / (W + alpha~),  lambda += dl,
///   c_m += w_m dl,  c_i -= (w_i / n) dl.
/// w: (#S + 1) inverse masses. k: stiffness factor (1 for XPBD). simd: AVX2 rows (x, y, z, 0) when
/// the CPU has them (same results).
void projectLaplacianSweep(const std::vector<int>& adjStart, const std::vector<int>& adj,
                           const Real* w, LaplacianStepData& data, Real* p4, Real k,
                           bool simd = true);

/// Rotation extraction for many spheres at once: the iteration of extractRotation()
/// (pbd_constraints.h; Mueller, Bender, Chentanez, Macklin 2016), warm-started from q:
///   omega = sum_c R_c x A_c / (|sum_c R_c . A_c| + 1e-30),  stop when |omega| < 1e-9,
///   q <- normalise(exp(omega) q),  R = R(q),
/// on structure-of-arrays data, 8 spheres per AVX-512 step (scalar path identical: same
/// operations, sin/cos of the half angle by the same polynomial for |angle/2| <= pi/4, std::sin /
/// std::cos beyond). Arrays are component-major with stride `padded` (a multiple of 8).
struct RotationBatch {
  int n = 0, padded = 0;
  std::vector<Real> A;  ///< 9 * padded: A_rc at A[(3r + c) * padded + i]
  std::vector<Real> q;  ///< 4 * padded: w, x, y, z of sphere i at q[k * padded + i]
  void resize(int count);
  void setIdentity();
};

/// Runs maxIter iterations on every sphere and writes R(q) row-major to rotations (#n * 9).
void extractRotations(RotationBatch& batch, int maxIter, Real* rotations, bool simd = true);

}  // namespace deform::metaballs
