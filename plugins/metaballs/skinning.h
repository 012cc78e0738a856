// Metaballs plugin, skinning of the surface mesh by the spheres (paper Sect. 5.4, eqs. 13-16).
//   field strength  f(d, r) = c exp(-(d - r)^2 / r^2),  c = 1                        (13)
//   attached spheres of vertex v: f(|v - c_i|, r_i) >= T (the text's "<= T" is a misprint, see
//     README), at most maxSpheres of them (the strongest), at least one (the strongest overall)
//   c_center = sum_i f_i c_i / sum_i f_i                                            (14)
//   disp = v - c_center  (at rest)                                                  (15)
//   v' = c'_center + (sum_i r'_i / sum_i r_i) R_v disp                              (16)
// R_v = identity in the paper's fixed frame; in the rotated frame R_v = sum_i w_i R_i, the
// weight-blended local rotations of the attached spheres (see README).
// Storage: K = maxSpheres slots per vertex, structure of arrays, zero-weight padding; no
// allocation per step.
#pragma once

#include "sphere_set.h"

#include <cmath>
#include <vector>

namespace deform::metaballs {

/// Eq. (13) with c = 1 (c cancels in eq. 14; T is relative to it).
inline Real fieldStrength(Real d, Real r) {
  const Real t = (d - r) / r;
  return std::exp(-t * t);
}

struct Skinning {
  int numVertices = 0;
  int slots = 0;                          ///< K
  std::vector<int> sphere;                ///< #V*K, vertex-major
  std::vector<Real> weight;               ///< #V*K, f_i / sum f (eq. 14), 0 in padding slots
  std::vector<Real> restRadiusSum;        ///< #V: sum_i r_i over the attached spheres at rest
  std::vector<Real> dispX, dispY, dispZ;  ///< #V each: eq. (15)
  std::vector<int> count;                 ///< #V attached spheres (the first count slots)
  int fallbacks = 0;    ///< vertices with no sphere at f >= T (took the strongest)
  int attachments = 0;  ///< total attached (vertex, sphere) pairs
};

/// V: #V by 3 rest surface vertices. threshold T in (0, 1].
Skinning buildSkinning(const MatX3& V, const SphereSet& spheres, Real threshold, int maxSpheres);

/// Doubles per sphere in a frame record: (c_x, c_y, c_z, r, R row-major (9), 0, 0, 0).
inline constexpr int kFrameStride = 16;

/// Packs the per-sphere data eq. (16) blends into one record per sphere (#S*16, pre-sized):
/// centers #S by 3, radii #S, rotations #S*9 row-major or nullptr (identity).
void packSphereFrames(const MatX3& centers, const VecX& radii, const Real* rotations,
                      std::vector<Real>& frames);

/// Eq. (16) from packed frames: per vertex the weighted sum of its spheres' records (one
/// 16-double multiply-add per attached sphere; AVX-512 when simd and the CPU has it, identical
/// results either way), then v' = c'_center + (sum r' / sum r) R_v disp. rotate: false for the
/// paper's fixed frame (R_v = I). out: #V by 3 (pre-sized).
void applySkinningFrames(const Skinning& sk, const Real* frames, bool rotate, MatX3& out,
                         bool simd = true);

/// Eq. (16). centers: #S by 3 current centres; radii: #S current radii; rotations: #S*9 row-major
/// 3x3 local rotations, or nullptr for the paper's fixed frame. out: #V by 3 (pre-sized).
void applySkinning(const Skinning& sk, const MatX3& centers, const VecX& radii,
                   const Real* rotations, MatX3& out);

}  // namespace deform::metaballs
