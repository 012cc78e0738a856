// Property tests of the PBD constraint kernels: each constraint is satisfied after projection,
// mass-weighted corrections sum to zero, nothing moves at rest, degenerate input is refused,
// XPBD tends to the hard constraint as compliance -> 0, and the classic stiffness correction
// makes the effective stiffness independent of the iteration count.
#include "../support/meshes.h"
#include "pbd_constraints.h"

#include <deform/kernels/tet_volume_batch.h>

#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <vector>

namespace deform::pbd {
namespace {

Vec3 randomVec(std::mt19937& rng, Real s = 1.0) {
  std::uniform_real_distribution<Real> u(-s, s);
  return Vec3(u(rng), u(rng), u(rng));
}

Vec3 momentum(const Vec3 dx[], const Real w[], int n) {
  Vec3 p = Vec3::Zero();
  for (int i = 0; i < n; ++i)
    if (w[i] > 0) p += dx[i] / w[i];
  return p;
}

// ---- distance ----

TEST(PbdDistance, SatisfiedAfterOneProjection) {
  std::mt19937 rng(1);
  for (int trial = 0; trial < 20; ++trial) {
    const Vec3 xa = randomVec(rng), xb = randomVec(rng);
    const Real wa = 0.5 + trial % 3, wb = 1.0 + trial % 2, rest = 0.3 + 0.05 * trial;
    Real lambda = 0;
    Vec3 dxa, dxb;
    ASSERT_TRUE(projectDistance(xa, xb, wa, wb, rest, 0.0, 1.0, lambda, dxa, dxb));
    EXPECT_NEAR(((xa + dxa) - (xb + dxb)).norm(), rest, 1e-12);
    // Mass-weighted corrections sum to zero, with equal and unequal masses.
    EXPECT_LT((dxa / wa + dxb / wb).norm(), 1e-12);
  }
}

TEST(PbdDistance, NothingMovesAtRest) {
  const Vec3 xa(0.1, 0.2, 0.3), xb(-0.2, 0.4, 0.0);
  Real lambda = 0;
  Vec3 dxa, dxb;
  ASSERT_TRUE(projectDistance(xa, xb, 1.0, 1.0, (xa - xb).norm(), 0.0, 1.0, lambda, dxa, dxb));
  EXPECT_EQ(dxa.norm(), 0.0);
  EXPECT_EQ(dxb.norm(), 0.0);
}

TEST(PbdDistance, DegenerateInputIsRefused) {
  const Vec3 x(0.1, 0.2, 0.3);
  Real lambda = 0;
  Vec3 dxa, dxb;
  EXPECT_FALSE(projectDistance(x, x, 1.0, 1.0, 0.5, 0.0, 1.0, lambda, dxa, dxb));
  EXPECT_FALSE(projectDistance(x, Vec3(1, 2, 3), 0.0, 0.0, 0.5, 0.0, 1.0, lambda, dxa, dxb));
  EXPECT_EQ(lambda, 0.0);
}

// XPBD on one distance constraint has the closed form C* = C0 at / (wa + wb + at) (the
// constraint is linear along its own direction): iterating must reach it, and C* -> 0 as
// alpha -> 0.
TEST(PbdDistance, XpbdConvergesToTheConstraintAsComplianceVanishes) {
  const Real rest = 1.0, stretch = 0.2;
  Real previous = 1e300;
  for (Real at : {1.0, 1e-2, 1e-4, 1e-8, 1e-14}) {
    Vec3 xa(0, 0, 0), xb(rest + stretch, 0, 0);
    Real lambda = 0;
    for (int it = 0; it < 50; ++it) {
      Vec3 dxa, dxb;
      ASSERT_TRUE(projectDistance(xa, xb, 1.0, 1.0, rest, at, 1.0, lambda, dxa, dxb));
      xa += dxa;
      xb += dxb;
    }
    const Real C = (xa - xb).norm() - rest;
    EXPECT_NEAR(C, stretch * at / (2.0 + at), 1e-12);
    EXPECT_LT(std::abs(C), previous);
    previous = std::abs(C);
  }
  EXPECT_LT(previous, 1e-14);
}

// k' = 1 - (1 - k)^(1/n) applied n times leaves (1 - k) of the error for every n.
TEST(PbdDistance, ClassicStiffnessCorrectionIsIndependentOfIterationCount) {
  const Real k = 0.3, rest = 1.0, stretch = 0.1;
  for (int n : {1, 2, 5, 10, 40}) {
    const Real kp = classicStiffness(k, n);
    EXPECT_GT(kp, 0.0);
    EXPECT_LE(kp, k + 1e-15);
    Vec3 xa(0, 0, 0), xb(0, rest + stretch, 0);
    for (int it = 0; it < n; ++it) {
      Real lambda = 0;
      Vec3 dxa, dxb;
      ASSERT_TRUE(projectDistance(xa, xb, 1.0, 2.0, rest, 0.0, kp, lambda, dxa, dxb));
      xa += dxa;
      xb += dxb;
    }
    EXPECT_NEAR((xa - xb).norm() - rest, (1.0 - k) * stretch, 1e-12) << "n = " << n;
  }
  EXPECT_EQ(classicStiffness(1.0, 7), 1.0);
  EXPECT_EQ(classicStiffness(0.0, 7), 0.0);
}

// The colour kernel (padded positions, SIMD when available) equals projecting the constraints of
// one colour one by one with projectDistance(), and its SIMD and scalar paths agree to rounding.
TEST(PbdDistance, ColourKernelMatchesSequentialProjection) {
  std::mt19937 rng(7);
  const int n = 23;  // not a multiple of the vector width: exercises the tail
  std::vector<Vec3> x(2 * n);
  for (auto& p : x) p = randomVec(rng);
  x[2 * 5 + 1] = x[2 * 5];  // one degenerate constraint
  std::vector<int> a(n), b(n);
  std::vector<Real> rest(n), at(n), scale(n), wa(n), wb(n), lam1(n, 0.01), lam2(n, 0.01),
      lam3(n, 0.01);
  for (int i = 0; i < n; ++i) {
    a[i] = 2 * i;
    b[i] = 2 * i + 1;
    rest[i] = 0.5 + 0.01 * i;
    at[i] = (i % 3) * 0.1;
    wa[i] = 1.0 + 0.1 * (i % 4);
    wb[i] = (i % 5 == 0) ? 0.0 : 0.7;
    scale[i] = 1.0 / (wa[i] + wb[i] + at[i]);
  }
  auto pad = [&] {
    std::vector<Real> x4(8 * n, 0.0);
    for (int i = 0; i < 2 * n; ++i)
      for (int k = 0; k < 3; ++k) x4[4 * i + k] = x[i][k];
    return x4;
  };
  std::vector<Real> simd = pad(), scalar = pad();
  const DistanceBatch b1{a.data(),     b.data(),    rest.data(), at.data(),
                         scale.data(), lam1.data(), wa.data(),   wb.data()};
  const DistanceBatch b2{a.data(),     b.data(),    rest.data(), at.data(),
                         scale.data(), lam2.data(), wa.data(),   wb.data()};
  EXPECT_EQ(projectDistanceColourPadded(simd.data(), b1, 0, n, true), 1);
  EXPECT_EQ(projectDistanceColourPadded(scalar.data(), b2, 0, n, false), 1);
  // AVX2 repeats the scalar arithmetic exactly; AVX-512 replaces sqrt and division by a refined
  // reciprocal square root, equal to rounding.
  for (size_t i = 0; i < simd.size(); ++i) EXPECT_NEAR(simd[i], scalar[i], 1e-14) << i;
  for (int i = 0; i < n; ++i) EXPECT_NEAR(lam1[i], lam2[i], 1e-14) << i;
  for (int i = 0; i < n; ++i) {
    Vec3 dxa, dxb;
    if (!projectDistance(x[a[i]], x[b[i]], wa[i], wb[i], rest[i], at[i], 1.0, lam3[i], dxa, dxb))
      continue;
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(simd[4 * a[i] + k], x[a[i]][k] + dxa[k], 1e-14);
      EXPECT_NEAR(simd[4 * b[i] + k], x[b[i]][k] + dxb[k], 1e-14);
    }
    EXPECT_NEAR(lam1[i], lam3[i], 1e-14);
    EXPECT_EQ(simd[4 * a[i] + 3], 0.0);
  }
}

// ---- single precision (precision = float32) ----

struct FloatColour {
  int n;
  std::vector<Vec3> x;  // 2 n particles, constraint i joins 2 i and 2 i + 1
  std::vector<int> a4, b4;
  std::vector<float> rest, at, scale, wa, wb;
  std::vector<Real> restD, atD, scaleD, waD, wbD;
  explicit FloatColour(int count) : n(count), x(2 * count), a4(count), b4(count) {
    std::mt19937 rng(11);
    for (auto& p : x) p = randomVec(rng, 0.1);
    x[2 * 5 + 1] = x[2 * 5];  // one degenerate constraint (in the first vector group)
    for (int i = 0; i < n; ++i) {
      a4[i] = 4 * (2 * i);
      b4[i] = 4 * (2 * i + 1);
      restD.push_back(0.05 + 0.002 * i);
      atD.push_back((i % 3) * 0.1);
      waD.push_back(1.0 + 0.1 * (i % 4));
      wbD.push_back((i % 5 == 0) ? 0.0 : 0.7);
      scaleD.push_back(1.0 / (waD[i] + wbD[i] + atD[i]));
      rest.push_back(static_cast<float>(restD[i]));
      at.push_back(static_cast<float>(atD[i]));
      scale.push_back(static_cast<float>(scaleD[i]));
      wa.push_back(static_cast<float>(waD[i]));
      wb.push_back(static_cast<float>(wbD[i]));
    }
  }
  std::vector<float> padded() const {  // 16-byte aligned: 4 floats of headroom, offset returned
    std::vector<float> x4(8 * static_cast<size_t>(n) + 4, 0.0f);
    return x4;
  }
};

float* alignedRows(std::vector<float>& storage, const std::vector<Vec3>& x) {
  const auto base = reinterpret_cast<std::uintptr_t>(storage.data());
  float* p = storage.data() + ((16 - base % 16) % 16) / sizeof(float);
  for (size_t i = 0; i < x.size(); ++i)
    for (int k = 0; k < 3; ++k) p[4 * i + k] = static_cast<float>(x[i][k]);
  return p;
}

// The float colour kernel: the fastest SIMD path of this CPU against its scalar reference, and
// both against the double kernel. n = 37: two (AVX-512) or four (AVX2) vector steps and a tail.
TEST(PbdDistanceFloat, ColourKernelMatchesScalarReferenceAndDoublePath) {
  const FloatColour c(37);
  std::vector<float> s1 = c.padded(), s2 = c.padded();
  float* simd = alignedRows(s1, c.x);
  float* scalar = alignedRows(s2, c.x);
  std::vector<float> lam1(c.n, 0.01f), lam2(c.n, 0.01f);
  const DistanceBatchF b1{c.a4.data(),    c.b4.data(), c.rest.data(), c.at.data(),
                          c.scale.data(), lam1.data(), c.wa.data(),   c.wb.data()};
  DistanceBatchF b2 = b1;
  b2.lambda = lam2.data();
  EXPECT_EQ(projectDistanceColourPaddedF(simd, b1, 0, c.n, true), 1);
  EXPECT_EQ(projectDistanceColourPaddedF(scalar, b2, 0, c.n, false), 1);
  // The AVX-512 path replaces sqrt and division by rsqrt14 + one Newton step (relative error
  // ~2^-27) and may fuse multiply-adds: a few float roundings (2^-24 each) of values below 0.2 m,
  // so 1e-7 m (~12 ulp at 0.2) bounds the difference.
  for (int i = 0; i < 8 * c.n; ++i) EXPECT_NEAR(simd[i], scalar[i], 1e-7) << i;
  for (int i = 0; i < c.n; ++i) EXPECT_NEAR(lam1[i], lam2[i], 1e-6 * std::abs(lam2[i]) + 1e-9);
  for (int i = 0; i < 2 * c.n; ++i) EXPECT_EQ(simd[4 * i + 3], 0.0f);
  // Against the double kernel: the float inputs are rounded (2^-24 relative); the corrections
  // are O(|C|) <= 0.2 m, so 1e-6 m (~16 ulp) bounds the difference.
  std::vector<Real> x4(8 * c.n, 0.0);
  for (int i = 0; i < 2 * c.n; ++i)
    for (int k = 0; k < 3; ++k) x4[4 * i + k] = c.x[i][k];
  std::vector<int> a(c.n), b(c.n);
  for (int i = 0; i < c.n; ++i) {
    a[i] = c.a4[i] / 4;
    b[i] = c.b4[i] / 4;
  }
  std::vector<Real> lam3(c.n, 0.01);
  const DistanceBatch bd{a.data(),        b.data(),    c.restD.data(), c.atD.data(),
                         c.scaleD.data(), lam3.data(), c.waD.data(),   c.wbD.data()};
  EXPECT_EQ(projectDistanceColourPadded(x4.data(), bd, 0, c.n, false), 1);
  for (int i = 0; i < 8 * c.n; ++i) EXPECT_NEAR(simd[i], x4[i], 1e-6) << i;
  // and the constraints moved (the comparison is not vacuous)
  Real moved = 0;
  for (int i = 0; i < 2 * c.n; ++i)
    for (int k = 0; k < 3; ++k) moved = std::max(moved, std::abs(x4[4 * i + k] - c.x[i][k]));
  EXPECT_GT(moved, 1e-3);
}

// The AVX2 path (CPUs without AVX-512) is the scalar reference bit for bit: the same exactly
// rounded sqrt and division in the same order, and lengths measured on the scalar path are at
// rest in it. n = 45: two steps of 16, one of 8 and a tail of 5 (the degenerate constraint is 5).
TEST(PbdDistanceFloat, Avx2ColourKernelIsTheScalarReferenceBitForBit) {
  if (fastestFloatPath() == FloatPath::Scalar) GTEST_SKIP() << "this CPU has no AVX2";
  const FloatColour c(45);
  std::vector<float> s1 = c.padded(), s2 = c.padded();
  float* avx2 = alignedRows(s1, c.x);
  float* scalar = alignedRows(s2, c.x);
  std::vector<float> lam1(c.n, 0.01f), lam2(c.n, 0.01f);
  const DistanceBatchF b1{c.a4.data(),    c.b4.data(), c.rest.data(), c.at.data(),
                          c.scale.data(), lam1.data(), c.wa.data(),   c.wb.data()};
  DistanceBatchF b2 = b1;
  b2.lambda = lam2.data();
  EXPECT_EQ(projectDistanceColourPaddedF(avx2, b1, 0, c.n, FloatPath::Avx2), 1);
  EXPECT_EQ(projectDistanceColourPaddedF(scalar, b2, 0, c.n, FloatPath::Scalar), 1);
  for (int i = 0; i < 8 * c.n; ++i) EXPECT_EQ(avx2[i], scalar[i]) << i;
  for (int i = 0; i < c.n; ++i) EXPECT_EQ(lam1[i], lam2[i]) << i;
  EXPECT_GT(std::abs(avx2[0] - static_cast<float>(c.x[0][0])), 1e-4f);  // it moved

  FloatColour r(45);
  r.x[2 * 5 + 1] += Vec3(0.01, 0, 0);
  std::vector<float> s3 = r.padded();
  float* x = alignedRows(s3, r.x);
  const std::vector<float> before(x, x + 8 * r.n);
  std::vector<float> rest(r.n), lam(r.n, 0.0f);
  distanceLengthsColourF(x, r.a4.data(), r.b4.data(), 0, r.n, rest.data(), false);
  const DistanceBatchF br{r.a4.data(),    r.b4.data(), rest.data(), r.at.data(),
                          r.scale.data(), lam.data(),  r.wa.data(), r.wb.data()};
  EXPECT_EQ(projectDistanceColourPaddedF(x, br, 0, r.n, FloatPath::Avx2), 0);
  for (int i = 0; i < 8 * r.n; ++i) EXPECT_EQ(x[i], before[i]) << i;
}

// Rest lengths measured with distanceLengthsColourF give C = 0 bit for bit in the kernel: a
// colour at rest does not move, on either path.
TEST(PbdDistanceFloat, LengthsMeasuredByTheKernelArithmeticAreExactlyAtRest) {
  FloatColour c(37);
  c.x[2 * 5 + 1] += Vec3(0.01, 0, 0);  // no degenerate constraint here
  for (bool simd : {true, false}) {
    std::vector<float> s = c.padded();
    float* x = alignedRows(s, c.x);
    const std::vector<float> before(x, x + 8 * c.n);
    std::vector<float> rest(c.n), lam(c.n, 0.0f);
    distanceLengthsColourF(x, c.a4.data(), c.b4.data(), 0, c.n, rest.data(), simd);
    const DistanceBatchF bf{c.a4.data(),    c.b4.data(), rest.data(), c.at.data(),
                            c.scale.data(), lam.data(),  c.wa.data(), c.wb.data()};
    EXPECT_EQ(projectDistanceColourPaddedF(x, bf, 0, c.n, simd), 0);
    for (int i = 0; i < 8 * c.n; ++i) EXPECT_EQ(x[i], before[i]) << i << " simd " << simd;
    for (int i = 0; i < c.n; ++i) EXPECT_EQ(lam[i], 0.0f);
  }
}

// The float volume projection: SIMD rows and scalar reference identical (same operations in the
// same order), and close to the double projection.
TEST(PbdSurfaceVolumeFloat, RowsMatchScalarAndDouble) {
  const SurfaceMesh m = testing::uvEllipsoid(8, 12, 0.05, 0.04, 0.03);
  const Eigen::Index n = m.numVertices();
  const Real v0 = signedVolume(m.V, m.F);
  VecX w(n);
  for (Eigen::Index i = 0; i < n; ++i) w[i] = 1.0 + 0.1 * (i % 5);
  std::vector<Vec3> x(n);
  for (Eigen::Index i = 0; i < n; ++i) x[i] = 1.1 * Vec3(m.V.row(i));
  std::vector<float> s1(4 * n + 4), s2(4 * n + 4), g1(4 * n), g2(4 * n);
  float* simd = alignedRows(s1, x);
  float* scalar = alignedRows(s2, x);
  Real lam1 = 0, lam2 = 0;
  ASSERT_TRUE(
      projectSurfaceVolumePaddedF(simd, n, w.data(), m.F, v0, 0.0, 1.0, lam1, g1.data(), true));
  ASSERT_TRUE(
      projectSurfaceVolumePaddedF(scalar, n, w.data(), m.F, v0, 0.0, 1.0, lam2, g2.data(), false));
  EXPECT_EQ(lam1, lam2);
  for (Eigen::Index i = 0; i < 4 * n; ++i) EXPECT_EQ(simd[i], scalar[i]) << i;
  EXPECT_EQ(surfaceVolumePaddedF(simd, n, m.F, true), surfaceVolumePaddedF(simd, n, m.F, false));
  std::vector<Real> xd(4 * n, 0.0), gd(4 * n);
  for (Eigen::Index i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) xd[4 * i + k] = x[i][k];
  Real lam3 = 0;
  ASSERT_TRUE(
      projectSurfaceVolumePadded(xd.data(), n, w.data(), m.F, v0, 0.0, 1.0, lam3, gd.data()));
  // Positions ~0.06 m in float (ulp 4e-9 m): the corrections (~3 mm) agree to 1e-7 m.
  Real moved = 0;
  for (Eigen::Index i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) {
      EXPECT_NEAR(simd[4 * i + k], xd[4 * i + k], 1e-7);
      moved = std::max(moved, std::abs(xd[4 * i + k] - x[i][k]));
    }
  EXPECT_GT(moved, 1e-4);
  EXPECT_NEAR(lam1, lam3, 1e-5 * std::abs(lam3));
}

// ---- dihedral ----

struct Hinge {
  Vec3 x[4];
};

Hinge randomHinge(std::mt19937& rng) {
  Hinge h;
  h.x[2] = Vec3(0, 0, 0) + randomVec(rng, 0.1);
  h.x[3] = Vec3(1, 0, 0) + randomVec(rng, 0.1);
  h.x[0] = Vec3(0.5, -0.8, 0) + randomVec(rng, 0.3);
  h.x[1] = Vec3(0.5, 0.8, 0) + randomVec(rng, 0.3);
  return h;
}

TEST(PbdDihedral, GradientMatchesFiniteDifferences) {
  std::mt19937 rng(2);
  for (int trial = 0; trial < 20; ++trial) {
    Hinge h = randomHinge(rng);
    Real theta;
    Vec3 g[4];
    ASSERT_TRUE(dihedralAngle(h.x[0], h.x[1], h.x[2], h.x[3], theta, g));
    const Real eps = 1e-6;
    for (int i = 0; i < 4; ++i) {
      for (int k = 0; k < 3; ++k) {
        Hinge hp = h, hm = h;
        hp.x[i][k] += eps;
        hm.x[i][k] -= eps;
        Real tp, tm;
        Vec3 gg[4];
        ASSERT_TRUE(dihedralAngle(hp.x[0], hp.x[1], hp.x[2], hp.x[3], tp, gg));
        ASSERT_TRUE(dihedralAngle(hm.x[0], hm.x[1], hm.x[2], hm.x[3], tm, gg));
        EXPECT_NEAR((tp - tm) / (2 * eps), g[i][k], 1e-6) << "vertex " << i << " axis " << k;
      }
    }
    EXPECT_LT((g[0] + g[1] + g[2] + g[3]).norm(), 1e-12);
  }
}

TEST(PbdDihedral, FlatHingeHasZeroAngle) {
  Real theta;
  Vec3 g[4];
  ASSERT_TRUE(
      dihedralAngle(Vec3(0.5, -1, 0), Vec3(0.5, 1, 0), Vec3(0, 0, 0), Vec3(1, 0, 0), theta, g));
  EXPECT_NEAR(theta, 0.0, 1e-15);
  EXPECT_TRUE(g[0].allFinite() && g[1].allFinite());
}

TEST(PbdDihedral, ProjectionSatisfiesConstraintAndConservesMomentum) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 10; ++trial) {
    Hinge h = randomHinge(rng);
    const Real w[4] = {1.0, 2.0, 0.5, 1.5};
    const Real target = 0.4 * (trial % 2 ? 1 : -1);
    Real lambda = 0;
    for (int it = 0; it < 30; ++it) {
      Vec3 dx[4];
      ASSERT_TRUE(projectDihedral(h.x, w, target, 0.0, 1.0, lambda, dx));
      EXPECT_LT(momentum(dx, w, 4).norm(), 1e-12);
      for (int i = 0; i < 4; ++i) h.x[i] += dx[i];
    }
    Real theta;
    Vec3 g[4];
    ASSERT_TRUE(dihedralAngle(h.x[0], h.x[1], h.x[2], h.x[3], theta, g));
    EXPECT_NEAR(theta, target, 1e-9);
  }
}

TEST(PbdDihedral, NothingMovesAtRest) {
  std::mt19937 rng(4);
  Hinge h = randomHinge(rng);
  Real theta;
  Vec3 g[4], dx[4];
  ASSERT_TRUE(dihedralAngle(h.x[0], h.x[1], h.x[2], h.x[3], theta, g));
  const Real w[4] = {1, 1, 1, 1};
  Real lambda = 0;
  ASSERT_TRUE(projectDihedral(h.x, w, theta, 0.0, 1.0, lambda, dx));
  for (int i = 0; i < 4; ++i) EXPECT_EQ(dx[i].norm(), 0.0);
}

TEST(PbdDihedral, DegenerateInputIsRefused) {
  const Real w[4] = {1, 1, 1, 1};
  Real lambda = 0;
  Vec3 dx[4];
  // Wing vertex on the hinge line: zero-area triangle.
  const Vec3 collapsed[4] = {Vec3(0.5, 0, 0), Vec3(0.5, 1, 0), Vec3(0, 0, 0), Vec3(1, 0, 0)};
  EXPECT_FALSE(projectDihedral(collapsed, w, 0.0, 0.0, 1.0, lambda, dx));
  // Zero-length hinge edge.
  const Vec3 shortEdge[4] = {Vec3(0.5, -1, 0), Vec3(0.5, 1, 0), Vec3(0, 0, 0), Vec3(0, 0, 0)};
  EXPECT_FALSE(projectDihedral(shortEdge, w, 0.0, 0.0, 1.0, lambda, dx));
  // All immovable.
  const Real w0[4] = {0, 0, 0, 0};
  const Vec3 ok[4] = {Vec3(0.5, -1, 0.2), Vec3(0.5, 1, 0), Vec3(0, 0, 0), Vec3(1, 0, 0)};
  EXPECT_FALSE(projectDihedral(ok, w0, 0.0, 0.0, 1.0, lambda, dx));
}

// ---- tet volume ----

TEST(PbdTetVolume, ProjectionSatisfiesConstraintAndConservesMomentum) {
  std::mt19937 rng(5);
  for (int trial = 0; trial < 10; ++trial) {
    Vec3 x[4] = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)};
    for (auto& p : x) p += randomVec(rng, 0.1);
    const Real v0 = tetVolume(x[0], x[1], x[2], x[3]);
    for (auto& p : x) p *= 1.2;  // 73% too large
    const Real w[4] = {1.0, 0.5, 2.0, 1.0};
    Real lambda = 0;
    for (int it = 0; it < 20; ++it) {
      Vec3 dx[4];
      ASSERT_TRUE(projectTetVolume(x, w, v0, 0.0, 1.0, lambda, dx));
      EXPECT_LT(momentum(dx, w, 4).norm(), 1e-12);
      for (int i = 0; i < 4; ++i) x[i] += dx[i];
    }
    EXPECT_NEAR(tetVolume(x[0], x[1], x[2], x[3]), v0, 1e-12);
  }
}

TEST(PbdTetVolume, NothingMovesAtRestAndDegenerateIsRefused) {
  const Vec3 x[4] = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(0, 0, 1)};
  const Real w[4] = {1, 1, 1, 1};
  Real lambda = 0;
  Vec3 dx[4];
  ASSERT_TRUE(projectTetVolume(x, w, 1.0 / 6.0, 0.0, 1.0, lambda, dx));
  for (int i = 0; i < 4; ++i) EXPECT_EQ(dx[i].norm(), 0.0);
  // All four nodes at one point (zero gradients) and collinear nodes.
  const Vec3 point[4] = {Vec3(1, 1, 1), Vec3(1, 1, 1), Vec3(1, 1, 1), Vec3(1, 1, 1)};
  EXPECT_FALSE(projectTetVolume(point, w, 1.0 / 6.0, 0.0, 1.0, lambda, dx));
  const Vec3 line[4] = {Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(2, 0, 0), Vec3(3, 0, 0)};
  EXPECT_FALSE(projectTetVolume(line, w, 1.0 / 6.0, 0.0, 1.0, lambda, dx));
  EXPECT_EQ(lambda, 0.0);
}

// ---- global surface volume ----

// A colour of 13 tets on 52 particles (no two share a particle; particle 0 immovable), their
// rest volumes, the stretched positions x4 and the batch's arrays; tet 5 collapsed to a segment.
template <class T>
struct TetColour {
  static constexpr int kTets = 13;
  std::vector<T> x4, w[4], rest, floor, alphaTilde, lambda;
  std::vector<int> p[4];
  std::vector<Real> restD;  // the double rest volumes (projectTetVolume's)
  explicit TetColour(Real compliance) {
    std::mt19937 rng(11);
    x4.assign(4 * 4 * kTets, T(0));
    for (int k = 0; k < 4; ++k) {
      p[k].resize(kTets);
      w[k].resize(kTets);
    }
    for (int t = 0; t < kTets; ++t) {
      Vec3 x[4] = {Vec3(0, 0, 0), Vec3(0.01, 0, 0), Vec3(0, 0.01, 0), Vec3(0, 0, 0.01)};
      for (auto& q : x) q += randomVec(rng, 0.002) + Vec3(0.03 * t, 0, 0);
      if (t == 5) x[2] = x[3] = 0.5 * (x[0] + x[1]);  // a segment: refused
      restD.push_back(t == 5 ? 1e-6 : tetVolume(x[0], x[1], x[2], x[3]));
      for (int k = 0; k < 4; ++k) {
        const int particle = 4 * t + k;
        p[k][t] = 4 * particle;
        w[k][t] = T(particle == 0 ? 0.0 : 1.0 + 0.25 * ((t + k) % 3));
        const Vec3 moved = t == 5 ? x[k] : Vec3(x[k] * 1.1 + randomVec(rng, 5e-4));
        for (int c = 0; c < 3; ++c) x4[4 * particle + c] = T(moved[c]);
      }
    }
    for (const Real v0 : restD) {
      rest.push_back(T(v0));
      floor.push_back(T(tetVolumeGradientFloor(v0)));
      alphaTilde.push_back(T(compliance * 1e-9));  // |g|^2 is ~1e-10 m^4
    }
    lambda.assign(kTets, T(0));
  }
  TetVolumeBatch<T> batch(T k) { return tetVolumeBatch(p, w, rest, floor, alphaTilde, lambda, k); }
};

TEST(PbdTetVolume, ColourKernelIsTheOneAtATimeRuleBitForBit) {
  for (const Real compliance : {0.0, 1.0}) {
    for (const bool simd : {false, true}) {
      TetColour<Real> c(compliance);
      std::vector<Real> x4 = c.x4, lambda(TetColour<Real>::kTets, 0.0);
      int refused = 0;
      for (int it = 0; it < 3; ++it) {
        EXPECT_EQ(
            projectTetVolumeColour(c.x4.data(), c.batch(0.8), 0, TetColour<Real>::kTets, simd), 1);
        for (int t = 0; t < TetColour<Real>::kTets; ++t) {
          Vec3 x[4], dx[4];
          Real w[4];
          for (int k = 0; k < 4; ++k) {
            x[k] = Vec3(x4[c.p[k][t]], x4[c.p[k][t] + 1], x4[c.p[k][t] + 2]);
            w[k] = c.w[k][t];
          }
          if (!projectTetVolume(x, w, c.restD[t], c.alphaTilde[t], 0.8, lambda[t], dx)) {
            ++refused;
            continue;
          }
          for (int k = 0; k < 4; ++k)
            for (int d = 0; d < 3; ++d) x4[c.p[k][t] + d] += dx[k][d];
        }
      }
      EXPECT_EQ(refused, 3);
      for (size_t i = 0; i < x4.size(); ++i) ASSERT_EQ(c.x4[i], x4[i]) << i;
      for (int t = 0; t < TetColour<Real>::kTets; ++t) EXPECT_EQ(c.lambda[t], lambda[t]);
      EXPECT_EQ(c.x4[0], TetColour<Real>(compliance).x4[0]);  // the immovable particle
    }
  }
}

TEST(PbdTetVolume, FloatPathsAgreeAndMeasuredRestVolumesAreExactlyAtRest) {
  TetColour<float> scalar(1.0), vector(1.0);
  for (int it = 0; it < 3; ++it) {
    projectTetVolumeColour(scalar.x4.data(), scalar.batch(1.0f), 0, 13, false);
    projectTetVolumeColour(vector.x4.data(), vector.batch(1.0f), 0, 13, true);
  }
  EXPECT_EQ(scalar.x4, vector.x4);
  EXPECT_EQ(scalar.lambda, vector.lambda);
  EXPECT_NE(scalar.x4, TetColour<float>(1.0).x4);  // it moved something
  // Volumes measured with the kernel's own arithmetic are its rest: nothing moves.
  TetColour<float> rest(0.0);
  std::vector<float> measured(13);
  tetVolumesColour(rest.x4.data(), rest.batch(1.0f), 0, 13, measured.data());
  rest.rest = measured;
  const std::vector<float> before = rest.x4;
  projectTetVolumeColour(rest.x4.data(), rest.batch(1.0f), 0, 13);
  EXPECT_EQ(rest.x4, before);
}

TEST(PbdSurfaceVolume, RestoresVolumeConservesMomentumAndRestsAtRest) {
  const SurfaceMesh m = testing::uvEllipsoid(8, 12, 0.05, 0.04, 0.03);
  const Real v0 = signedVolume(m.V, m.F);
  ASSERT_GT(v0, 0.0);
  VecX w(m.numVertices());
  for (int i = 0; i < m.numVertices(); ++i) w[i] = 1.0 + 0.1 * (i % 5);
  MatX3 grad, dx;
  Real lambda = 0;
  // At rest: corrections vanish (up to round-off of the volume sum).
  ASSERT_TRUE(projectSurfaceVolume(m.V, w, m.F, v0, 0.0, 1.0, lambda, grad, dx));
  EXPECT_LT(dx.cwiseAbs().maxCoeff(), 1e-14);
  // Inflated by 10% in each direction: projections bring the volume back.
  MatX3 x = 1.1 * m.V;
  lambda = 0;
  for (int it = 0; it < 10; ++it) {
    ASSERT_TRUE(projectSurfaceVolume(x, w, m.F, v0, 0.0, 1.0, lambda, grad, dx));
    Vec3 p = Vec3::Zero();
    for (int i = 0; i < x.rows(); ++i) p += dx.row(i).transpose() / w[i];
    EXPECT_LT(p.norm(), 1e-15);
    x += dx;
  }
  EXPECT_NEAR(signedVolume(x, m.F), v0, 1e-12 * v0);
}

TEST(PbdSurfaceVolume, AllImmovableIsRefused) {
  const SurfaceMesh m = testing::uvEllipsoid(4, 6, 0.05, 0.04, 0.03);
  const VecX w = VecX::Zero(m.numVertices());
  MatX3 grad, dx;
  Real lambda = 0;
  EXPECT_FALSE(
      projectSurfaceVolume(1.1 * m.V, w, m.F, signedVolume(m.V, m.F), 0.0, 1.0, lambda, grad, dx));
}

}  // namespace
}  // namespace deform::pbd
