#include "quadratic_tet.h"

namespace deform::reference_fem {

std::array<Vec4, 4> quadraticTetQuadrature() {
  const Real a = (5.0 + 3.0 * std::sqrt(5.0)) / 20.0, b = (5.0 - std::sqrt(5.0)) / 20.0;
  return {Vec4(a, b, b, b), Vec4(b, a, b, b), Vec4(b, b, a, b), Vec4(b, b, b, a)};
}

Eigen::Matrix<Real, 10, 1> quadraticShape(const Vec4& L) {
  Eigen::Matrix<Real, 10, 1> N;
  for (int a = 0; a < 4; ++a) N(a) = L(a) * (2 * L(a) - 1);
  for (int e = 0; e < 6; ++e) N(4 + e) = 4 * L(kQuadraticEdges[e][0]) * L(kQuadraticEdges[e][1]);
  return N;
}

Mat3x10 quadraticShapeGradients(const Eigen::Matrix<Real, 3, 4>& g, const Vec4& L) {
  Mat3x10 G;
  for (int a = 0; a < 4; ++a) G.col(a) = (4 * L(a) - 1) * g.col(a);
  for (int e = 0; e < 6; ++e) {
    const int a = kQuadraticEdges[e][0], b = kQuadraticEdges[e][1];
    G.col(4 + e) = 4 * (L(a) * g.col(b) + L(b) * g.col(a));
  }
  return G;
}

QuadraticTetRest makeQuadraticTetRest(const TetRest& linear) {
  QuadraticTetRest r;
  r.volume = linear.volume;
  const Eigen::Matrix<Real, 3, 4> g = linear.gradients();
  const auto points = quadraticTetQuadrature();
  for (int q = 0; q < 4; ++q)
    r.gradients[size_t(q)] = quadraticShapeGradients(g, points[size_t(q)]);
  return r;
}

}  // namespace deform::reference_fem
