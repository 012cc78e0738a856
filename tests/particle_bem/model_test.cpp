// Tests of the particle_bem model class (guided and pure particle modes).
#include "../support/grasp.h"
#include "../support/meshes.h"
#include "../support/plate.h"
#include "../support/press.h"
#include "conforming_surface.h"
#include "particle_bem_model.h"
#include "static_accuracy.h"

#include <deform/engine/interaction.h>
#include <gtest/gtest.h>

#include <filesystem>

namespace deform::particle_bem {
namespace {

using testing::graspResidual;
using testing::patchLoad;
using testing::vertexLoad;

/// The grasp of the fine surface vertices within r of p, targets at the rest surface moved by d.
GraspInput surfaceGrasp(const SurfaceMesh& s, const Vec3& p, Real r, const Vec3& d) {
  return testing::surfaceGrasp(s, p, r, s.V, d);
}

struct Fixture {
  Organ organ;
  ParamValues params;
  Cache cache{""};
  explicit Fixture(bool guided, int coarse = 250, int points = 150) {
    organ.source = "test:ellipsoid";
    organ.surface = testing::ellipsoid(4, Vec3(0.06, 0.04, 0.03));
    organ.material = Material{5000, 0.3, 1000};
    Box b;
    b.lo = Vec3(-1, -1, -1);
    b.hi = Vec3(1, 1, -0.015);
    organ.fixed.boxes.push_back(b);
    params = ParamValues::defaults(paramSpecs());
    params.set("guidance", guided);
    params.set("coarse_vertices", (long long)coarse);
    params.set("points", (long long)points);
  }
  std::unique_ptr<ParticleBemModel> make(Cache* c = nullptr) {
    auto m = std::make_unique<ParticleBemModel>();
    m->init(ModelSetup{organ, params, c ? *c : cache, 1e-3, Vec3(0, 0, -9.81)});
    return m;
  }
};

StepInput input(int step) {
  StepInput in;
  in.time = step * 1e-3;
  in.dt = 1e-3;
  return in;
}

TEST(GuidedModel, RestStaysAtRestAndInterpolationIsExact) {
  Fixture fx(true);
  auto m = fx.make();
  EXPECT_EQ(m->surface(), fx.organ.surface.V);
  EXPECT_EQ(m->counts().at("coarse_vertices"), 250);
  EXPECT_GT(m->counts().at("points"), 100);
  EXPECT_GT(m->counts().at("deformation_matrix_bytes"), 0);
  EXPECT_FALSE(m->fixedNodes().empty());
  for (int s = 0; s < 20; ++s) ASSERT_EQ(m->step(input(s)), StepStatus::Ok);
  EXPECT_LT((m->surface() - fx.organ.surface.V).cwiseAbs().maxCoeff(), 1e-15);
  const PhaseTimes t = m->phaseTimes();
  EXPECT_TRUE(t.count("surface") && t.count("correction") && t.count("interpolation"));
}

TEST(GuidedModel, PointLoadDisplacesAlongTheLoad) {
  Fixture fx(true);
  auto m = fx.make();
  const int v = topVertex(fx.organ.surface.V);
  const Vec3 f(0.2, 0, -1.0);
  const PointLoad load = patchLoad(fx.organ.surface, v, f);
  ASSERT_GT(load.vertices.size(), 1u);
  for (int s = 0; s < 400; ++s) {
    StepInput in = input(s);
    in.loads.push_back(load);
    ASSERT_EQ(m->step(in), StepStatus::Ok);
  }
  Vec3 u = Vec3::Zero();  // the patch's mean displacement
  for (size_t k = 0; k < load.vertices.size(); ++k)
    u +=
        load.weights[k] *
        (m->surface().row(load.vertices[k]) - fx.organ.surface.V.row(load.vertices[k])).transpose();
  EXPECT_GT(u.norm(), 1e-4);
  EXPECT_GT(u.dot(f.normalized()), 0.8 * u.norm());
  // Far from the load (and at the fixed bottom) the surface moves much less.
  int bottom = 0;
  for (int i = 0; i < fx.organ.surface.V.rows(); ++i)
    if (fx.organ.surface.V(i, 2) < fx.organ.surface.V(bottom, 2)) bottom = i;
  EXPECT_LT((m->surface().row(bottom) - fx.organ.surface.V.row(bottom)).norm(), 0.2 * u.norm());
}

// The harness spreads a point force over a pressure patch (here 3 cm); the model maps the
// per-vertex forces to its coarse nodes by J^T. Against the same force on the vertex alone, the
// loaded vertex sinks less (the load is spread) and its neighbours relatively more.
TEST(GuidedModel, PointForcePressurePatchSpreadsTheLoad) {
  Fixture fx(true);
  auto mp = fx.make(), mn = fx.make();
  const int v = topVertex(fx.organ.surface.V);
  const PointLoad spread = patchLoad(fx.organ.surface, v, Vec3(0, 0, -0.5), 0.03);
  for (int s = 0; s < 300; ++s) {
    StepInput in = input(s);
    in.loads.push_back(spread);
    ASSERT_EQ(mp->step(in), StepStatus::Ok);
    in.loads = {vertexLoad(v, Vec3(0, 0, -0.5))};
    ASSERT_EQ(mn->step(in), StepStatus::Ok);
  }
  const MatX3 up = mp->surface() - fx.organ.surface.V, un = mn->surface() - fx.organ.surface.V;
  EXPECT_LT(up(v, 2), 0);
  EXPECT_LT(-up(v, 2), -un(v, 2)) << "spread over 3 cm, the loaded vertex sinks less";
  // A vertex 2 cm from the loaded one: a larger share of the loaded vertex's motion.
  int ring = -1;
  for (int i = 0; i < fx.organ.surface.V.rows(); ++i) {
    const Real d = (fx.organ.surface.V.row(i) - fx.organ.surface.V.row(v)).norm();
    if (d > 0.015 && d < 0.025 &&
        (ring < 0 || fx.organ.surface.V(i, 2) > fx.organ.surface.V(ring, 2)))
      ring = i;
  }
  ASSERT_GE(ring, 0);
  EXPECT_GT(up(ring, 2) / up(v, 2), un(ring, 2) / un(v, 2));
}

TEST(GuidedModel, SurfaceTransferChangesTheSurfaceByAFractionOfTheMotion) {
  // The same loaded run with the gradient (default) and the linear transfer: the particles differ
  // a little (the load reaches them through J^T of the transfer), the fine surfaces by a fraction
  // of the motion (the transfer is used).
  Fixture fg(true), fl(true);
  fl.params.set("surface_transfer", std::string("linear"));
  auto mg = fg.make(), ml = fl.make();
  const int v = topVertex(fg.organ.surface.V);
  for (int s = 0; s < 200; ++s) {
    StepInput in = input(s);
    in.loads.push_back(vertexLoad(v, Vec3(0.2, 0, -1.0)));
    ASSERT_EQ(mg->step(in), StepStatus::Ok);
    ASSERT_EQ(ml->step(in), StepStatus::Ok);
  }
  const Real nodeDiff = (mg->nodes() - ml->nodes()).rowwise().norm().mean();
  const MatX3 ug = mg->surface() - fg.organ.surface.V, ul = ml->surface() - fl.organ.surface.V;
  const Real diff = (ug - ul).rowwise().norm().mean(), motion = ul.rowwise().norm().mean();
  EXPECT_GT(motion, 1e-5);
  EXPECT_GT(diff, 1e-4 * motion);
  EXPECT_LT(diff, 0.2 * motion);
  EXPECT_LT(nodeDiff, 0.2 * motion);
  Fixture bad(true);
  bad.params.set("surface_transfer", std::string("cubic"));
  EXPECT_THROW(bad.make(), InputError);
}

TEST(GuidedModel, SingularSupportChangesMAndIsInTheCacheKey) {
  Fixture fl(true), fs(true);
  fl.params.set("singular_support", false);
  // The singular reaction is the default discretisation (docs/notes/particle_bem-history.md, "Fifth
  // pass").
  EXPECT_TRUE(fs.params.flag("singular_support"));
  const std::string dir =
      (std::filesystem::temp_directory_path() / "particle_bem_singular_cache").string();
  std::filesystem::remove_all(dir);
  Cache cache(dir);
  auto ml = fl.make(&cache), ms = fs.make(&cache);  // the second must not reuse the first's M
  EXPECT_GT(ms->numericCounters().at("singular_support_faces"), 0);
  EXPECT_EQ(ml->numericCounters().count("singular_support_faces"), 0u);
  const MatX& Ml = ml->deformationMatrix().M;
  const MatX& Ms = ms->deformationMatrix().M;
  ASSERT_EQ(Ml.rows(), Ms.rows());
  EXPECT_GT((Ms - Ml).norm(), 1e-3 * Ml.norm());
  EXPECT_LT((Ms - Ml).norm(), 0.5 * Ml.norm());
  std::filesystem::remove_all(dir);
}

TEST(GuidedModel, GraspReachesTargetAndResetReproduces) {
  Fixture fx(true);
  auto m = fx.make();
  const int top = topVertex(fx.organ.surface.V);
  const GraspInput g = surfaceGrasp(fx.organ.surface, fx.organ.surface.V.row(top).transpose(), 0.01,
                                    Vec3(0, 0, 0.004));
  ASSERT_GT(g.vertices.size(), 3u);
  std::vector<MatX3> first;
  for (int run = 0; run < 2; ++run) {
    m->reset();
    for (int s = 0; s < 300; ++s) {
      StepInput in = input(s);
      in.grasps.push_back(g);
      in.gravity = Vec3(0, 0, -9.81);
      ASSERT_EQ(m->step(in), StepStatus::Ok);
    }
    first.push_back(m->surface());
  }
  EXPECT_EQ(first[0], first[1]);  // bit for bit
  // The grasped fine vertices (not coarse particles) are on their targets, through the transfer.
  EXPECT_LT(graspResidual(m->surface(), g), 1e-9);
  EXPECT_GT(m->graspedNodes().size(), 3u);
}

// A 4 mm grasper closes on one or two fine vertices between the coarse particles: the particles
// of their coarse triangles (and, with the gradient transfer, the triangles' one-rings) carry
// them to their targets during a lift, with gravity.
TEST(GuidedModel, SmallGraspLiftsItsFineVertices) {
  for (const char* transfer : {"gradient", "linear"}) {
    SCOPED_TRACE(transfer);
    Fixture fx(true);
    fx.params.set("surface_transfer", std::string(transfer));
    auto m = fx.make();
    const int top = topVertex(fx.organ.surface.V);
    GraspInput g = surfaceGrasp(fx.organ.surface, fx.organ.surface.V.row(top).transpose(), 0.004,
                                Vec3::Zero());
    const MatX3 t0 = g.targets;
    Real worst = 0;
    for (int s = 0; s < 200; ++s) {
      StepInput in = input(s);
      in.gravity = Vec3(0, 0, -9.81);
      g.targets = t0.rowwise() + Eigen::RowVector3d(0, 0, 0.01 * std::min(1.0, (s + 1) / 150.0));
      in.grasps.push_back(g);
      ASSERT_EQ(m->step(in), StepStatus::Ok);
      worst = std::max(worst, graspResidual(m->surface(), g));
    }
    EXPECT_LT(worst, 1e-9);
  }
}

TEST(GuidedModel, GravitySagsAndCacheHits) {
  const auto dir = std::filesystem::temp_directory_path() / "particle_bem_model_test_cache";
  std::filesystem::remove_all(dir);
  Cache cache(dir);
  Fixture fx(true, 150, 60);
  auto a = fx.make(&cache);
  auto b = fx.make(&cache);
  ASSERT_GE(cache.events().size(), 2u);
  EXPECT_EQ(cache.events().back().what, Cache::EventKind::Hit);
  EXPECT_EQ(a->deformationMatrix().M, b->deformationMatrix().M);
  // Issue 35: the assembly's counters survive a cache hit.
  EXPECT_TRUE(b->numericCounters().count("bem_degenerate_triangles"));
  EXPECT_EQ(a->numericCounters(), b->numericCounters());
  for (int s = 0; s < 300; ++s) {
    StepInput in = input(s);
    in.gravity = Vec3(0, 0, -9.81);
    ASSERT_EQ(b->step(in), StepStatus::Ok);
  }
  const int v = topVertex(fx.organ.surface.V);
  EXPECT_LT(b->surface()(v, 2), fx.organ.surface.V(v, 2) - 1e-5);
  std::filesystem::remove_all(dir);
}

// Markers: the Shepard-weighted displacement of their 8 nearest particles. At rest they are the
// points; one on a particle follows it; under gravity an interior one sags.
TEST(GuidedModel, MarkersFollowTheirNearestParticles) {
  Fixture fx(true, 150, 60);
  auto m = fx.make();
  const int k = m->surfaceParticles();  // the first interior particle
  ASSERT_LT(k, m->nodes().rows());
  MatX3 pts(2, 3);
  pts.row(0) = m->nodes().row(k);
  pts.row(1) = Vec3(0.0, 0.0, 0.01).transpose();
  m->bindMarkers(pts);
  EXPECT_LE((m->markers() - pts).cwiseAbs().maxCoeff(), 1e-15);
  for (int s = 0; s < 300; ++s) {
    StepInput in = input(s);
    in.gravity = Vec3(0, 0, -9.81);
    ASSERT_EQ(m->step(in), StepStatus::Ok);
  }
  const MatX3 x = m->markers();
  EXPECT_LT((x.row(0) - m->nodes().row(k)).norm(),
            1e-6 * (m->nodes().row(k) - pts.row(0)).norm() + 1e-12);
  EXPECT_LT(x(1, 2), pts(1, 2) - 1e-6) << "the interior sags";
}

TEST(ParticleModel, RestStaysAtRestAndGravitySagsStably) {
  Fixture fx(false, 250, 300);
  auto m = fx.make();
  EXPECT_FALSE(m->guided());
  for (int s = 0; s < 10; ++s) ASSERT_EQ(m->step(input(s)), StepStatus::Ok);
  EXPECT_LT((m->surface() - fx.organ.surface.V).cwiseAbs().maxCoeff(), 1e-12);
  m->reset();
  for (int s = 0; s < 1000; ++s) {
    StepInput in = input(s);
    in.gravity = Vec3(0, 0, -9.81);
    ASSERT_EQ(m->step(in), StepStatus::Ok) << s;
  }
  const int v = topVertex(fx.organ.surface.V);
  const Real dz = m->surface()(v, 2) - fx.organ.surface.V(v, 2);
  EXPECT_LT(dz, -1e-5);
  EXPECT_GT(dz, -0.03);  // bounded: no blow-up at dt = 1e-3, E = 5 kPa
}

TEST(ParticleModel, PointLoadPushesAlongTheLoad) {
  Fixture fx(false, 250, 300);
  auto m = fx.make();
  const int v = topVertex(fx.organ.surface.V);
  const PointLoad load = patchLoad(fx.organ.surface, v, Vec3(0, 0, -0.5));
  for (int s = 0; s < 500; ++s) {
    StepInput in = input(s);
    in.loads.push_back(load);
    ASSERT_EQ(m->step(in), StepStatus::Ok);
  }
  EXPECT_LT(m->surface()(v, 2) - fx.organ.surface.V(v, 2), -1e-4);
}

// A sliding plate (GraspInput::slideNormal): guided, the traction solve prescribes only the normal
// component of the carrying nodes' displacement (a normal traction each, no tangential one);
// pure, only their normal coordinate is set. Against a bonded plate the top spreads out
// (tests/support/plate.h) and the plate needs less force. The 10 cm cube, its bottom face fixed.
// The pure model is checked over the first 20 steps (0.4 mm): held by a plate, bonded or
// sliding, its particles blow up between 20 and 50 steps on this cube (the bonded plate too, with
// or without this change; cause not investigated), a limit of that model's grasp.
TEST(GuidedModel, ASlidingPlateSpreadsTheTopWhereABondedOneHoldsIt) {
  const testing::CubePress press = testing::cubePress(0.5);
  for (const bool guided : {true, false}) {
    Fixture fx(guided, 250, guided ? 150 : 300);
    fx.organ = press.organ;
    const auto m = fx.make();
    // The bonded plate's force (reaction_force) against reference_fem's 1.1 N at 2 mm (0.22 N
    // at 0.4 mm, linear), within the factor 2 these methods may miss by; sliding below it.
    if (guided) {
      testing::expectSlidingSpreadsTheTopAndEasesThePlate(*m, press.organ, 0.002, 100, 100,
                                                          "particle_bem guided");
      testing::expectBondedPlateForceNear(*m, press.organ, 0.002, 100, 100, 1.1, 2,
                                          "particle_bem guided");
    } else {
      testing::expectSlidingSpreadsTheTopAndEasesThePlate(*m, press.organ, 0.0004, 20, 0,
                                                          "particle_bem pure");
      testing::expectBondedPlateForceNear(*m, press.organ, 0.0004, 20, 0, 0.22, 2,
                                          "particle_bem pure");
    }
  }
}

TEST(GuidedModel, CoarseSurfaceConformsToTheFixedBox) {
  // conforming_support (default): the coarse surface is cut along the box's top face, so the
  // fixed nodes (fixedNodeIndices, the closed box) are exactly the nodes of the faces in the
  // box, and a load leaves them where they are; with the flag off the plain decimation
  // crosses the box's face.
  Fixture fx(true);
  auto m = fx.make();
  const SurfaceMesh& c = m->coarseSurface();
  EXPECT_EQ(testing::badEdges(c), 0);
  EXPECT_EQ(nonConformingFaces(c, fx.organ.fixed.boxes), 0);
  const Real h = fx.organ.fixed.boxes[0].hi[2];
  int onFace = 0;
  for (int v = 0; v < c.numVertices(); ++v) onFace += c.V(v, 2) == h;
  EXPECT_GE(onFace, 6);
  const int v = topVertex(fx.organ.surface.V);
  for (int s = 0; s < 100; ++s) {
    StepInput in = input(s);
    in.loads.push_back(vertexLoad(v, Vec3(0.3, 0, -1.0)));
    ASSERT_EQ(m->step(in), StepStatus::Ok);
  }
  int fixedCoarse = 0;
  for (int i : m->fixedNodes())
    if (i < c.numVertices()) {
      EXPECT_EQ(m->nodes().row(i), c.V.row(i)) << i;
      ++fixedCoarse;
    }
  EXPECT_GE(fixedCoarse, onFace);
  EXPECT_GT((m->surface().row(v) - fx.organ.surface.V.row(v)).norm(), 1e-4);
  fx.params.set("conforming_support", false);
  auto plain = fx.make();
  EXPECT_GT(nonConformingFaces(plain->coarseSurface(), fx.organ.fixed.boxes), 0);
}

// The model's static answer to a point force (the harness's 3 cm pressure patch on the fine
// surface, mapped to the coarse nodes by J^T) against the same coarse surface's BEM solve with
// the patch traction field integrated over the elements (integrateTractionField, the measure of
// the paper's Table 2): the consistent tractions (default) reproduce it closely; the lumped ones
// (p_k = f_k / A_k) load a wider area on elements of the patch's size and miss it by more.
TEST(GuidedModel, ConsistentPatchTractionsMatchTheIntegratedPatchField) {
  const Real R = 0.03;
  Fixture fc(true, 120, 60), fl(true, 120, 60);
  fl.params.set("patch_traction", std::string("lumped"));
  auto mc = fc.make(), ml = fl.make();
  const int v = topVertex(fc.organ.surface.V);
  const Vec3 f(0, 0, -0.5);
  const PointLoad load = patchLoad(fc.organ.surface, v, f, R);
  for (int s = 0; s < 400; ++s) {
    StepInput in = input(s);
    in.loads.push_back(load);
    ASSERT_EQ(mc->step(in), StepStatus::Ok);
    ASSERT_EQ(ml->step(in), StepStatus::Ok);
  }
  const SurfaceMesh& C = mc->coarseSurface();
  ASSERT_EQ(C.V, ml->coarseSurface().V);
  const int nc = C.numVertices();
  std::vector<int> fixed;
  for (int i : mc->fixedNodes())
    if (i < nc) fixed.push_back(i);
  const Material& mat = fc.organ.material;
  const Vec3 c = fc.organ.surface.V.row(v).transpose();
  const Box& box = fc.organ.fixed.boxes[0];
  // t = f w / int w, w = 1 - |x - c|^2 / R^2 (int w from the shares' own sampling: sum = 1).
  Real intw = 0;
  {
    const auto shares = pressurePatchShares(C, c, R);
    ASSERT_FALSE(shares.empty());
    // int w dGamma by a fine midpoint rule (the shares are normalised, so compute it here).
    for (int t = 0; t < C.numFaces(); ++t) {
      const Vec3 a = C.V.row(C.F(t, 0)).transpose(), b = C.V.row(C.F(t, 1)).transpose(),
                 d = C.V.row(C.F(t, 2)).transpose();
      const int n = 24;
      const Real area = 0.5 * (b - a).cross(d - a).norm() / (n * n);
      for (int i = 0; i < n; ++i)
        for (int j = 0; i + j < n; ++j)
          for (int up = 0; up < (i + j < n - 1 ? 2 : 1); ++up) {
            const Vec3 x = a + (b - a) * ((i + (up ? 2.0 : 1.0) / 3) / n) +
                           (d - a) * ((j + (up ? 2.0 : 1.0) / 3) / n);
            intw += std::max(Real(0), 1 - (x - c).squaredNorm() / (R * R)) * area;
          }
    }
  }
  const TractionField field = [&](const Vec3& x) -> Vec3 {
    if (box.contains(x)) return Vec3::Zero();
    return f * std::max(Real(0), 1 - (x - c).squaredNorm() / (R * R)) / intw;
  };
  const BemMatrices bem = assembleBem(C, mat.young, mat.poisson);
  SupportColumns sc = supportColumns(C, mat.young, mat.poisson, fixed);
  sc = withSingularSupport(sc, bem.G, singularSupport(C, mat.young, mat.poisson, fixed));
  const VecX u = solveBemRhs(bem, C, fixed,
                             integrateTractionField(C, mat.young, mat.poisson, field, R / 8), &sc);
  Real errC = 0, errL = 0, sum = 0;
  for (int k = 0; k < nc; ++k) {
    const Vec3 uk = u.segment<3>(3 * k);
    errC += ((mc->nodes().row(k) - C.V.row(k)).transpose() - uk).norm();
    errL += ((ml->nodes().row(k) - C.V.row(k)).transpose() - uk).norm();
    sum += uk.norm();
  }
  ASSERT_GT(sum, 0);
  // Measured: consistent 7.1%, lumped 7.4% (before the harness's spread, with the model's own
  // patch on the coarse surface: 0.16% and 2.2%, history "Sixth pass"). The fine surface's nodal
  // loads mapped by J^T of the gradient transfer now dominate the difference.
  EXPECT_LT(errC / sum, 0.1) << "consistent " << errC / sum << ", lumped " << errL / sum;
  EXPECT_LT(errC, errL) << "consistent " << errC / sum << ", lumped " << errL / sum;
  Fixture bad(true, 120, 60);
  bad.params.set("patch_traction", std::string("lumpy"));
  EXPECT_THROW(bad.make(), InputError);
}

}  // namespace
}  // namespace deform::particle_bem
