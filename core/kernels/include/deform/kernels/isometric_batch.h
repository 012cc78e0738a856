// deformbench kernels: IsometricBatch, the structure-of-arrays form of a run of isometric bending
// hinges (deform/kernels/isometric_bending.h). A header of its own that includes nothing, so that
// the lane-generic arithmetic compiled with and without -mavx2 (isometric_bending_math.h) reads
// the same struct the solvers fill.
#pragma once

namespace deform::pbd {

/// A run of hinges as structure of arrays, the solvers' form. T = float or double, matching the
/// padded positions x4 (four T per particle: x, y, z, 0). Per hinge: p[k] the row offset
/// 4 * particle of slot k; K[k] the weights; wK[k] = w_k K_k (inverse mass times weight);
/// rest = s0; alphaTilde = alpha / dt^2; scale = k / (sum_k w_k K_k^2 + alphaTilde), 0 when no
/// particle is movable; lambda the multiplier. movable (optional, one byte per hinge): bit k set
/// when slot k's particle is movable (w_k > 0); a vector group then skips the update of a slot
/// that is immovable in all its hinges (an update of exactly zero, so the result is the same),
/// which pays where many particles are immovable and the hinges of a colour are sorted by this
/// pattern (the hybrid model's control nodes). nullptr: every slot is updated.
template <class T>
struct IsometricBatch {
  const int* p[4];
  const T* K[4];
  const T* wK[4];
  const T* rest;
  const T* alphaTilde;
  const T* scale;
  T* lambda;
  const unsigned char* movable = nullptr;
};

}  // namespace deform::pbd
