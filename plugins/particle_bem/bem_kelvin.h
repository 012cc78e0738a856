// particle_bem: Kelvin fundamental solutions of 3D isotropic linear elastostatics and the
// triangle quadratures used to integrate them (the paper's §5.1, eqs. 2-4; Brebbia &
// Dominguez, "Boundary Elements: An Introductory Course", ch. 5).
//
// With r = y - x (field point y, source point x), r_,i = r_i / |r|, n the unit outward normal at y,
// mu the shear modulus and nu Poisson's ratio:
//
//   U*_ij(x, y) = 1 / (16 pi mu (1 - nu) |r|) [ (3 - 4 nu) delta_ij + r_,i r_,j ]
//   T*_ij(x, y) = -1 / (8 pi (1 - nu) |r|^2) { dr/dn [ (1 - 2 nu) delta_ij + 3 r_,i r_,j ]
//                                             - (1 - 2 nu) (r_,i n_j - r_,j n_i) }
//
// U*_ij is the displacement in direction j at y due to a unit point force in direction i at x,
// T*_ij the traction on the surface with normal n at y (T* = sigma(U*) n, tested against finite
// differences). The boundary integral equation (eq. 2) is
//   c_ij(x) u_j(x) + int_Gamma T*_ij u_j dGamma = int_Gamma U*_ij p_j dGamma.
#pragma once

#include <deform/sdk/types.h>

#include <array>
#include <vector>

namespace deform::particle_bem {

class KelvinKernel {
 public:
  KelvinKernel(Real young, Real poisson);
  /// U* for r = y - x (r != 0).
  Mat3 displacement(const Vec3& r) const;
  /// T* for r = y - x and unit normal n at y.
  Mat3 traction(const Vec3& r, const Vec3& n) const;
  /// Both at once (shares the geometry).
  void both(const Vec3& r, const Vec3& n, Mat3& U, Mat3& T) const;

  /// U* = scale / |r| (diagonal I + r_,i r_,j): the two constants, for loops that inline it.
  Real displacementScale() const { return m_cu; }
  Real displacementDiagonal() const { return m_cu34; }

  Real mu() const { return m_mu; }
  Real nu() const { return m_nu; }

 private:
  Real m_mu, m_nu, m_cu, m_cu34, m_ct, m_ct12;
};

/// A point of a triangle rule: barycentric coordinates (l0, l1, l2) and weight (weights sum
/// to 1; multiply by the triangle's area).
struct TrianglePoint {
  Real l0, l1, l2, w;
};

/// The seven-point Gauss rule of eqs. 3-4 (Radon / Hammer-Stroud; exact for polynomials of
/// degree <= 5): centroid 9/40, (1-2a, a, a) with a = (6 -+ sqrt 15)/21 and weights
/// (155 -+ sqrt 15)/1200.
const std::array<TrianglePoint, 7>& gaussTriangle7();

/// Duffy-transformed rule for an integrand singular like 1/r at the triangle's FIRST vertex:
/// (s, t) in [0,1]^2 -> l1 = s (1 - t), l2 = s t, l0 = 1 - s, Jacobian 2 s; Gauss-Legendre with
/// `order` points in s and t. The factor s cancels a 1/r singularity. Weights sum to 1.
std::vector<TrianglePoint> duffyTriangle(int order);

/// Gauss-Legendre nodes and weights on [0, 1].
void gaussLegendre01(int order, std::vector<Real>& x, std::vector<Real>& w);

}  // namespace deform::particle_bem
