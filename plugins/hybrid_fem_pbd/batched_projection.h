// Hybrid FEM+PBD: the surface projection of surface_pbd.h (projectSurfaceConstraints), colour
// batched and vectorised. Same constraints, same stiffnesses, same Gauss-Seidel order (stretch
// colours then bending colours in each sweep, each colour in index order): the constraints of one
// colour share no movable particle, so projecting four of them at once (AVX2) gives what
// projecting them one after the other gives, up to rounding. The arithmetic is in
// batched_projection_math.h; see there for the equations (paper Eqs. (8)-(11)).
//
// Per-constraint data that do not change while the set of immovable particles stays the same
// (the inverse masses, the stretch scales k w_a / (w_a + w_b), cos and sin of the rest angle) are
// precomputed in SurfaceBatches, rebuilt only when that set changes (a grasp starts or ends, a
// cut). Positions are projected in a padded #V by 4 array, in double or (the default, with the
// isometric bending) in float relative to the organ's centre.
#pragma once

#include <deform/sdk/types.h>

#include <vector>

#include "batched_projection_math.h"
#include "surface_pbd.h"

namespace deform::hybrid_fem_pbd {

struct SurfaceBatches {
  // Stretch, in ActiveConstraints colour order (sorted by pattern within a colour; a movable).
  std::vector<int> sa, sb;
  std::vector<unsigned char> sbMovable;
  std::vector<Real> sRest, sScaleA, sScaleB;
  std::vector<int> sColourStart;  ///< #colours + 1 offsets into the stretch arrays
  // Bending, in ActiveConstraints colour order (sorted by movable-slot pattern within a colour).
  std::vector<int> hp[4];
  std::vector<unsigned char> hMovable;            ///< bit k: w[hp[k]] > 0
  std::vector<Real> hw[4], hwd[4], hCos0, hSin0;  ///< hwd: hingeDenominatorWeights() of hw
  std::vector<int> hColourStart;
  bool sLastColourShared = false, hLastColourShared = false;  ///< colour overflow: sequential
  Real kStretch = 0, kBending = 0;                            ///< per-iteration stiffnesses
  // Isometric bending (deform/kernels/isometric_bending.h), set by addIsometricBending(): the same
  // hinges in the same order as hp, with the stencil weights of their rest shape; when set, the
  // bending pass projects these instead of the dihedral angles.
  bool isometric = false;
  std::vector<int> isoP[4];  ///< 4 * particle index (row offsets in x4)
  std::vector<Real> isoK[4], isoWK[4], isoRest, isoAlphaTilde, isoScale;
  mutable std::vector<Real> isoLambda;  ///< written by the projection (classic PBD: unused)
  // Single precision (the default `precision = float32`, isometric bending), set by
  // addSinglePrecision(): the same constraints, order and stiffnesses in float, for positions
  // relative to `origin` in a padded float array. The rest lengths and rest stencil lengths are
  // measured in float from the rounded rest positions with the projection's own arithmetic, so
  // that C = 0 bit for bit at rest.
  bool singlePrecision = false;
  Vec3 origin = Vec3::Zero();  ///< m
  std::vector<float> fRest, fScaleA, fScaleB;
  std::vector<float> fIsoK[4], fIsoWK[4], fIsoRest, fIsoAlphaTilde, fIsoScale;
  mutable std::vector<float> fIsoLambda;

  batched::StretchView stretchView() const;
  batched::StretchViewF stretchViewF() const;
  batched::BendView bendView() const;
};

/// Builds the batches of the active constraints (a: from activeConstraints(c, w)). kStretch,
/// kBending: classic PBD stiffnesses in [0, 1] for `iterations` sweeps.
SurfaceBatches buildSurfaceBatches(const SurfaceConstraints& c, const ActiveConstraints& a,
                                   const VecX& w, Real kStretch, Real kBending, int iterations);

/// Switches the bending pass of b to the isometric constraint (classic stiffness b.kBending) on
/// the same hinges, with stencils from the rest positions restV (#V by 3), dividing by the
/// weights hingeDenominatorWeights() as the dihedral pass does. A hinge degenerate at
/// rest gets a zero stencil (it is then never moved).
void addIsometricBending(SurfaceBatches& b, const MatX3& restV);

/// Adds the single-precision form of b's stretch and isometric bending data (b.isometric must be
/// set): positions relative to origin (m), rest values measured at restV (#V by 3) rounded to
/// float, with the arithmetic of projectSurfaceBatchesF(..., simd) for the same simd flag.
void addSinglePrecision(SurfaceBatches& b, const MatX3& restV, const Vec3& origin, bool simd);

/// `iterations` sweeps on the padded positions x4 (#V by 4, row-major, 4th column unused).
/// simd: use the AVX2 path when the CPU has it. Returns the degenerate projections skipped.
long long projectSurfaceBatches(Real* x4, const SurfaceBatches& b, int iterations, bool simd);

/// projectSurfaceBatches() in single precision (b from addSinglePrecision()): x4 holds the
/// positions minus b.origin as floats (#V by 4). Stretch eight constraints at a time (AVX2), the
/// isometric hinges by the shared float kernel of deform/kernels/isometric_bending.h.
long long projectSurfaceBatchesF(float* x4, const SurfaceBatches& b, int iterations, bool simd);

/// Whether projectSurfaceBatches(..., simd = true) runs four constraints at a time here.
bool surfaceSimdAvailable();

/// Scalar atan2 by the same polynomial as the batched bending kernel (for tests).
Real atan2Polynomial(Real y, Real x);

}  // namespace deform::hybrid_fem_pbd
