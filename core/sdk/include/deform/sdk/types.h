// deformbench SDK: numeric types and named tolerances shared by the core, the harness and every
// plugin. All quantities are SI: metres, seconds, kilograms, newtons, pascals.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstdint>

namespace deform {

using Real = double;
using Vec3 = Eigen::Matrix<Real, 3, 1>;
using Vec4 = Eigen::Matrix<Real, 4, 1>;
using Mat3 = Eigen::Matrix<Real, 3, 3>;
using VecX = Eigen::Matrix<Real, Eigen::Dynamic, 1>;
using MatX = Eigen::Matrix<Real, Eigen::Dynamic, Eigen::Dynamic>;
using Vec3i = Eigen::Matrix<int, 3, 1>;
using Vec4i = Eigen::Matrix<int, 4, 1>;

/// #N by 3 row-major list of points (one point a row), metres unless documented otherwise.
using MatX3 = Eigen::Matrix<Real, Eigen::Dynamic, 3, Eigen::RowMajor>;
/// #F by 3 row-major list of triangle vertex indices (counter-clockwise seen from outside).
using MatX3i = Eigen::Matrix<int, Eigen::Dynamic, 3, Eigen::RowMajor>;
/// #T by 4 row-major list of tetrahedron vertex indices (positive orientation:
/// (x1-x0)·((x2-x0)×(x3-x0)) > 0).
using MatX4i = Eigen::Matrix<int, Eigen::Dynamic, 4, Eigen::RowMajor>;
/// #E by 2 row-major list of edge vertex indices.
using MatX2i = Eigen::Matrix<int, Eigen::Dynamic, 2, Eigen::RowMajor>;

/// Named tolerances. Geometry tolerances are relative to the organ's bounding-box diagonal
/// unless their name says otherwise.
namespace tol {
inline constexpr Real kRelativeWeld = 1e-9;         ///< duplicate vertices: |a-b| <= this * diag
inline constexpr Real kRelativeZeroArea = 1e-14;    ///< degenerate triangle: area <= this * diag^2
inline constexpr Real kDegenerateLength = 1e-12;    ///< absolute, metres: a zero-length edge
inline constexpr Real kDivergenceBoxFactor = 10.0;  ///< diverged: surface leaves 10x the organ box
}  // namespace tol

}  // namespace deform
