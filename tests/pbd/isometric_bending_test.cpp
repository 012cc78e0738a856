// The isometric bending constraint (deform/kernels/isometric_bending.h): its gradient against
// central finite differences, zero at a flat and at a curved rest shape, invariance to rigid
// motions, the flat-rest energy equals Bergou et al.'s quadratic form for an isometric fold, and
// the batched projection (scalar and AVX2, float and double) equals the one-by-one projection.
#include <deform/kernels/isometric_bending.h>

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

namespace deform::pbd {
namespace {

// A hinge about the edge x2 = (0, -0.5, 0) -> x3 = (0, 0.5, 0) (metres, scaled by s) with the wing
// x0 on the -x side at distance a and x1 on the +x side at distance b, x1's triangle folded up by
// theta (0: flat). Triangles (x0, x2, x3) and (x1, x3, x2) are counter-clockwise seen from +z.
void hinge(Real theta, Real a, Real b, Real s, Vec3 x[4]) {
  x[0] = s * Vec3(-a, 0.1, 0);
  x[1] = s * Vec3(b * std::cos(theta), -0.2, b * std::sin(theta));
  x[2] = s * Vec3(0, -0.5, 0);
  x[3] = s * Vec3(0, 0.5, 0);
}

/// C(x) of the hinge h.
Real constraintValue(const Vec3 x[4], const IsometricHinge& h) {
  Real C;
  Vec3 g[4];
  isometricBendingConstraint(x, h.K, h.rest, C, g);
  return C;
}

Mat3 rotation(const Vec3& axis, Real angle) {
  return Eigen::AngleAxis<Real>(angle, axis.normalized()).toRotationMatrix();
}

TEST(IsometricBending, StencilOfAFlatHingeSumsToZeroAndVanishes) {
  Vec3 x[4];
  hinge(0.0, 0.4, 0.7, 0.01, x);
  IsometricHinge h;
  ASSERT_TRUE(isometricHinge(x, h));
  EXPECT_NEAR(h.K[0] + h.K[1] + h.K[2] + h.K[3], 0.0, 1e-12);
  EXPECT_LT(std::abs(h.rest), 1e-15);  // flat: zero at rest
  EXPECT_LT(std::abs(constraintValue(x, h)), 1e-15);
}

// For a hinge of the flat rest shape folded isometrically by theta, |v| = 2 |e| sin(theta / 2),
// so C^2 / (2 alpha) is Bergou et al.'s 1/2 x^T Q x with Q = K K^T / alpha.
TEST(IsometricBending, FoldMeasuresTwiceEdgeTimesHalfAngleSine) {
  Vec3 x0[4], x[4];
  hinge(0.0, 0.4, 0.7, 0.01, x0);
  IsometricHinge h;
  ASSERT_TRUE(isometricHinge(x0, h));
  for (Real theta : {0.1, 0.5, -0.8, 1.5}) {
    hinge(theta, 0.4, 0.7, 0.01, x);
    Real C;
    Vec3 g[4];
    ASSERT_TRUE(isometricBendingConstraint(x, h.K, h.rest, C, g));
    const Real e = (x[3] - x[2]).norm();
    EXPECT_NEAR(std::abs(C), 2 * e * std::sin(std::abs(theta) / 2), 1e-12 * e);
    Real quad = 0;  // x^T (K K^T) x per coordinate = |sum_i K_i x_i|^2
    Vec3 v = Vec3::Zero();
    for (int i = 0; i < 4; ++i) v += h.K[i] * x[i];
    quad = v.squaredNorm();
    EXPECT_NEAR(C * C, quad, 1e-12 * quad);
  }
}

TEST(IsometricBending, GradientMatchesFiniteDifferences) {
  std::mt19937 rng(5);
  std::uniform_real_distribution<Real> u(-1, 1);
  for (int trial = 0; trial < 20; ++trial) {
    Vec3 rest[4], x[4];
    hinge(0.6 * u(rng), 0.3 + 0.2 * std::abs(u(rng)), 0.3 + 0.2 * std::abs(u(rng)), 0.01, rest);
    IsometricHinge h;
    ASSERT_TRUE(isometricHinge(rest, h));
    for (int i = 0; i < 4; ++i) x[i] = rest[i] + 0.002 * Vec3(u(rng), u(rng), u(rng));
    Real C;
    Vec3 g[4];
    ASSERT_TRUE(isometricBendingConstraint(x, h.K, h.rest, C, g));
    const Real eps = 1e-7;
    for (int i = 0; i < 4; ++i) {
      for (int c = 0; c < 3; ++c) {
        Vec3 xp[4], xm[4];
        for (int k = 0; k < 4; ++k) xp[k] = xm[k] = x[k];
        xp[i][c] += eps;
        xm[i][c] -= eps;
        Real Cp, Cm;
        Vec3 gg[4];
        isometricBendingConstraint(xp, h.K, h.rest, Cp, gg);
        isometricBendingConstraint(xm, h.K, h.rest, Cm, gg);
        EXPECT_NEAR(g[i][c], (Cp - Cm) / (2 * eps), 1e-6) << trial << " " << i << " " << c;
      }
    }
  }
}

TEST(IsometricBending, ZeroAtACurvedRestShapeAndNothingMoves) {
  Vec3 x[4];
  hinge(0.7, 0.4, 0.5, 0.01, x);
  IsometricHinge h;
  ASSERT_TRUE(isometricHinge(x, h));
  EXPECT_GT(h.rest, 0.0);
  const Real w[4] = {1, 2, 0.5, 1};
  Real lambda = 0;
  Vec3 dx[4];
  ASSERT_TRUE(projectIsometricBending(x, w, h.K, h.rest, 0.0, 1.0, lambda, dx));
  for (int i = 0; i < 4; ++i) EXPECT_LT(dx[i].norm(), 1e-17);
}

TEST(IsometricBending, InvariantToRigidMotion) {
  Vec3 rest[4], x[4], y[4];
  hinge(0.3, 0.4, 0.5, 0.01, rest);
  IsometricHinge h;
  ASSERT_TRUE(isometricHinge(rest, h));
  hinge(-0.4, 0.4, 0.5, 0.01, x);
  const Mat3 R = rotation(Vec3(0.3, -1, 0.5), 2.1);
  const Vec3 t(0.5, -0.2, 1.0);
  for (int i = 0; i < 4; ++i) y[i] = R * x[i] + t;
  Real Cx, Cy;
  Vec3 gx[4], gy[4];
  ASSERT_TRUE(isometricBendingConstraint(x, h.K, h.rest, Cx, gx));
  ASSERT_TRUE(isometricBendingConstraint(y, h.K, h.rest, Cy, gy));
  EXPECT_NEAR(Cx, Cy, 1e-14);
  for (int i = 0; i < 4; ++i) EXPECT_LT((R * gx[i] - gy[i]).norm(), 1e-12);
  // A flattened hinge is not (C = -s0); the mirror image is (the documented limit).
  hinge(0.0, 0.4, 0.5, 0.01, x);
  isometricBendingConstraint(x, h.K, h.rest, Cx, gx);
  EXPECT_NEAR(Cx, -h.rest, 1e-15);
  hinge(-0.3, 0.4, 0.5, 0.01, x);
  isometricBendingConstraint(x, h.K, h.rest, Cx, gx);
  EXPECT_LT(std::abs(Cx), 1e-15);
}

TEST(IsometricBending, ProjectionSatisfiesTheHardConstraint) {
  Vec3 rest[4], x[4];
  hinge(0.4, 0.4, 0.5, 0.01, rest);
  IsometricHinge h;
  ASSERT_TRUE(isometricHinge(rest, h));
  hinge(-0.2, 0.4, 0.5, 0.01, x);
  const Real w[4] = {1, 2, 0.5, 1};
  // C is linear along v's direction: a few projections reach C = 0, conserving momentum.
  for (int it = 0; it < 5; ++it) {
    Real lambda = 0;
    Vec3 dx[4];
    ASSERT_TRUE(projectIsometricBending(x, w, h.K, h.rest, 0.0, 1.0, lambda, dx));
    Vec3 p = Vec3::Zero();
    for (int i = 0; i < 4; ++i) {
      x[i] += dx[i];
      p += dx[i] / w[i];
    }
    EXPECT_LT(p.norm(), 1e-15);
  }
  EXPECT_LT(std::abs(constraintValue(x, h)), 1e-9 * h.rest);
}

// A strip of hinges that share no particle (one colour): the batch kernel, scalar and AVX2, in
// double equals the one-by-one projection, and in float the AVX2 path equals the scalar path bit
// for bit.
template <class T>
struct Strip {
  std::vector<T> x4;
  std::vector<int> p[4];
  std::vector<T> K[4], wK[4], rest, at, scale, lambda;
  std::vector<IsometricHinge> hinges;
  std::vector<std::array<Real, 4>> w;
  IsometricBatch<T> batch() { return isometricBatch(p, K, wK, rest, at, scale, lambda); }
};

template <class T>
Strip<T> makeStrip(int n, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<Real> u(-1, 1);
  Strip<T> s;
  s.x4.assign(16 * n, T(0));
  for (int i = 0; i < n; ++i) {
    Vec3 x[4], y[4];
    hinge(0.5 * u(rng), 0.4, 0.5, 0.01, x);
    IsometricHinge h;
    EXPECT_TRUE(isometricHinge(x, h));
    hinge(0.5 * u(rng), 0.4, 0.5, 0.01, y);
    std::array<Real, 4> w{};
    Real denom = 1e-3;  // alphaTilde
    for (int k = 0; k < 4; ++k) {
      h.p[k] = 4 * i + k;
      w[k] = (k == 2 && i % 3 == 0) ? 0.0 : 1.0 + 0.5 * u(rng);
      denom += w[k] * h.K[k] * h.K[k];
      for (int c = 0; c < 3; ++c) s.x4[16 * i + 4 * k + c] = static_cast<T>(y[k][c] + 0.01 * i);
      s.p[k].push_back(16 * i + 4 * k);
      s.K[k].push_back(static_cast<T>(h.K[k]));
      s.wK[k].push_back(static_cast<T>(w[k] * h.K[k]));
    }
    s.rest.push_back(static_cast<T>(h.rest));
    s.at.push_back(T(1e-3));
    s.scale.push_back(static_cast<T>(1.0 / denom));
    s.lambda.push_back(T(0));
    s.hinges.push_back(h);
    s.w.push_back(w);
  }
  return s;
}

TEST(IsometricBending, BatchedDoubleEqualsOneByOne) {
  const int n = 27;  // three pairs of groups of four and a tail of three
  for (bool simd : {false, true}) {
    Strip<double> s = makeStrip<double>(n, 3);
    std::vector<double> ref = s.x4;
    std::vector<Real> lambdas(n, 0.0);
    for (int it = 0; it < 3; ++it) {
      EXPECT_EQ(projectIsometricColour(s.x4.data(), s.batch(), 0, n, simd), 0);
      for (int i = 0; i < n; ++i) {
        Vec3 x[4], dx[4];
        Real w[4], K[4];
        for (int k = 0; k < 4; ++k) {
          x[k] = Vec3(ref[16 * i + 4 * k], ref[16 * i + 4 * k + 1], ref[16 * i + 4 * k + 2]);
          w[k] = s.w[i][k];
          K[k] = s.hinges[i].K[k];
        }
        ASSERT_TRUE(projectIsometricBending(x, w, K, s.hinges[i].rest, 1e-3, 1.0, lambdas[i], dx));
        for (int k = 0; k < 4; ++k)
          for (int c = 0; c < 3; ++c) ref[16 * i + 4 * k + c] += dx[k][c];
      }
    }
    Real worst = 0, moved = 0;
    const Strip<double> s0 = makeStrip<double>(n, 3);
    for (size_t j = 0; j < ref.size(); ++j) {
      worst = std::max(worst, std::abs(s.x4[j] - ref[j]));
      moved = std::max(moved, std::abs(s.x4[j] - s0.x4[j]));
    }
    EXPECT_GT(moved, 1e-5);
    EXPECT_LT(worst, 1e-12 * moved) << "simd " << simd;
  }
}

TEST(IsometricBending, FloatSimdEqualsScalarBitForBit) {
  const int n = 61;  // AVX-512 / AVX2: pairs of groups of 16 / 8, one group alone, a scalar tail
  Strip<float> a = makeStrip<float>(n, 7), b = makeStrip<float>(n, 7);
  for (int it = 0; it < 3; ++it) {
    projectIsometricColour(a.x4.data(), a.batch(), 0, n, false);
    projectIsometricColour(b.x4.data(), b.batch(), 0, n, true);
  }
  EXPECT_EQ(a.x4, b.x4);
  EXPECT_EQ(a.lambda, b.lambda);
  // Measured rest values give C = 0 exactly: nothing moves.
  Strip<float> c = makeStrip<float>(n, 9);
  c.rest.assign(n, 0.0f);
  isometricLengthsColour(c.x4.data(), c.batch(), 0, n, c.rest.data(), true);
  const std::vector<float> before = c.x4;
  projectIsometricColour(c.x4.data(), c.batch(), 0, n, true);
  EXPECT_EQ(c.x4, before);
}

// With the optional movable pattern, a vector group skips the update of a slot that is immovable
// in all its hinges: the result is the same as updating every slot (float and double, scalar and
// AVX2), here with slot 2 immovable in every hinge and slot 1 in a run of hinges.
template <class T>
void expectSkippingChangesNothing() {
  const int n = 37;
  for (bool simd : {false, true}) {
    Strip<T> a = makeStrip<T>(n, 4), b = makeStrip<T>(n, 4);
    std::vector<unsigned char> movable(n, 0xF);
    for (int i = 0; i < n; ++i) {
      a.wK[2][i] = b.wK[2][i] = T(0);
      movable[i] &= ~4u;
      if (i >= 8 && i < 24) {
        a.wK[1][i] = b.wK[1][i] = T(0);
        movable[i] &= ~2u;
      }
    }
    IsometricBatch<T> bm = b.batch();
    bm.movable = movable.data();
    for (int it = 0; it < 3; ++it) {
      projectIsometricColour(a.x4.data(), a.batch(), 0, n, simd);
      projectIsometricColour(b.x4.data(), bm, 0, n, simd);
    }
    EXPECT_EQ(a.x4, b.x4) << "simd " << simd;
    EXPECT_EQ(a.lambda, b.lambda) << "simd " << simd;
    EXPECT_NE(a.x4, makeStrip<T>(n, 4).x4);
  }
}

TEST(IsometricBending, SkippingImmovableSlotsChangesNothing) {
  expectSkippingChangesNothing<float>();
  expectSkippingChangesNothing<double>();
}

}  // namespace
}  // namespace deform::pbd
