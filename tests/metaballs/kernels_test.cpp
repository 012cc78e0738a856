// Run-time kernels: PBD constraints (eqs. 6-12), rotation extraction and skinning (eqs. 13-16).
#include "construction.h"
#include "pbd_constraints.h"
#include "skinning.h"
#include "solver_kernels.h"
#include "test_meshes.h"

#include <gtest/gtest.h>

#include <random>
#include <set>

namespace deform::metaballs {
namespace {

TEST(MetaballsKernels, StretchRestoresLengthAndConservesMomentum) {
  const Vec3 a(0, 0, 0), b(0.3, 0.4, 0);  // length 0.5
  const Real w1 = 2.0, w2 = 0.5, rest = 0.3;
  Vec3 da, db;
  ASSERT_TRUE(projectStretch(a, b, w1, w2, rest, 1.0, da, db));
  EXPECT_NEAR(((a + da) - (b + db)).norm(), rest, 1e-15);
  EXPECT_NEAR((da / w1 + db / w2).norm(), 0, 1e-15);  // m1 dc1 + m2 dc2 = 0
  Real lambda = 0;
  Vec3 xa, xb;
  ASSERT_TRUE(projectStretchXpbd(a, b, w1, w2, rest, 0.0, lambda, xa, xb));
  EXPECT_NEAR((xa - da).norm(), 0, 1e-15);  // zero compliance = rigid classic
  EXPECT_NEAR((xb - db).norm(), 0, 1e-15);
  // Compliance softens the correction.
  lambda = 0;
  ASSERT_TRUE(projectStretchXpbd(a, b, w1, w2, rest, 1.0, lambda, xa, xb));
  EXPECT_LT(xa.norm(), da.norm());
  EXPECT_FALSE(projectStretch(a, a, w1, w2, rest, 1.0, da, db));
}

// Colour batches: every link exactly once, no two links of one colour share a sphere, padding only
// with the dummy row; one sweep equals the single-link kernel applied in batch order, on both the
// AVX-512 and the scalar path, bit for bit.
TEST(MetaballsKernels, StretchBatchesAreValidColouringAndSweepMatchesKernel) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<Real> u(-1, 1);
  const int n = 60;
  MatX3 x(n, 3);
  for (int i = 0; i < n; ++i) x.row(i) = Eigen::RowVector3d(u(rng), u(rng), u(rng));
  std::vector<std::pair<int, int>> pairs;
  for (int i = 0; i < n; ++i)
    for (int j = i + 1; j < n; ++j)
      if ((x.row(i) - x.row(j)).norm() < 0.6) pairs.emplace_back(i, j);
  MatX2i links(Eigen::Index(pairs.size()), 2);
  std::vector<Real> rest, alpha;
  for (size_t l = 0; l < pairs.size(); ++l) {
    links(Eigen::Index(l), 0) = pairs[l].first;
    links(Eigen::Index(l), 1) = pairs[l].second;
    rest.push_back(0.9 * (x.row(pairs[l].first) - x.row(pairs[l].second)).norm());
    alpha.push_back(l % 3 == 0 ? 0.0 : 1e-3);
  }
  const StretchBatches bt = buildStretchBatches(links, rest, alpha, n);
  ASSERT_GT(bt.numColours(), 1);
  std::vector<int> seen(pairs.size(), 0);
  for (int c = 0; c < bt.numColours(); ++c) {
    EXPECT_EQ((bt.colourStart[size_t(c) + 1] - bt.colourStart[size_t(c)]) % 8, 0);
    std::set<int> used;
    for (int i = bt.colourStart[size_t(c)]; i < bt.colourStart[size_t(c) + 1]; ++i) {
      const int l = bt.link[size_t(i)];
      if (l < 0) {
        EXPECT_EQ(bt.a[size_t(i)], n);
        EXPECT_EQ(bt.b[size_t(i)], n);
        continue;
      }
      ++seen[size_t(l)];
      EXPECT_TRUE(used.insert(bt.a[size_t(i)]).second);
      EXPECT_TRUE(used.insert(bt.b[size_t(i)]).second);
      EXPECT_EQ(bt.a[size_t(i)], links(l, 0));
      EXPECT_EQ(bt.rest[size_t(i)], rest[size_t(l)]);
    }
  }
  for (int k : seen) EXPECT_EQ(k, 1);

  // Inverse masses (sphere 0 kinematic), positions, then one sweep three ways.
  std::vector<Real> w(size_t(n) + 1, 0);
  for (int i = 1; i < n; ++i) w[size_t(i)] = 0.5 + 0.01 * i;
  const Real dt = 1e-3;
  StretchStepData d0;
  for (int i = 0; i < bt.size(); ++i) {
    d0.wa.push_back(w[size_t(bt.a[size_t(i)])]);
    d0.wb.push_back(w[size_t(bt.b[size_t(i)])]);
    d0.alphaTilde.push_back(bt.compliance[size_t(i)] / (dt * dt));
    d0.lambda.push_back(0);
  }
  std::vector<Real> p0(size_t(n + 1) * 4, 0);
  for (int i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) p0[size_t(4 * i + c)] = x(i, c);
  std::vector<Real> pRef = p0, pSimd = p0, pScalar = p0;
  StretchStepData dRef = d0, dSimd = d0, dScalar = d0;
  for (int i = 0; i < bt.size(); ++i) {
    const int l = bt.link[size_t(i)];
    if (l < 0) continue;
    const int a = bt.a[size_t(i)], b = bt.b[size_t(i)];
    Vec3 da, db;
    const Vec3 xa(pRef[size_t(4 * a)], pRef[size_t(4 * a + 1)], pRef[size_t(4 * a + 2)]);
    const Vec3 xb(pRef[size_t(4 * b)], pRef[size_t(4 * b + 1)], pRef[size_t(4 * b + 2)]);
    if (!projectStretchXpbd(xa, xb, w[size_t(a)], w[size_t(b)], rest[size_t(l)],
                            dRef.alphaTilde[size_t(i)], dRef.lambda[size_t(i)], da, db))
      continue;
    for (int c = 0; c < 3; ++c) {
      pRef[size_t(4 * a + c)] += da(c);
      pRef[size_t(4 * b + c)] += db(c);
    }
  }
  EXPECT_EQ(projectStretchSweep(bt, dSimd, pSimd.data(), 1.0, true), 0);
  EXPECT_EQ(projectStretchSweep(bt, dScalar, pScalar.data(), 1.0, false), 0);
  EXPECT_TRUE(pSimd == pScalar);
  EXPECT_TRUE(dSimd.lambda == dScalar.lambda);
  EXPECT_NE(pScalar, p0);
  for (size_t i = 0; i < p0.size(); ++i) EXPECT_NEAR(pScalar[i], pRef[i], 1e-14) << i;
  for (int c = 0; c < 3; ++c) EXPECT_EQ(pScalar[size_t(c)], p0[size_t(c)]);  // kinematic
  // A zero-length movable link is skipped and counted on both paths.
  MatX2i two(2, 2);
  two << 0, 1, 2, 3;
  const StretchBatches bt2 = buildStretchBatches(two, {0.1, 0.1}, {0, 0}, 4);
  StretchStepData e;
  for (int i = 0; i < bt2.size(); ++i) {
    const bool real = bt2.link[size_t(i)] >= 0;
    e.wa.push_back(real ? 1.0 : 0.0);
    e.wb.push_back(real ? 1.0 : 0.0);
    e.alphaTilde.push_back(0);
    e.lambda.push_back(0);
  }
  std::vector<Real> q0 = {0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0.5, 0, 0, 0, 0, 0, 0, 0};
  std::vector<Real> qa = q0, qb = q0;
  StretchStepData ea = e, eb = e;
  EXPECT_EQ(projectStretchSweep(bt2, ea, qa.data(), 1.0, true), 1);
  EXPECT_EQ(projectStretchSweep(bt2, eb, qb.data(), 1.0, false), 1);
  EXPECT_TRUE(qa == qb);
  EXPECT_NEAR(qa[12] - qa[8], 0.1, 1e-15);  // the other link was projected
}

TEST(MetaballsKernels, LaplacianReducesToEquation11WithFixedNeighbours) {
  // With immovable neighbours the projection is c'_m = L_m + c'_center.
  const Vec3 c1(0, 0, 0), c2(1, 0, 0), c3(0, 1, 0);
  const Vec3 centre = (c1 + c2 + c3) / 3.0;
  const Vec3 L(0.1, 0.2, 0.3);
  const Vec3 cm(5, 5, 5);
  const Vec3 C = cm - centre - L;
  const Real s = laplacianScale(1.0, 0.0, 3, 1.0);
  const Vec3 projected = cm - 1.0 * s * C;
  EXPECT_NEAR((projected - (L + centre)).norm(), 0, 1e-14);
  // With movable neighbours the constraint is satisfied too (it is linear) and momentum kept.
  const Real wm = 1, wi = 2;
  Vec3 lambda = Vec3::Zero();
  const Vec3 dl = laplacianXpbd(C, wm, 3 * wi, 3, 0.0, lambda);
  const Vec3 pm = cm + wm * dl;
  const Vec3 q1 = c1 - (wi / 3) * dl, q2 = c2 - (wi / 3) * dl, q3 = c3 - (wi / 3) * dl;
  EXPECT_NEAR((pm - (q1 + q2 + q3) / 3.0 - L).norm(), 0, 1e-13);
  EXPECT_NEAR((wm * dl / wm - 3 * (wi / 3) * dl / wi).norm(), 0, 1e-14);
}

TEST(MetaballsKernels, VolumeScaleKeepsLengthTimesRadiusSquared) {
  for (Real stretch : {0.5, 0.8, 1.0, 1.3, 2.0}) {
    const Real restSum = 0.07, cur = stretch * restSum;
    const Real s = volumeRadiusScale(restSum, cur);
    EXPECT_NEAR(cur * s * s, restSum, 1e-15);
  }
  EXPECT_EQ(volumeRadiusScale(0.0, 1.0), 1.0);
}

TEST(MetaballsKernels, RotationExtractionRecoversRotation) {
  const Mat3 R0 = Eigen::AngleAxis<Real>(0.7, Vec3(1, 2, 3).normalized()).toRotationMatrix();
  Mat3 S;
  S << 2, 0.1, 0, 0.1, 1, 0.2, 0, 0.2, 1.5;  // symmetric positive definite stretch
  Eigen::Quaternion<Real> q = Eigen::Quaternion<Real>::Identity();
  extractRotation(R0 * S, q, 50);
  EXPECT_NEAR((q.toRotationMatrix() - R0).norm(), 0, 1e-7);
  q = Eigen::Quaternion<Real>::Identity();
  extractRotation(S, q, 50);
  EXPECT_EQ(q.toRotationMatrix(), Mat3::Identity());
}

// The batched extraction (AVX-512 and scalar, bit for bit) follows the Eigen reference
// extractRotation() to round-off, including a large first correction and a sphere without links.
TEST(MetaballsKernels, BatchedRotationExtractionMatchesReference) {
  std::mt19937 rng(11);
  std::normal_distribution<Real> g(0, 1);
  const int n = 21;
  RotationBatch simd, scalar;
  simd.resize(n);
  std::vector<Mat3> As;
  std::vector<Eigen::Quaternion<Real>> qs;
  for (int i = 0; i < n; ++i) {
    Mat3 S = Mat3::Identity();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c <= r; ++c) S(r, c) = S(c, r) = S(r, c) + 0.2 * g(rng);
    const Real angle = i == 0 ? 2.5 : 0.3 * g(rng);
    const Mat3 R =
        Eigen::AngleAxis<Real>(angle, Vec3(g(rng), g(rng), g(rng)).normalized()).matrix();
    const Mat3 A = i == 1 ? Mat3::Zero().eval() : (R * S).eval();
    As.push_back(A);
    Eigen::Quaternion<Real> q0(Eigen::AngleAxis<Real>(0.1 * g(rng), Vec3(0, 0, 1)));
    qs.push_back(q0);
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c)
        simd.A[size_t(3 * r + c) * size_t(simd.padded) + size_t(i)] = A(r, c);
    simd.q[size_t(i)] = q0.w();
    simd.q[size_t(simd.padded + i)] = q0.x();
    simd.q[size_t(2 * simd.padded + i)] = q0.y();
    simd.q[size_t(3 * simd.padded + i)] = q0.z();
  }
  scalar = simd;
  std::vector<Real> rs(size_t(n) * 9), rc(size_t(n) * 9);
  extractRotations(simd, 3, rs.data(), true);
  extractRotations(scalar, 3, rc.data(), false);
  EXPECT_TRUE(rs == rc);
  EXPECT_TRUE(simd.q == scalar.q);
  for (int i = 0; i < n; ++i) {
    extractRotation(As[size_t(i)], qs[size_t(i)], 3);
    const Mat3 R = qs[size_t(i)].toRotationMatrix();
    for (int k = 0; k < 9; ++k) EXPECT_NEAR(rc[size_t(9 * i + k)], R(k / 3, k % 3), 1e-13) << i;
  }
}

class SkinningTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    surface = new SurfaceMesh(test::banana(0.16, 0.035, 0.08, 4));
    ConstructionParams p;
    p.targetSpheres = 100;
    p.voxelResolution = 32;
    mb = new Metaballs(constructMetaballs(*surface, p));
  }
  static void TearDownTestSuite() {
    delete surface;
    delete mb;
  }
  static SurfaceMesh* surface;
  static Metaballs* mb;
};
SurfaceMesh* SkinningTest::surface = nullptr;
Metaballs* SkinningTest::mb = nullptr;

TEST_F(SkinningTest, WeightsFollowEquations13And14) {
  const Real T = 0.2;
  const Skinning sk = buildSkinning(surface->V, mb->spheres, T, 6);
  for (int v = 0; v < sk.numVertices; ++v) {
    Real sum = 0;
    int attached = 0;
    for (int s = 0; s < sk.slots; ++s) {
      const Real w = sk.weight[size_t(v * sk.slots + s)];
      sum += w;
      if (w <= 0) continue;
      ++attached;
      const int i = sk.sphere[size_t(v * sk.slots + s)];
      const Real f = fieldStrength((surface->V.row(v) - mb->spheres.centers.row(i)).norm(),
                                   mb->spheres.radii(i));
      if (sk.fallbacks == 0) {
        EXPECT_GE(f, T);
      }
    }
    EXPECT_NEAR(sum, 1.0, 1e-12);
    EXPECT_GE(attached, 1);
  }
  EXPECT_NEAR(fieldStrength(0.3, 0.3), 1.0, 1e-15);  // strongest on the sphere's surface
  EXPECT_LT(fieldStrength(0.6, 0.3), fieldStrength(0.4, 0.3));
}

TEST_F(SkinningTest, RestReproducesSurfaceAndRigidTranslationTranslates) {
  const Skinning sk = buildSkinning(surface->V, mb->spheres, 0.2, 6);
  MatX3 out(surface->V.rows(), 3);
  std::vector<Real> identity(size_t(mb->spheres.size()) * 9, 0.0);
  for (int i = 0; i < mb->spheres.size(); ++i)
    for (int q = 0; q < 3; ++q) identity[size_t(9 * i + 4 * q)] = 1.0;
  const std::vector<const Real*> frames = {nullptr, identity.data()};
  for (const Real* rot : frames) {
    applySkinning(sk, mb->spheres.centers, mb->spheres.radii, rot, out);
    EXPECT_LE((out - surface->V).cwiseAbs().maxCoeff(), 1e-15);
    const Vec3 t(0.01, -0.02, 0.03);
    MatX3 moved = mb->spheres.centers;
    moved.rowwise() += t.transpose();
    applySkinning(sk, moved, mb->spheres.radii, rot, out);
    MatX3 expect = surface->V;
    expect.rowwise() += t.transpose();
    EXPECT_LE((out - expect).cwiseAbs().maxCoeff(), 1e-15);
  }
}

TEST_F(SkinningTest, RadiusScaleScalesDisplacementAndRotationRotates) {
  const Skinning sk = buildSkinning(surface->V, mb->spheres, 0.2, 6);
  MatX3 out(surface->V.rows(), 3), rest(surface->V.rows(), 3);
  const VecX bigger = 1.5 * mb->spheres.radii;
  applySkinning(sk, mb->spheres.centers, bigger, nullptr, out);
  // Eq. (16): v' - c_center = 1.5 disp.
  for (int v = 0; v < sk.numVertices; ++v) {
    Vec3 cc = Vec3::Zero();
    for (int s = 0; s < sk.slots; ++s)
      cc += sk.weight[size_t(v * sk.slots + s)] *
            mb->spheres.centers.row(sk.sphere[size_t(v * sk.slots + s)]).transpose();
    const Vec3 disp(sk.dispX[size_t(v)], sk.dispY[size_t(v)], sk.dispZ[size_t(v)]);
    EXPECT_NEAR((out.row(v).transpose() - cc - 1.5 * disp).norm(), 0, 1e-14);
  }
  // A rigid rotation of the spheres with matching frames rotates the whole surface.
  const Mat3 R = Eigen::AngleAxis<Real>(0.5, Vec3(0, 0, 1)).toRotationMatrix();
  const MatX3 rotated = (mb->spheres.centers * R.transpose()).eval();
  std::vector<Real> rots(size_t(mb->spheres.size()) * 9);
  for (int i = 0; i < mb->spheres.size(); ++i)
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) rots[size_t(9 * i + 3 * r + c)] = R(r, c);
  applySkinning(sk, rotated, mb->spheres.radii, rots.data(), out);
  EXPECT_LE((out - surface->V * R.transpose()).cwiseAbs().maxCoeff(), 1e-14);
}

TEST_F(SkinningTest, SimdAndScalarPathsAgreeBitForBit) {
  const Skinning sk = buildSkinning(surface->V, mb->spheres, 0.2, 6);
  std::mt19937 rng(3);
  std::normal_distribution<Real> g(0, 0.003);
  MatX3 c = mb->spheres.centers;
  VecX r = mb->spheres.radii;
  std::vector<Real> rots(size_t(mb->spheres.size()) * 9);
  for (int i = 0; i < mb->spheres.size(); ++i) {
    c.row(i) += Eigen::RowVector3d(g(rng), g(rng), g(rng));
    r(i) *= 1 + 10 * g(rng);
    const Mat3 R = Eigen::AngleAxis<Real>(100 * g(rng), Vec3(1, 2, 3).normalized()).matrix();
    for (int q = 0; q < 9; ++q) rots[size_t(9 * i + q)] = R(q / 3, q % 3);
  }
  std::vector<Real> frames(size_t(kFrameStride) * size_t(r.size()));
  packSphereFrames(c, r, rots.data(), frames);
  for (bool rotate : {true, false}) {
    MatX3 a(surface->V.rows(), 3), b(surface->V.rows(), 3);
    applySkinningFrames(sk, frames.data(), rotate, a, true);
    applySkinningFrames(sk, frames.data(), rotate, b, false);
    EXPECT_TRUE(a == b);
    EXPECT_GT((a - surface->V).cwiseAbs().maxCoeff(), 1e-4);
  }
}

}  // namespace
}  // namespace deform::metaballs
