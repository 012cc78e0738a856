#include "hex_element.h"
#include "../support/finite_difference.h"
#include "element_product.h"
#include "hex_grid.h"
#include "rotation_batch.h"

#include <gtest/gtest.h>
#include <Eigen/Dense>

#include <algorithm>
#include <cstdio>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

namespace deform::fem_hex {
namespace {

Mat38 boxNodes(const Vec3& size) {
  Mat38 X;
  for (int a = 0; a < 8; ++a) X.col(a) = hexCorner(a).cast<Real>().cwiseProduct(size);
  return X;
}

Mat38 randomMat38(std::mt19937& rng, Real scale) {
  std::uniform_real_distribution<Real> u(-scale, scale);
  Mat38 m;
  for (int i = 0; i < 24; ++i) m.data()[i] = u(rng);
  return m;
}

Mat3 rotation(const Vec3& axis, Real angle) {
  return Eigen::AngleAxis<Real>(angle, axis.normalized()).toRotationMatrix();
}

const Real kE = 5500, kNu = 0.3;

TEST(HexElement, UnitCubeStiffnessHasExactlySixRigidModes) {
  for (int incompatible = 0; incompatible < 2; ++incompatible)
    for (Real nu : {0.0, 0.3, 0.45}) {
      const Mat24 K = incompatible ? hexStiffnessIncompatible(Vec3::Ones(), 1.0, nu)
                                   : hexStiffness(Vec3::Ones(), 1.0, nu);
      EXPECT_LT((K - K.transpose()).norm(), 1e-14);
      Eigen::SelfAdjointEigenSolver<Mat24> es(K);
      const auto& ev = es.eigenvalues();  // ascending
      const Real top = ev[23];
      int zeros = 0;
      for (int i = 0; i < 24; ++i) zeros += std::abs(ev[i]) < 1e-10 * top;
      EXPECT_EQ(zeros, 6) << "nu=" << nu << " incompatible=" << incompatible;
      EXPECT_GT(ev[6], 1e-3 * top) << "nu=" << nu << " incompatible=" << incompatible;
      EXPECT_GT(ev[0], -1e-10 * top);
    }
}

TEST(HexElement, StiffnessTimesDisplacementEqualsQuadratureForce) {
  std::mt19937 rng(7);
  const Vec3 size(0.01, 0.012, 0.009);
  const Mat24 K = hexStiffness(size, kE, kNu);
  for (int trial = 0; trial < 5; ++trial) {
    const Mat38 u = randomMat38(rng, 1e-3);
    const Mat38 f = hexElasticForce(size, kE, kNu, u);
    const Vec24 Ku = K * Eigen::Map<const Vec24>(u.data());
    EXPECT_LT((Ku + Eigen::Map<const Vec24>(f.data())).norm(), 1e-12 * Ku.norm());
  }
}

TEST(HexElement, ForceIsMinusEnergyGradientAndStiffnessIsMinusForceJacobian) {
  std::mt19937 rng(11);
  const Vec3 size(0.01, 0.01, 0.01);
  const Mat24 K = hexStiffness(size, kE, kNu);
  const Mat38 u = randomMat38(rng, 1e-3);
  const Mat38 f = hexElasticForce(size, kE, kNu, u);
  const Real eps = 1e-7;
  const VecX dW = testing::numericGradient(
      u, eps, [&](const Mat38& y) { return hexStrainEnergy(size, kE, kNu, y); });
  for (int i = 0; i < 24; ++i) EXPECT_NEAR(-dW(i), f.data()[i], 1e-6 * f.norm());
  const MatX Kfd = -testing::centralDifferences(
      u, eps, [&](const Mat38& y) { return hexElasticForce(size, kE, kNu, y); });
  EXPECT_LT((Kfd - K).norm(), 1e-6 * K.norm());
}

TEST(HexElement, RigidRotationGivesZeroCorotationalForceButNonzeroLinearForce) {
  const Vec3 size = Vec3::Constant(0.01);
  const Mat24 K = hexStiffness(size, kE, kNu);
  const Mat38 X = boxNodes(size);
  for (Real angle : {0.3, 1.2, 2.5}) {
    const Mat3 Rtrue = rotation(Vec3(1, 2, 3), angle);
    const Mat38 x = (Rtrue * X).colwise() + Vec3(0.02, -0.01, 0.03);
    Quat q = Quat::Identity();
    extractRotation(hexCentreGradient(size, x), q, 100);
    EXPECT_LT((q.toRotationMatrix() - Rtrue).norm(), 1e-10);
    const Mat38 fCo = hexCorotationalForce(K, q.toRotationMatrix(), x, X);
    const Mat38 u = x - X;
    const Vec24 fLin = -K * Eigen::Map<const Vec24>(u.data());
    const Real scale = K.norm() * u.norm();
    EXPECT_LT(fCo.norm(), 1e-10 * scale) << "angle " << angle;
    EXPECT_GT(fLin.norm(), 1e-3 * scale) << "angle " << angle;
  }
}

TEST(HexElement, CorotationalStiffnessMatchesFiniteDifferencesAtARotatedRestState) {
  // At x = R X the derivative of R drops out (K0 annihilates infinitesimal rotations), so the
  // exact Jacobian of the corotational force is -R K0 R^T.
  const Vec3 size = Vec3::Constant(0.01);
  const Mat24 K = hexStiffness(size, kE, kNu);
  const Mat38 X = boxNodes(size);
  const Mat3 Rtrue = rotation(Vec3(-1, 0.5, 2), 0.8);
  const Mat38 x = Rtrue * X;
  auto force = [&](const Mat38& y) {
    Quat q(Rtrue);
    extractRotation(hexCentreGradient(size, y), q, 200, 1e-15);
    return hexCorotationalForce(K, q.toRotationMatrix(), y, X);
  };
  Mat24 RB = Mat24::Zero();
  for (int a = 0; a < 8; ++a) RB.block<3, 3>(3 * a, 3 * a) = Rtrue;
  const Mat24 Kr = RB * K * RB.transpose();
  const MatX Kfd = -testing::centralDifferences(x, 1e-8, force);
  EXPECT_LT((Kfd - Kr).norm(), 1e-5 * Kr.norm());
}

TEST(HexElement, RotationExtractionHandlesStretchAndInversion) {
  const Mat3 R = rotation(Vec3(0.3, -1, 0.2), 2.0);
  const Mat3 S = (Mat3() << 1.3, 0.1, 0, 0.1, 0.8, 0.05, 0, 0.05, 1.1).finished();
  Quat q = Quat::Identity();
  extractRotation(R * S, q, 200);
  EXPECT_LT((q.toRotationMatrix() - R).norm(), 1e-9);
  // An inverted F still yields a proper rotation.
  Mat3 F = R;
  F.col(0) *= -0.5;
  Quat q2 = Quat::Identity();
  extractRotation(F, q2, 200);
  EXPECT_NEAR(q2.toRotationMatrix().determinant(), 1.0, 1e-12);
}

Mat3 polarRotationBySvd(const Mat3& F) {
  const Eigen::JacobiSVD<Mat3> svd(F, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Mat3 U = svd.matrixU();
  if ((U * svd.matrixV().transpose()).determinant() < 0) U.col(2) = -U.col(2);
  return U * svd.matrixV().transpose();
}

// Issue 35 item 4: with Müller's step (error contracted by about sym(A) / tr(A) ~ 1/3 per
// iteration) a warm start 1e-4 rad off needed 11 iterations to reach 1e-9 rad, so nearly every
// element hit the cap of 8 at every step. The Newton step converges in a few, at any element size
// (F is dimensionless: the same element at 1 cm, 10 cm and 1 m gives the same iterations).
TEST(HexElement, RotationExtractionConvergesInAFewNewtonStepsAtEveryScale) {
  std::mt19937 rng(7);
  std::normal_distribution<Real> n01;
  std::uniform_real_distribution<Real> stretch(0.5, 2.0);
  int worst = 0;
  for (Real h : {0.01, 0.1, 1.0}) {
    const Vec3 size = Vec3::Constant(h);
    const Mat38 X = boxNodes(size);
    for (int trial = 0; trial < 50; ++trial) {
      const Mat3 Rtrue = rotation(Vec3(n01(rng), n01(rng), n01(rng)), 3.0 * stretch(rng) - 1.5);
      const Mat3 Q = rotation(Vec3(n01(rng), n01(rng), n01(rng)), 1.0);
      const Mat3 S =
          Q * Vec3(stretch(rng), stretch(rng), stretch(rng)).asDiagonal() * Q.transpose();
      const Mat38 x = ((Rtrue * S) * X).colwise() + h * Vec3(0.3, -2, 1);
      const Mat3 F = hexCentreGradient(size, x);
      for (Real off : {1e-4, 1e-2, 0.3}) {
        Quat q = Quat(rotation(Vec3(n01(rng), n01(rng), n01(rng)), off) * Rtrue);
        const RotationExtraction r = extractRotationInfo(F, q, 8, 1e-9);
        EXPECT_TRUE(r.converged);
        EXPECT_FALSE(r.svd) << "h " << h << " off " << off;
        EXPECT_LE(r.iterations, 4) << "h " << h << " off " << off;
        EXPECT_LT((q.toRotationMatrix() - Rtrue).norm(), 1e-9) << "h " << h << " off " << off;
        worst = std::max(worst, r.iterations);
      }
    }
  }
  std::printf("most Newton steps from a warm start 0.3 rad off: %d\n", worst);
}

TEST(HexElement, RotationExtractionOfInvertedOrFarStartsIsTheSvdMaximiser) {
  std::mt19937 rng(11);
  std::normal_distribution<Real> n01;
  for (int trial = 0; trial < 200; ++trial) {
    Mat3 F;
    for (int i = 0; i < 9; ++i) F.data()[i] = n01(rng);  // about half of them inverted
    Quat q = Quat(rotation(Vec3(n01(rng), n01(rng), n01(rng)), 3.0));
    const RotationExtraction r = extractRotationInfo(F, q, 8, 1e-9);
    EXPECT_TRUE(r.converged);
    const Mat3 R = q.toRotationMatrix();
    EXPECT_NEAR(R.determinant(), 1.0, 1e-12);
    // Both maximise tr(R^T F); the maximiser is unique for distinct singular values.
    EXPECT_LT((R - polarRotationBySvd(F)).norm(), 1e-6) << "trial " << trial;
  }
  // A non-finite F is the only rotation that does not converge.
  Quat q = Quat::Identity();
  Mat3 F = Mat3::Identity();
  F(1, 2) = std::numeric_limits<Real>::quiet_NaN();
  EXPECT_FALSE(extractRotationInfo(F, q, 8, 1e-9).converged);
}

// The rotations' steps on vector lanes (rotation_batch.h) against the scalar extractRotationInfo,
// lane by lane: where a lane finishes (steps below 1e-3 rad until one is below the tolerance or
// is the last by its bound) its quaternion, rotation matrix and step count are the scalar path's
// bits; where it does not, it leaves q alone. Warm starts from the converged rotation up to 0.3 rad
// off, an inverted F and a NaN, on every width this CPU runs.
TEST(HexElement, RotationLanesAreTheScalarPathBitForBit) {
  std::vector<std::pair<int, void (*)(const double*, double*, double*, signed char*, double, int)>>
      paths;
#if defined(__x86_64__) && defined(__GNUC__)
  if (__builtin_cpu_supports("avx2")) paths.push_back({4, detail::rotationStepsAvx2});
  if (__builtin_cpu_supports("avx512f")) paths.push_back({8, detail::rotationStepsAvx512});
#endif
  if (paths.empty()) GTEST_SKIP() << "no vector path on this CPU";
  std::mt19937 rng(5);
  std::normal_distribution<Real> n01;
  std::uniform_real_distribution<Real> stretch(0.7, 1.4);
  const Real offsets[] = {0, 1e-10, 1e-8, 1e-6, 1e-4, 1e-2, 0.3};
  for (const auto& [L, run] : paths) {
    int finished = 0, lanes = 0;
    for (int block = 0; block < 400; ++block) {
      std::vector<Mat3> Fs(static_cast<size_t>(L));
      std::vector<Quat> qs(static_cast<size_t>(L));
      std::vector<double> F(size_t(9 * L)), q(size_t(4 * L)), R(size_t(9 * L));
      std::vector<signed char> outcome(static_cast<size_t>(L));
      for (int l = 0; l < L; ++l) {
        const Mat3 Rtrue = rotation(Vec3(n01(rng), n01(rng), n01(rng)), 3.0 * n01(rng));
        const Mat3 S = Vec3(stretch(rng), stretch(rng), stretch(rng)).asDiagonal();
        Mat3 Fl = Rtrue * S;
        if (block % 50 == 7 && l == 1) Fl.col(0) = -Fl.col(0);  // inverted
        if (block % 50 == 9 && l == 2) Fl(1, 1) = std::numeric_limits<Real>::quiet_NaN();
        Quat ql = Quat(Rtrue);
        const Real off = offsets[size_t(block + l) % std::size(offsets)];
        if (off == 0) {
          extractRotationInfo(Fl, ql, 8, 1e-9);  // the converged rotation: no step
        } else {
          ql = Quat(rotation(Vec3(n01(rng), n01(rng), n01(rng)), off) * Rtrue);
        }
        Fs[size_t(l)] = Fl;
        qs[size_t(l)] = ql;
        for (int k = 0; k < 9; ++k) F[size_t(k * L + l)] = Fl.data()[k];
        q[size_t(l)] = ql.w(), q[size_t(L + l)] = ql.x(), q[size_t(2 * L + l)] = ql.y();
        q[size_t(3 * L + l)] = ql.z();
      }
      run(F.data(), q.data(), R.data(), outcome.data(), 1e-9, 8);
      for (int l = 0; l < L; ++l) {
        Quat scalar = qs[size_t(l)];
        const RotationExtraction r = extractRotationInfo(Fs[size_t(l)], scalar, 8, 1e-9);
        const double lane[4] = {q[size_t(l)], q[size_t(L + l)], q[size_t(2 * L + l)],
                                q[size_t(3 * L + l)]};
        ++lanes;
        if (outcome[size_t(l)] == 0) {
          const double start[4] = {qs[size_t(l)].w(), qs[size_t(l)].x(), qs[size_t(l)].y(),
                                   qs[size_t(l)].z()};
          EXPECT_EQ(std::memcmp(lane, start, sizeof lane), 0) << "L " << L << " lane " << l;
          // Not finished on the lanes: the scalar path took a step (and looked again).
          EXPECT_TRUE(r.iterations >= 1 || !r.converged) << "L " << L << " lane " << l;
          continue;
        }
        ++finished;
        EXPECT_EQ(r.iterations, outcome[size_t(l)] - 1) << "L " << L << " lane " << l;
        EXPECT_TRUE(r.converged && !r.svd);
        const double want[4] = {scalar.w(), scalar.x(), scalar.y(), scalar.z()};
        EXPECT_EQ(std::memcmp(lane, want, sizeof lane), 0) << "L " << L << " lane " << l;
        const Mat3 Rs = rotationMatrixOf(scalar);
        for (int k = 0; k < 9; ++k)
          EXPECT_EQ(std::memcmp(&R[size_t(k * L + l)], Rs.data() + k, sizeof(double)), 0)
              << "L " << L << " lane " << l << " entry " << k;
      }
    }
    // The starts within 1e-4 rad are finished on the lanes.
    EXPECT_GT(finished, lanes / 2) << "L " << L;
    std::printf("%d lanes: %d of %d finished on the vector path\n", L, finished, lanes);
  }
}

// The element pass's product K0 U (element_product.h) on the path this CPU takes (AVX2 where it
// has it): every entry summed over K0's columns in ascending order without fused multiply-adds,
// so equal bit for bit to that loop written out, and to Eigen's product within round-off. An odd
// element count reaches the single-element tail after the pairs.
TEST(HexElement, ElementProductIsTheAscendingSumOnEveryPath) {
  std::mt19937 rng(3);
  std::normal_distribution<Real> n01;
  Mat24 K0;
  for (int i = 0; i < 24 * 24; ++i) K0.data()[i] = n01(rng);
  const int E = 7;
  MatX U(24, E), KU(24, E), expected(24, E);
  for (int i = 0; i < 24 * E; ++i) U.data()[i] = n01(rng);
  multiplyElements(K0.data(), U.data(), KU.data(), E);
  for (int e = 0; e < E; ++e)
    for (int i = 0; i < 24; ++i) {
      volatile Real sum = 0.0;  // one rounding per multiply and per add, as the kernel does
      for (int j = 0; j < 24; ++j) {
        volatile Real product = K0(i, j) * U(j, e);
        sum = sum + product;
      }
      expected(i, e) = sum;
    }
  for (int k = 0; k < 24 * E; ++k) EXPECT_EQ(KU.data()[k], expected.data()[k]) << "entry " << k;
  EXPECT_LT((KU - K0 * U).norm(), 1e-13 * (K0 * U).norm());
}

// The corotational gather and scatter of the element pass (element_product.h) on this CPU's path:
// u_i = R^T (a x_n) - b X_n and out_n += s R f_i, each sum in the order written out below without
// fused multiply-adds (bit for bit), and Eigen's products within round-off. Nodes are shared
// between elements, as in a grid, so the scatter's accumulation order matters too.
TEST(HexElement, RotatedGatherAndScatterAreTheWrittenSumsOnEveryPath) {
  std::mt19937 rng(5);
  std::normal_distribution<Real> n01;
  std::uniform_int_distribution<int> node(0, 9);
  const int E = 5, N = 10;
  std::vector<int> hexes(8 * E);
  for (int& h : hexes) h = node(rng);
  std::vector<Mat3> R(E);
  for (Mat3& r : R) r = rotation(Vec3(n01(rng), n01(rng), n01(rng)), n01(rng));
  VecX x(3 * N), X(3 * N), fill(E);
  for (int i = 0; i < 3 * N; ++i) x[i] = n01(rng), X[i] = n01(rng);
  for (int e = 0; e < E; ++e) fill[e] = 0.5 + 0.1 * e;
  const Real a = 1.3, b = 0.7, scale = -2.0;
  MatX U(24, E), KU(24, E);
  gatherRotated(hexes.data(), R[0].data(), x.data(), X.data(), a, b, U.data(), E);
  for (int i = 0; i < 24 * E; ++i) KU.data()[i] = n01(rng);
  VecX out = VecX::Zero(3 * N), outEigen = VecX::Zero(3 * N);
  scatterRotated(hexes.data(), R[0].data(), KU.data(), fill.data(), scale, out.data(), E);
  VecX expectedOut = VecX::Zero(3 * N);
  for (int e = 0; e < E; ++e)
    for (int i = 0; i < 8; ++i) {
      const int n = hexes[8 * e + i];
      const Vec3 v = a * x.segment<3>(3 * n);
      for (int c = 0; c < 3; ++c) {
        volatile Real t0 = R[e](0, c) * v[0], t1 = R[e](1, c) * v[1], t2 = R[e](2, c) * v[2];
        volatile Real u = t0 + t1;
        u = u + t2;
        volatile Real rest = b * X[3 * n + c];
        EXPECT_EQ(U(3 * i + c, e), u - rest) << "element " << e << " node " << i;
      }
      const Vec3 ref = R[e].transpose() * v - b * X.segment<3>(3 * n);
      EXPECT_LT((U.col(e).segment<3>(3 * i) - ref).norm(), 1e-14 * (1 + ref.norm()));
      const Mat3 sR = scale * fill[e] * R[e];
      for (int row = 0; row < 3; ++row) {
        volatile Real t0 = sR(row, 0) * KU(3 * i, e), t1 = sR(row, 1) * KU(3 * i + 1, e);
        volatile Real t2 = sR(row, 2) * KU(3 * i + 2, e);
        volatile Real f = t0 + t1;
        f = f + t2;
        expectedOut[3 * n + row] = expectedOut[3 * n + row] + f;
      }
      outEigen.segment<3>(3 * n) += sR * KU.col(e).segment<3>(3 * i);
    }
  for (int k = 0; k < 3 * N; ++k) EXPECT_EQ(out[k], expectedOut[k]) << "entry " << k;
  EXPECT_LT((out - outEigen).norm(), 1e-13 * outEigen.norm());
}

TEST(HexElement, PatchTestLinearFieldIsReproducedAtInteriorNodes) {
  // 4 x 4 x 4 cells: impose u = A X + c on the boundary nodes, solve K_ii u_i = -K_ib u_b.
  VoxelGrid vox;
  vox.cellSize = 0.01;
  vox.origin = Vec3(0.1, -0.2, 0.05);
  vox.dims = Vec3i(4, 4, 4);
  vox.state.assign(64, CellState::Inside);
  for (int k = 0; k < 4; ++k)
    for (int j = 0; j < 4; ++j)
      for (int i = 0; i < 4; ++i) vox.cells.emplace_back(i, j, k);
  const HexGrid g = hexGridFromVoxels(vox);
  ASSERT_EQ(g.numNodes(), 125);
  for (int incompatible = 0; incompatible < 2; ++incompatible) {
    SCOPED_TRACE(incompatible ? "incompatible modes" : "trilinear");
    const Mat24 K0 = incompatible ? hexStiffnessIncompatible(Vec3::Constant(vox.cellSize), kE, kNu)
                                  : hexStiffness(Vec3::Constant(vox.cellSize), kE, kNu);
    const int n = 3 * g.numNodes();
    MatX K = MatX::Zero(n, n);
    for (const auto& hex : g.hexes)
      for (int a = 0; a < 8; ++a)
        for (int b = 0; b < 8; ++b)
          K.block<3, 3>(3 * hex[a], 3 * hex[b]) += K0.block<3, 3>(3 * a, 3 * b);
    const Mat3 A = (Mat3() << 0.01, -0.02, 0.005, 0.03, 0.0, -0.01, 0.002, 0.015, -0.02).finished();
    const Vec3 c(1e-3, -2e-3, 5e-4);
    std::vector<int> interior, boundary;
    const Box bb = boundingBox(g.nodes);
    for (int v = 0; v < g.numNodes(); ++v) {
      const Vec3 p = g.nodes.row(v);
      const bool onBoundary =
          ((p - bb.lo).cwiseAbs().minCoeff() < 1e-9) || ((p - bb.hi).cwiseAbs().minCoeff() < 1e-9);
      (onBoundary ? boundary : interior).push_back(v);
    }
    ASSERT_EQ(interior.size(), 27u);
    const int ni = 3 * static_cast<int>(interior.size()),
              nb = 3 * static_cast<int>(boundary.size());
    MatX Kii(ni, ni), Kib(ni, nb);
    VecX ub(nb);
    for (size_t a = 0; a < interior.size(); ++a) {
      for (size_t b = 0; b < interior.size(); ++b)
        Kii.block<3, 3>(3 * a, 3 * b) = K.block<3, 3>(3 * interior[a], 3 * interior[b]);
      for (size_t b = 0; b < boundary.size(); ++b)
        Kib.block<3, 3>(3 * a, 3 * b) = K.block<3, 3>(3 * interior[a], 3 * boundary[b]);
    }
    for (size_t b = 0; b < boundary.size(); ++b)
      ub.segment<3>(3 * b) = A * g.nodes.row(boundary[b]).transpose() + c;
    const VecX ui = Kii.ldlt().solve(-Kib * ub);
    for (size_t a = 0; a < interior.size(); ++a) {
      const Vec3 expected = A * g.nodes.row(interior[a]).transpose() + c;
      EXPECT_LT((ui.segment<3>(3 * a) - expected).norm(), 1e-12) << "node " << interior[a];
    }
  }
}

TEST(HexElement, TrilinearWeightsPartitionUnityAndReproduceCorners) {
  const Eigen::Matrix<Real, 8, 1> w = hexTrilinearWeights(Vec3(0.2, 0.7, 0.4));
  EXPECT_NEAR(w.sum(), 1.0, 1e-15);
  for (int a = 0; a < 8; ++a) {
    const Eigen::Matrix<Real, 8, 1> wa = hexTrilinearWeights(hexCorner(a).cast<Real>());
    EXPECT_EQ(wa[a], 1.0);
    EXPECT_EQ(wa.sum(), 1.0);
  }
}

// Pure bending of one element, u_x = kappa x z, u_z = -kappa x^2 / 2 (the element centred at the
// origin, the beam axis along x, curvature kappa): the exact strain
// is eps_xx = kappa z, no shear, with energy E I kappa^2 L / 2 for a uniaxial state (nu = 0). The
// trilinear element adds a spurious shear gamma_xz = kappa x, so it stores more energy (it locks);
// with the incompatible modes the nodal values of the exact field give exactly the bending energy.
TEST(HexElement, IncompatibleModesBendWithoutSpuriousShear) {
  const Vec3 size(0.04, 0.01, 0.01);
  const Real kappa = 0.5, E = 1e6;
  Mat38 u;
  for (int a = 0; a < 8; ++a) {
    const Vec3 x = (hexCorner(a).cast<Real>() - Vec3::Constant(0.5)).cwiseProduct(size);
    u.col(a) = Vec3(kappa * x.x() * x.z(), 0, -0.5 * kappa * x.x() * x.x());
  }
  const Vec24 uv = Eigen::Map<const Vec24>(u.data());
  const Real I = size.y() * size.z() * size.z() * size.z() / 12;
  const Real exact = 0.5 * E * I * kappa * kappa * size.x();
  const Real trilinear = 0.5 * uv.dot(hexStiffness(size, E, 0.0) * uv);
  const Real incompatible = 0.5 * uv.dot(hexStiffnessIncompatible(size, E, 0.0) * uv);
  std::printf("bending energy: exact %.6g J, trilinear %.6g J, incompatible modes %.6g J\n", exact,
              trilinear, incompatible);
  EXPECT_NEAR(incompatible, exact, 1e-9 * exact);
  // The spurious shear energy is (L/t)^2 / 2 = 8 times the bending energy at aspect 4.
  EXPECT_NEAR(trilinear, 9 * exact, 1e-9 * exact);
}

}  // namespace
}  // namespace deform::fem_hex
