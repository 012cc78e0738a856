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
