// NodeCholesky (node_cholesky.h): its supernodal float-valued solve with right-hand sides stored
// per node agrees with a double-precision sparse Cholesky solve, on spring matrices of a small
// ellipsoid and of the 8k liver phantom (wide supernodes), with and without identity rows.
#include "node_cholesky.h"
#include "../support/meshes.h"
#include "massspring_model.h"

#include <deform/geometry/phantom.h>

#include <gtest/gtest.h>
#include <Eigen/SparseCholesky>

#include <cmath>
#include <vector>

namespace deform::massspring {
namespace {

// A = M + h^2 L of the organ's springs; rows and columns of every `identityEvery`-th node
// replaced by the identity (0: none).
SparseMatrix springMatrix(const SurfaceMesh& surface, Real h, int identityEvery) {
  Organ o;
  o.source = "test";
  o.surface = surface;
  MassSpringModel m;
  m.init(o, MassSpringConfig{});
  const auto fixed = [&](int i) { return identityEvery > 0 && i % identityEvery == 0; };
  std::vector<Triplet> t;
  for (int i = 0; i < int(m.masses().size()); ++i)
    t.emplace_back(i, i, fixed(i) ? 1.0 : m.masses()[i]);
  for (const Spring& s : m.springs()) {
    const Real c = h * h * s.k;
    if (!fixed(s.a)) t.emplace_back(s.a, s.a, c);
    if (!fixed(s.b)) t.emplace_back(s.b, s.b, c);
    if (!fixed(s.a) && !fixed(s.b)) {
      t.emplace_back(s.a, s.b, -c);
      t.emplace_back(s.b, s.a, -c);
    }
  }
  SparseMatrix A(m.masses().size(), m.masses().size());
  A.setFromTriplets(t.begin(), t.end());
  return A;
}

// max |X - X_ref| / max |X_ref| over the three columns; expects the padding column to stay 0.
Real relativeSolveError(const SparseMatrix& A) {
  NodeCholesky chol;
  chol.factor(A);
  const Eigen::Index n = A.rows();
  MatX B(n, 3);
  for (Eigen::Index i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) B(i, c) = std::sin(0.37 * double(i) + 1.3 * c) + 0.2 * c;
  Eigen::SimplicialLDLT<SparseMatrix> ref(A);
  EXPECT_EQ(ref.info(), Eigen::Success);
  const MatX Xref = ref.solve(B);
  std::vector<Row4> Z(n);
  for (Eigen::Index k = 0; k < n; ++k) {
    const int i = chol.perm()[k];
    Z[k] = {{B(i, 0), B(i, 1), B(i, 2), 0.0}};
  }
  chol.solveInPlace(Z.data());
  Real err = 0;
  for (Eigen::Index k = 0; k < n; ++k) {
    const int i = chol.perm()[k];
    for (int c = 0; c < 3; ++c) err = std::max(err, std::abs(Z[k].v[c] - Xref(i, c)));
    EXPECT_EQ(Z[k].v[3], 0.0);
  }
  EXPECT_GT(chol.factorNonZeros(), A.nonZeros() / 2);
  return err / Xref.cwiseAbs().maxCoeff();
}

TEST(NodeCholesky, SolvesLikeADoublePrecisionCholesky) {
  const SurfaceMesh small = testing::uvEllipsoid(10, 16, 0.05, 0.04, 0.03);
  // h large enough for the springs to dominate the masses (a poorly conditioned A).
  EXPECT_LT(relativeSolveError(springMatrix(small, 1e-2, 0)), 1e-5);
  EXPECT_LT(relativeSolveError(springMatrix(small, 1e-2, 7)), 1e-5);
  const SurfaceMesh liver = makePhantom("liver");
  EXPECT_LT(relativeSolveError(springMatrix(liver, 1e-3, 0)), 1e-5);
  EXPECT_LT(relativeSolveError(springMatrix(liver, 1e-3, 5)), 1e-5);
}

TEST(NodeCholesky, RejectsAnIndefiniteMatrix) {
  SparseMatrix A(2, 2);
  A.insert(0, 0) = 1.0;
  A.insert(1, 1) = -1.0;
  NodeCholesky chol;
  EXPECT_THROW(chol.factor(A), std::runtime_error);
}

}  // namespace
}  // namespace deform::massspring
