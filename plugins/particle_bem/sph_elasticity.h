// particle_bem: point-based elasticity for the small, low-resolution tissues (the paper's §4,
// eq. 1: sigma = C eps with C from Young's modulus and Poisson's ratio). We implement the
// moving-least-squares (MLS) point model of Mueller et al. 2004, "Point based animation of
// elastic, plastic and melting objects" (SCA 2004, the paper's ref. [5]):
//
//   kernel      w_ij = 315 / (64 pi h^9) (h^2 - |x_ij|^2)^3 for |x_ij| < h (x_ij = X_j - X_i, rest)
//   moment      A_i = sum_j x_ij x_ij^T w_ij,   d_ij = A_i^-1 x_ij w_ij
//   gradient    grad u_i = sum_j (u_j - u_i) d_ij^T            (3x3, rows = displacement comps)
//   strain      F_i = I + grad u_i,   E_i = (F_i^T F_i - I) / 2 (Green-St Venant)
//   stress      S_i = lambda tr(E_i) I + 2 mu E_i               (eq. 1, isotropic Hooke)
//   energy      U_i = v_i E_i : S_i / 2
//   forces      f_j = -dU_i/du_j = -v_i F_i S_i d_ij,   f_i = +v_i F_i S_i sum_j d_ij
//
// Forces are the exact gradient of a rotation-invariant energy, so linear and angular momentum
// are conserved. (Mueller's paper writes -2 v_i J sigma d_j for an energy with an extra factor
// 2 in its definition; we keep the energy E:S/2 so the stress is the Hookean one.)
// Time integration: symplectic Euler with mass-proportional damping (see model).
#pragma once

#include <deform/sdk/model.h>
#include <deform/sdk/types.h>

#include <vector>

namespace deform::particle_bem {

/// Lamé parameters from E (Pa) and nu.
inline void lame(Real E, Real nu, Real& lambda, Real& mu) {
  mu = E / (2 * (1 + nu));
  lambda = E * nu / ((1 + nu) * (1 - 2 * nu));
}

/// Rest data of the MLS elasticity. Neighbour lists in compressed rows.
struct MlsElasticity {
  Real h = 0, lambda = 0, mu = 0;
  VecX volume;                  ///< #P, m^3
  std::vector<int> start, nbr;  ///< neighbours of i: nbr[start[i] .. start[i+1])
  std::vector<Vec3> d;          ///< d_ij per neighbour entry
  std::vector<Vec3> dSum;       ///< sum_j d_ij per particle
  std::vector<char> valid;      ///< A_i invertible (>= 4 non-coplanar neighbours)
};

/// Builds neighbour lists (spatial hash, radius h) and MLS rest data. Particles whose moment
/// matrix is singular are marked invalid, contribute no energy and are counted in
/// *degenerate (may be null).
MlsElasticity initMlsElasticity(const MatX3& rest, Real h, const VecX& volume, Real E, Real nu,
                                long long* degenerate = nullptr);

/// Deformation gradient F_i = I + grad u_i of every particle (identity for invalid ones).
void mlsDeformationGradients(const MlsElasticity& m, const MatX3& rest, const MatX3& x,
                             std::vector<Mat3>& F);

/// Second Piola-Kirchhoff stress S_i of a deformation gradient (Green strain, Hooke).
Mat3 hookeStress(const Mat3& F, Real lambda, Real mu);

/// Elastic forces (#P by 3, N), overwritten. F: deformation gradients from
/// mlsDeformationGradients for the same x.
void mlsForces(const MlsElasticity& m, const std::vector<Mat3>& F, MatX3& forces);

/// Total elastic energy sum_i v_i E_i:S_i / 2 (J), for tests.
Real mlsEnergy(const MlsElasticity& m, const std::vector<Mat3>& F);

}  // namespace deform::particle_bem
