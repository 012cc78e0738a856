// Closed-form and semi-analytic solutions (analytic.h).
#include <deform_harness/analytic.h>

#include <array>
#include <cmath>

namespace deform::harness {

double cantileverSag(double young, double poisson, double density, double gravity, double length,
                     double side) {
  const double q = density * gravity * side * side, inertia = side * side * side * side / 12;
  const double shear = young / (2 * (1 + poisson)), kappa = 5.0 / 6.0;
  return q * std::pow(length, 4) / (8 * young * inertia) +
         q * length * length / (2 * kappa * shear * side * side);
}

namespace {

/// State along the elastica: angle, curvature, x, z (z downward).
using ElasticaState = std::array<double, 4>;

struct ElasticaRun {
  ElasticaState end{};
};

ElasticaRun integrateElastica(double L, double EI, double q, double P, double rootCurvature,
                              int steps) {
  const double h = L / steps;
  const auto rhs = [&](double s, const ElasticaState& y) {
    return ElasticaState{y[1], -(P + q * (L - s)) * std::cos(y[0]) / EI, std::cos(y[0]),
                         std::sin(y[0])};
  };
  ElasticaState y{0, rootCurvature, 0, 0};
  for (int i = 0; i < steps; ++i) {
    const double s = i * h;
    const ElasticaState k1 = rhs(s, y);
    ElasticaState t;
    for (int j = 0; j < 4; ++j) t[size_t(j)] = y[size_t(j)] + 0.5 * h * k1[size_t(j)];
    const ElasticaState k2 = rhs(s + 0.5 * h, t);
    for (int j = 0; j < 4; ++j) t[size_t(j)] = y[size_t(j)] + 0.5 * h * k2[size_t(j)];
    const ElasticaState k3 = rhs(s + 0.5 * h, t);
    for (int j = 0; j < 4; ++j) t[size_t(j)] = y[size_t(j)] + h * k3[size_t(j)];
    const ElasticaState k4 = rhs(s + h, t);
    for (int j = 0; j < 4; ++j)
      y[size_t(j)] +=
          h / 6 * (k1[size_t(j)] + 2 * k2[size_t(j)] + 2 * k3[size_t(j)] + k4[size_t(j)]);
  }
  return {y};
}

}  // namespace

ElasticaTip elasticaCantilever(double length, double bendingStiffness, double weightPerLength,
                               double tipLoad, int steps) {
  ElasticaTip tip;
  if (!(length > 0) || !(bendingStiffness > 0) || steps < 1) return tip;
  // theta'(L) grows with the root curvature: negative at 0 (the load bends the free end back),
  // non-negative at the root moment of the undeformed beam over EI (cos theta <= 1).
  double lo = 0,
         hi = (tipLoad * length + 0.5 * weightPerLength * length * length) / bendingStiffness;
  if (!(hi > 0)) {
    tip.converged = true;
    return tip;
  }
  ElasticaRun run;
  for (int it = 0; it < 200; ++it) {
    const double mid = 0.5 * (lo + hi);
    run = integrateElastica(length, bendingStiffness, weightPerLength, tipLoad, mid, steps);
    (run.end[1] < 0 ? lo : hi) = mid;
    if (hi - lo <= 1e-15 * std::max(1.0, hi)) break;
  }
  run =
      integrateElastica(length, bendingStiffness, weightPerLength, tipLoad, 0.5 * (lo + hi), steps);
  tip.angle = run.end[0];
  tip.shortening = length - run.end[2];
  tip.sag = run.end[3];
  tip.converged = std::isfinite(tip.sag) &&
                  std::abs(run.end[1]) * length <= 1e-8 * std::max(1.0, std::abs(tip.angle));
  return tip;
}

namespace {

struct NeoHookeanModuli {
  double mu, kappa;
};

NeoHookeanModuli moduli(double young, double poisson) {
  return {young / (2 * (1 + poisson)), young / (3 * (1 - 2 * poisson))};
}

/// Cauchy stress along an axis with stretch c of the state (a, b, b): for psi above,
/// sigma = mu J^-5/3 (B - I1/3 I) + kappa (J - 1) I.
double cauchy(const NeoHookeanModuli& m, double a, double b, double c) {
  const double J = a * b * b, I1 = a * a + 2 * b * b;
  return m.mu * std::pow(J, -5.0 / 3.0) * (c * c - I1 / 3) + m.kappa * (J - 1);
}

}  // namespace

UniaxialState neoHookeanUniaxialAtStretch(double young, double poisson, double axialStretch) {
  UniaxialState s;
  s.axialStretch = axialStretch;
  if (!(axialStretch > 0) || !(young > 0) || !(poisson > -1 && poisson < 0.5)) return s;
  const NeoHookeanModuli m = moduli(young, poisson);
  // The lateral stress grows with b (more volume, more lateral stretch): bisection in log b.
  double lo = std::log(1e-4), hi = std::log(1e4);
  for (int it = 0; it < 300 && hi - lo > 1e-15; ++it) {
    const double mid = 0.5 * (lo + hi);
    (cauchy(m, axialStretch, std::exp(mid), std::exp(mid)) < 0 ? lo : hi) = mid;
  }
  const double b = std::exp(0.5 * (lo + hi));
  s.lateralStretch = b;
  // First Piola-Kirchhoff P = J sigma F^-T: axially sigma_a b^2.
  s.nominalStress = cauchy(m, axialStretch, b, axialStretch) * b * b;
  s.converged = std::abs(cauchy(m, axialStretch, b, b)) <= 1e-9 * (m.mu + m.kappa);
  return s;
}

UniaxialState neoHookeanUniaxialAtNominalStress(double young, double poisson,
                                                double nominalStress) {
  // The nominal stress grows with the axial stretch between a = 0.3 and 3 (far below, the
  // volumetric term kappa (J - 1) saturates and the compressive force passes a maximum):
  // bisection in log a there.
  double lo = std::log(0.3), hi = std::log(3.0);
  for (int it = 0; it < 300 && hi - lo > 1e-15; ++it) {
    const double mid = 0.5 * (lo + hi);
    (neoHookeanUniaxialAtStretch(young, poisson, std::exp(mid)).nominalStress < nominalStress
         ? lo
         : hi) = mid;
  }
  UniaxialState s = neoHookeanUniaxialAtStretch(young, poisson, std::exp(0.5 * (lo + hi)));
  s.converged = s.converged && std::abs(s.nominalStress - nominalStress) <=
                                   1e-8 * std::max(std::abs(nominalStress), 1e-6 * young);
  return s;
}

}  // namespace deform::harness
