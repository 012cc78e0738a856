// Central finite differences for the tests that check an analytic derivative (a force against an
// energy, a stiffness against a force). Include as
// "../support/finite_difference.h".
#pragma once

#include <deform/sdk/types.h>

namespace deform::testing {

/// The Jacobian of f at x by central differences of step h: column j is
/// (f(x + h e_j) - f(x - h e_j)) / (2 h), with e_j the j-th coefficient of x in storage order
/// (column-major for Eigen's default matrices) and f's value (an Eigen object) flattened the same
/// way. x is any dense Eigen object; f takes one of the same type.
template <class X, class F>
MatX centralDifferences(const X& x, Real h, F&& f) {
  using Plain = typename X::PlainObject;
  MatX jacobian;
  for (Eigen::Index j = 0; j < x.size(); ++j) {
    Plain plus = x, minus = x;
    plus.data()[j] += h;
    minus.data()[j] -= h;
    const auto fp = f(plus).eval(), fm = f(minus).eval();
    if (j == 0) jacobian.resize(fp.size(), x.size());
    jacobian.col(j) = (Eigen::Map<const VecX>(fp.data(), fp.size()) -
                       Eigen::Map<const VecX>(fm.data(), fm.size())) /
                      (2 * h);
  }
  return jacobian;
}

/// The gradient of a scalar function f at x by central differences: entry j is
/// (f(x + h e_j) - f(x - h e_j)) / (2 h), in x's storage order.
template <class X, class F>
VecX numericGradient(const X& x, Real h, F&& f) {
  using Plain = typename X::PlainObject;
  VecX gradient(x.size());
  for (Eigen::Index j = 0; j < x.size(); ++j) {
    Plain plus = x, minus = x;
    plus.data()[j] += h;
    minus.data()[j] -= h;
    gradient(j) = (Real(f(plus)) - Real(f(minus))) / (2 * h);
  }
  return gradient;
}

}  // namespace deform::testing
