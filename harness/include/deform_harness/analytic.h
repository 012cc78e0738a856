// Closed-form and semi-analytic solutions the verification table (and the stability sweep's
// cantilever cases) judge the reference against: beam theory with shear, the inextensible
// elastica under its own weight and a tip load (shooting method), and homogeneous uniaxial
// compression of the reference's Neo-Hookean material. SI units throughout.
#pragma once

namespace deform::harness {

/// Tip sag of a clamped square cantilever (side t, length L) under its own weight: Euler-Bernoulli
/// q L^4 / (8 E I) plus Timoshenko shear q L^2 / (2 kappa G A), q = rho g t^2, kappa = 5/6.
double cantileverSag(double young, double poisson, double density, double gravity, double length,
                     double side);

/// Tip of a clamped inextensible, unshearable elastica (Euler's elastica) of length L and bending
/// stiffness EI, horizontal at the clamp, under a distributed weight q (N/m, downward, dead) and
/// a vertical dead tip load P (N, downward). With theta(s) the section's angle below the
/// horizontal, EI theta'' = -(P + q (L - s)) cos theta, theta(0) = 0, theta'(L) = 0; solved by
/// shooting on the root curvature theta'(0) (bisection on the classical RK4 integration with
/// `steps` steps), the tip position by integrating (cos theta, sin theta) along s.
struct ElasticaTip {
  double sag = 0;         ///< m, downward tip displacement (v)
  double shortening = 0;  ///< m, horizontal tip displacement towards the clamp (u)
  double angle = 0;       ///< rad, tip rotation
  bool converged = false;
};
ElasticaTip elasticaCantilever(double length, double bendingStiffness, double weightPerLength,
                               double tipLoad, int steps = 2000);

/// Uniaxial homogeneous deformation of psi = mu/2 (J^-2/3 I1 - 3) + kappa/2 (J - 1)^2 (the
/// reference's Neo-Hookean): axial stretch a, lateral stretch b on both free axes (lateral
/// Cauchy stress zero). mu = E / (2 (1 + nu)), kappa = E / (3 (1 - 2 nu)).
struct UniaxialState {
  double axialStretch = 1, lateralStretch = 1;
  double nominalStress = 0;  ///< Pa, axial first Piola-Kirchhoff stress (force / rest area)
  bool converged = false;
};
/// The lateral stretch and nominal stress at axial stretch a.
UniaxialState neoHookeanUniaxialAtStretch(double young, double poisson, double axialStretch);
/// The state under a dead axial nominal stress (negative: compression), e.g. force / rest area.
UniaxialState neoHookeanUniaxialAtNominalStress(double young, double poisson, double nominalStress);

}  // namespace deform::harness
