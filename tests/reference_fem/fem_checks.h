// Shapes and checks shared by the reference FEM's element tests: jittered box meshes, the
// assembled stiffness as a dense matrix, and the forces and stiffness of a system against finite
// differences of its energy and forces.
#pragma once

#include "../support/finite_difference.h"
#include "fem_solver.h"
#include "test_shapes.h"

#include <gtest/gtest.h>
#include <Eigen/Eigenvalues>

#include <cmath>
#include <string>

namespace deform::reference_fem::fem_checks {

/// The 0.1 x 0.01 x 0.01 m cantilever of the solver and element tests, clamped at x = 0
/// (E = 100 kPa, nu = 0.3, 1000 kg/m^3), and Timoshenko's tip deflections of it.
namespace cantilever {

inline constexpr Real kL = 0.1, kB = 0.01, kH = 0.01, kE = 1e5, kNu = 0.3, kRho = 1000;
inline constexpr Real kI = kB * kH * kH * kH / 12, kA = kB * kH, kG = kE / (2 * (1 + kNu)),
                      kKappa = 5.0 / 6.0;

/// Tip deflection (m, down) under a tip load P (N): P L^3 / (3 E I) + P L / (kappa G A).
inline Real timoshenkoTipLoad(Real P) {
  return P * kL * kL * kL / (3 * kE * kI) + P * kL / (kKappa * kG * kA);
}

/// Tip deflection (m, down) under the beam's weight at gravity g (m/s^2), q = rho g A:
/// q L^4 / (8 E I) + q L^2 / (2 kappa G A).
inline Real timoshenkoGravity(Real g) {
  const Real q = kRho * g * kA;
  return q * std::pow(kL, 4) / (8 * kE * kI) + q * kL * kL / (2 * kKappa * kG * kA);
}

/// The nodal forces of a uniform downward traction over the tip face x = L carrying tipLoad (N)
/// on the full section (a half-width mesh carries half of it); mesh: a TetMesh or a FemSystem.
template <class Mesh>
std::vector<std::pair<int, Vec3>> tipForces(const Mesh& mesh, Real tipLoad) {
  return tractionForces(mesh, Vec3(0, 0, -tipLoad / kA),
                        [](const Vec3& p) { return std::abs(p(0) - kL) < 1e-12; });
}

/// Mean z-deflection (m, positive down) of the first `count` rows of rest on the tip face x = L,
/// x the solved positions (3 per node).
inline Real tipDeflection(const MatX3& rest, int count, const VecX& x) {
  Real s = 0;
  int n = 0;
  for (int i = 0; i < count; ++i)
    if (std::abs(rest(i, 0) - kL) < 1e-12) {
      s += rest(i, 2) - x(3 * i + 2);
      ++n;
    }
  return s / n;
}

}  // namespace cantilever

inline bool onBoundaryOfBox(const Vec3& p, const Vec3& lo, const Vec3& hi) {
  const Real e = 1e-12;
  for (int k = 0; k < 3; ++k)
    if (std::abs(p(k) - lo(k)) < e || std::abs(p(k) - hi(k)) < e) return true;
  return false;
}

/// A structured box mesh with its interior corner nodes moved (general tet shapes).
inline TetMesh jitteredBox(const Vec3& lo, const Vec3& hi, const Vec3i& cells) {
  TetMesh mesh = structuredBoxTets(lo, hi, cells);
  for (int i = 0; i < mesh.numVertices(); ++i) {
    const Vec3 p = mesh.V.row(i);
    if (!onBoundaryOfBox(p, lo, hi))
      mesh.V.row(i) +=
          0.0012 * Vec3(std::sin(7.0 * i), std::cos(3.0 * i), std::sin(5.0 * i + 1)).transpose();
  }
  return mesh;
}

/// Stiffness values on sys's pattern as a dense matrix.
inline MatX dense(const FemSystem& sys, const VecX& values) {
  const SparseMatrix& P = sys.stiffnessPattern();
  return MatX(Eigen::Map<const SparseMatrix>(P.rows(), P.cols(), P.nonZeros(), P.outerIndexPtr(),
                                             P.innerIndexPtr(), values.data()));
}

/// The rest positions mapped by F, each node then moved by a deterministic jitter of up to
/// `jitter` (m) per coordinate: a general deformed state.
inline VecX deformedState(const FemSystem& sys, const Mat3& F, Real jitter) {
  VecX x = sys.restPositions();
  for (int i = 0; i < sys.numNodes(); ++i)
    x.segment<3>(3 * i) =
        F * x.segment<3>(3 * i) +
        jitter * Vec3(std::sin(3.1 * i), std::cos(1.7 * i), std::sin(0.9 * i + 2));
  return x;
}

/// At a general deformed state (an affine map plus a jitter of 0.4 mm): the elastic forces are
/// the central differences of the energy and the stiffness those of the forces (within 1e-6
/// relative), the stiffness is symmetric, and the projected stiffness is positive semi-definite.
/// `label` names the case in a failure.
inline void expectForcesAndStiffnessMatchDifferences(const FemSystem& sys,
                                                     const std::string& label) {
  Mat3 F;
  F << 1.1, 0.08, -0.05, -0.04, 0.93, 0.06, 0.03, -0.02, 1.05;
  const VecX x = deformedState(sys, F, 4e-4);
  VecX g;
  sys.elasticGradient(x, g);
  ASSERT_TRUE(g.allFinite());
  const Real h = 1e-7;
  const VecX gFd =
      deform::testing::numericGradient(x, h, [&](const VecX& y) { return sys.elasticEnergy(y); });
  EXPECT_LT((g - gFd).norm(), 1e-6 * g.norm()) << label;
  VecX values;
  sys.stiffnessValues(x, values, false);
  const MatX K = dense(sys, values);
  EXPECT_LT((K - K.transpose()).norm(), 1e-10 * K.norm()) << label;
  const MatX KFd = deform::testing::centralDifferences(x, h, [&](const VecX& y) {
    VecX gy;
    sys.elasticGradient(y, gy);
    return gy;
  });
  EXPECT_LT((K - KFd).norm(), 1e-6 * K.norm()) << label;
  sys.stiffnessValues(x, values, true);
  const Eigen::SelfAdjointEigenSolver<MatX> es(dense(sys, values));
  EXPECT_GT(es.eigenvalues().minCoeff(), -1e-9 * es.eigenvalues().maxCoeff()) << label;
}

}  // namespace deform::reference_fem::fem_checks
