// The yardstick (issue G1): reference_fem with every parameter at its default (quadratic tets,
// 1000 target tets) solves the gravity-loaded cantilever within 2% of beam theory. The beam:
// L 0.1 m, 10 mm square section, E 10 MPa, nu 0.3, rho 1000 kg/m^3, fixed at x = 0 (the
// built-in "beam" phantom). Tip sag = Euler-Bernoulli q L^4 / (8 E I) + Timoshenko shear
// q L^2 / (2 kappa G A), with q = rho g A, I = b h^3 / 12, kappa = 10 (1 + nu) / (12 + 11 nu)
// (rectangle, Cowper 1966): 1.4715 + 0.0150 = 1.4865 mm (1.4868 mm with kappa = 5/6).
#include <deform/engine/plugin_loader.h>
#include <deform/geometry/phantom.h>
#include <deform/sdk/cache.h>
#include <deform/sdk/model.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <filesystem>

using namespace deform;

namespace {

TEST(ReferenceFemDefaults, GravityCantileverWithinTwoPercentOfBeamTheory) {
  const Real L = 0.1, b = 0.01, E = 1e7, nu = 0.3, rho = 1000, g = 9.81;
  const Real A = b * b, I = b * b * b * b / 12, G = E / (2 * (1 + nu));
  const Real kappa = 10 * (1 + nu) / (12 + 11 * nu), q = rho * g * A;
  const Real expected = q * std::pow(L, 4) / (8 * E * I) + q * L * L / (2 * kappa * G * A);
  ASSERT_NEAR(expected, 1.4868e-3, 5e-7);

  Organ organ;
  organ.source = "phantom:beam";
  organ.surface = makePhantom("beam", 1.0);
  organ.material.young = E;
  organ.material.poisson = nu;
  organ.material.density = rho;
  Box clamp;
  clamp.lo = Vec3(-0.01, -0.01, -0.01);
  clamp.hi = Vec3(1e-6, 0.01, 0.01);
  organ.fixed.boxes = {clamp};

  PluginLoader loader({DEFORM_BUILD_PLUGIN_DIR});
  const ModelInfo& info = loader.load("reference_fem");
  const ParamValues params = ParamValues::defaults(info.params);  // no override: the defaults
  Cache cache(std::filesystem::path(DEFORM_BUILD_DIR) / "test-cache");
  std::unique_ptr<Model> model = info.create();
  model->init(ModelSetup{organ, params, cache, 1e-3, Vec3(0, 0, -g)});
  StepInput in;
  in.dt = 1e-3;
  in.gravity = Vec3(0, 0, -g);
  ASSERT_EQ(model->step(in), StepStatus::Ok);
  // Mean vertical displacement of the surface vertices at the free end x = L.
  Real sag = 0;
  int n = 0;
  for (Eigen::Index v = 0; v < organ.surface.V.rows(); ++v) {
    if (organ.surface.V(v, 0) < L - 1e-9) continue;
    sag -= model->surface()(v, 2) - organ.surface.V(v, 2);
    ++n;
  }
  ASSERT_GT(n, 0);
  sag /= n;
  std::printf("reference_fem defaults: tip sag %.5f mm, beam theory %.5f mm (%+.2f%%)\n", 1e3 * sag,
              1e3 * expected, 100 * (sag - expected) / expected);
  EXPECT_NEAR(sag, expected, 0.02 * expected);
  model.reset();
}

}  // namespace
