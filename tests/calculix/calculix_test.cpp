// The calculix plugin (CalculiX's ccx as a child process) against reference_fem on one mesh, and
// how it reports a missing or failing ccx. ccx is installed by scripts/install-deps.sh; where it
// is missing the comparison tests are skipped (the missing-ccx test runs everywhere).
#include <deform/engine/plugin_loader.h>
#include <deform/engine/scene.h>
#include <deform/geometry/phantom.h>
#include <deform/sdk/cache.h>
#include <deform/sdk/error.h>
#include <deform/sdk/model.h>
#include <deform_harness/runner.h>
#include <gtest/gtest.h>

#include "../support/fixtures.h"
#include "../support/plate.h"
#include "../support/press.h"
#include "ccx_deck.h"
#include "ccx_process.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <optional>

using namespace deform;
namespace fs = std::filesystem;

namespace {

using deform::testing::loader;

using deform::testing::cache;

/// Sets an environment variable for the lifetime of the object.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const std::string& value) : m_name(name) {
    if (const char* old = std::getenv(name)) m_old = old;
    setenv(name, value.c_str(), 1);
  }
  ~ScopedEnv() {
    if (m_old) {
      setenv(m_name, m_old->c_str(), 1);
    } else {
      unsetenv(m_name);
    }
  }

 private:
  const char* m_name;
  std::optional<std::string> m_old;
};

/// An executable shell script in a fresh folder (a stand-in for ccx).
std::string fakeCcx(const std::string& name, const std::string& body) {
  const fs::path dir = fs::path(DEFORM_BUILD_DIR) / "test-calculix" / name;
  fs::create_directories(dir);
  const fs::path file = dir / "ccx";
  std::ofstream(file) << "#!/bin/sh\n" << body << "\n";
  fs::permissions(file, fs::perms::owner_all);
  return file.string();
}

Organ beam() {
  Organ organ;
  organ.source = "phantom:beam";
  organ.surface = makePhantom("beam", 1.0);
  organ.material.young = 1e7;
  organ.material.poisson = 0.3;
  organ.material.density = 1000;
  Box clamp;
  clamp.lo = Vec3(-0.01, -0.01, -0.01);
  clamp.hi = Vec3(1e-6, 0.01, 0.01);
  organ.fixed.boxes = {clamp};
  return organ;
}

MatX3 solveOnce(const std::string& plugin, const Organ& organ, const StepInput& in,
                long long elements, std::string material = "neo_hookean") {
  const ModelInfo& info = loader().load(plugin);
  ParamValues p = ParamValues::defaults(info.params);
  p.set("elements", elements);
  p.set("material", material);
  std::unique_ptr<Model> model = info.create();
  model->init(ModelSetup{organ, p, cache(), 1e-3, in.gravity});
  EXPECT_EQ(model->step(in), StepStatus::Ok);
  return model->surface();
}

/// RMS of |a - b| over the rows, relative to the RMS of |a - rest|.
double relativeRms(const MatX3& a, const MatX3& b, const MatX3& rest) {
  return std::sqrt((a - b).rowwise().squaredNorm().mean() /
                   (a - rest).rowwise().squaredNorm().mean());
}

// The same discrete problem twice: the same tets (one cache entry), the same 10-node elements
// with the same 4-point rule, the same Neo-Hookean energy (C10 = mu/2, D1 = 2/K), consistent
// gravity in both. What remains is each solver's stopping test and ccx's printed precision
// (7 digits): 0.1% of the displacement is far above that and far below any modelling
// difference (linear tets are 18% stiff on this beam, a nu 0.3 -> 0.31 change is ~0.7%).
TEST(Calculix, GravityCantileverAgreesWithReferenceFem) {
  if (calculix::findCcx().empty()) GTEST_SKIP() << "ccx not installed";
  const Organ organ = beam();
  StepInput in;
  in.dt = 1e-3;
  in.gravity = Vec3(0, 0, -9.81);
  const MatX3 ref = solveOnce("reference_fem", organ, in, 1000);
  const MatX3 ccx = solveOnce("calculix", organ, in, 1000);
  const double rel = relativeRms(ref, ccx, organ.surface.V);
  std::printf(
      "gravity cantilever: calculix differs from reference_fem by %.2e of the RMS displacement\n",
      rel);
  EXPECT_LT(rel, 1e-4);
  // And it sags as the beam does (1.4868 mm at the tip, beam theory with shear): the
  // comparison is not two zeros.
  double sag = 0;
  int n = 0;
  for (Eigen::Index v = 0; v < organ.surface.V.rows(); ++v)
    if (organ.surface.V(v, 0) > 0.1 - 1e-9) {
      sag -= ccx(v, 2) - organ.surface.V(v, 2);
      ++n;
    }
  EXPECT_NEAR(sag / n, 1.4868e-3, 0.02 * 1.4868e-3);
}

// material linear: *ELASTIC without NLGEOM against reference_fem's small-strain material.
TEST(Calculix, LinearMaterialAgreesWithReferenceFem) {
  if (calculix::findCcx().empty()) GTEST_SKIP() << "ccx not installed";
  const Organ organ = beam();
  StepInput in;
  in.dt = 1e-3;
  in.loads = {
      PointLoad::onVertex(nearestVertex(organ.surface.V, Vec3(0.1, 0, 0.005)), Vec3(0, 0.3, -0.5))};
  const MatX3 ref = solveOnce("reference_fem", organ, in, 300, "linear");
  const MatX3 ccx = solveOnce("calculix", organ, in, 300, "linear");
  EXPECT_LT(relativeRms(ref, ccx, organ.surface.V), 1e-4);
}

harness::RunRecord runScene(const std::string& plugin, const nlohmann::json& params) {
  const Scene scene =
      parseSceneFile(std::string(DEFORM_SOURCE_DIR) + "/tests/calculix/cantilever.json");
  const Organ organ = loadOrgan(scene);
  const ModelInfo& info = loader().load(plugin);
  const ParamValues p = resolveParams(info.params, params, "test", "/params");
  return harness::runModel(info, p, scene, organ, cache());
}

TEST(Calculix, MissingCcxIsUnsupported) {
  ScopedEnv env("DEFORM_CCX", "/nonexistent/ccx");
  EXPECT_EQ(calculix::findCcx(), "");
  const harness::RunRecord r = runScene("calculix", {{"elements", 300}});
  EXPECT_EQ(r.status, harness::RunStatus::Unsupported);
  EXPECT_NE(r.message.find("ccx not found"), std::string::npos) << r.message;
}

TEST(Calculix, FailingCcxIsAFailedRunWithItsMessage) {
  if (calculix::findCcx().empty()) GTEST_SKIP() << "ccx not installed";
  // A real ccx failure: one increment of a quarter of the load cannot finish the step.
  const harness::RunRecord r = runScene("calculix", {{"elements", 300}, {"max_increments", 1}});
  EXPECT_EQ(r.status, harness::RunStatus::Failed);
  EXPECT_NE(r.message.find("ccx"), std::string::npos) << r.message;
  EXPECT_NE(r.message.find("*ERROR"), std::string::npos) << r.message;
  EXPECT_FALSE(r.valid);
}

TEST(Calculix, CcxPastItsDeadlineIsKilledAndReported) {
  const std::string fake = fakeCcx("slow", "sleep 30");
  const calculix::CcxRun run = calculix::runCcx(fake, "*NODE\n", 0.5);
  EXPECT_FALSE(run.ok);
  EXPECT_NE(run.message.find("did not finish within 0.5 s"), std::string::npos) << run.message;
  EXPECT_LT(run.wallSeconds, 10);
}

TEST(Calculix, CcxPastItsMemoryLimitFailsAloneAndTheMessageNamesTheLimit) {
  // dd allocates a buffer of its block size: 400 MB is past a 200 MB address-space limit, 20 MB
  // is not (that run then fails only for writing no job.dat).
  const calculix::CcxRun hungry =
      calculix::runCcx(fakeCcx("hungry", "exec dd if=/dev/zero of=/dev/null bs=400M count=1"),
                       "*NODE\n", 30, 1, 2e8);
  EXPECT_FALSE(hungry.ok);
  EXPECT_NE(hungry.message.find("exited with status"), std::string::npos) << hungry.message;
  EXPECT_NE(hungry.message.find("its memory was limited to 0.2 GB"), std::string::npos)
      << hungry.message;
  const calculix::CcxRun modest = calculix::runCcx(
      fakeCcx("modest", "exec dd if=/dev/zero of=/dev/null bs=20M count=1"), "*NODE\n", 30, 1, 2e8);
  EXPECT_NE(modest.message.find("wrote no job.dat"), std::string::npos) << modest.message;
  // A ccx that says why it stopped, and not for memory, is not blamed on the limit.
  const calculix::CcxRun said = calculix::runCcx(
      fakeCcx("said", "echo ' *ERROR: increment size smaller than minimum'; exit 201"), "*NODE\n",
      30, 1, 2e8);
  EXPECT_EQ(said.message.find("memory"), std::string::npos) << said.message;
  EXPECT_GT(calculix::halfPhysicalMemory(), 1e8);
}

TEST(Calculix, CcxErrorLinesBecomeTheMessage) {
  const std::string fake = fakeCcx("error", "echo ' *ERROR in fake: no such keyword'; exit 201");
  const calculix::CcxRun run = calculix::runCcx(fake, "*NODE\n", 30);
  EXPECT_FALSE(run.ok);
  EXPECT_NE(run.message.find("status 201"), std::string::npos) << run.message;
  EXPECT_NE(run.message.find("*ERROR in fake: no such keyword"), std::string::npos) << run.message;
}

TEST(Calculix, DatTableIsRead) {
  const std::string dat =
      "\n displacements (vx,vy,vz) for set NALL and time  0.5000000E+00\n\n"
      "         1  1.000000E+00  0.000000E+00  0.000000E+00\n"
      "         2  0.000000E+00  0.000000E+00  0.000000E+00\n\n"
      " displacements (vx,vy,vz) for set NALL and time  0.1000000E+01\n\n"
      "         2 -1.500000E-03  2.000000E-03  3.000000E-03\n"
      "         1  1.000000E-03  0.000000E+00 -4.000000E-03\n";
  double t = 0;
  const MatX3 u = calculix::ccxLastDisplacements(dat, 2, t);
  EXPECT_DOUBLE_EQ(t, 1.0);
  EXPECT_DOUBLE_EQ(u(1, 0), -1.5e-3);
  EXPECT_DOUBLE_EQ(u(0, 2), -4e-3);
  EXPECT_THROW(calculix::ccxLastDisplacements(dat, 3, t), std::runtime_error);
  EXPECT_THROW(calculix::ccxLastReactionForces(dat, 2, t), std::runtime_error);
  // RF follows U in the same *NODE PRINT (ccx_deck.cpp): each table is read to its blank line.
  const std::string both = dat +
                           "\n forces (fx,fy,fz) for set NALL and time  0.1000000E+01\n\n"
                           "         1  2.500000E-01  0.000000E+00 -1.000000E+00\n"
                           "         2  0.000000E+00  0.000000E+00  0.000000E+00\n";
  EXPECT_DOUBLE_EQ(calculix::ccxLastDisplacements(both, 2, t)(0, 2), -4e-3);
  const MatX3 rf = calculix::ccxLastReactionForces(both, 2, t);
  EXPECT_DOUBLE_EQ(t, 1.0);
  EXPECT_DOUBLE_EQ(rf(0, 0), 0.25);
  EXPECT_DOUBLE_EQ(rf(0, 2), -1.0);
}

// Plates and markers through the harness (runner.cpp): a cube of nu = 0, bonded to its base and
// pressed 1 mm by a bonded plate, is in uniaxial strain, so the markers' displacement is linear
// in their height; both solvers report it, with the measured positions' errors, and the plate's
// force E A strain.
TEST(Calculix, PlateAndMarkersThroughTheHarnessMatchUniaxialStrain) {
  if (calculix::findCcx().empty()) GTEST_SKIP() << "ccx not installed";
  const double a = 0.05, press = 0.001, E = 5500;
  const nlohmann::json j = nlohmann::json::parse(R"({
    "organ": {"mesh": "phantom:cube", "resolution": 0.3,
              "material": {"young": 5500, "poisson": 0.0, "density": 1000},
              "fixed": {"box": [[-0.06, -0.06, -0.06], [0.06, 0.06, -0.049999]]}},
    "gravity": [0, 0, 0], "dt": 1.0, "duration": 1.0,
    "plates": [{"region": {"box": [[-0.06, -0.06, 0.049999], [0.06, 0.06, 0.06]]},
                "trajectory": [{"t": 0, "offset": [0, 0, 0]}, {"t": 1, "offset": [0, 0, -0.001]}]}],
    "markers": {"points": [[0.01, -0.02, 0.0], [-0.03, 0.025, 0.03]],
                "measured": [{"t": 1.0, "points": [[0.01, -0.02, -0.0005], [-0.03, 0.025, -0.0]]}]},
    "models": [{"plugin": "calculix"}], "reference": {"plugin": "reference_fem"}})");
  const Scene scene = parseScene(j, "plates.json");
  const Organ organ = loadOrgan(scene);
  double referenceForce = std::nan("");
  for (const char* plugin : {"reference_fem", "calculix"}) {
    const ModelInfo& info = loader().load(plugin);
    const ParamValues p = resolveParams(
        info.params, {{"elements", 300}, {"element_order", 1}, {"material", "linear"}}, "test",
        "/params");
    const harness::RunRecord r = harness::runModel(info, p, scene, organ, cache());
    ASSERT_EQ(r.status, harness::RunStatus::Ok) << plugin << ": " << r.message;
    EXPECT_TRUE(r.valid) << plugin << ": " << r.invalidReason;
    EXPECT_EQ(r.markerStatus, "ok") << plugin << ": " << r.markerReason;
    ASSERT_EQ(r.compared.size(), 1u);
    const MatX3& x = r.compared[0].markers;
    ASSERT_EQ(x.rows(), 2);
    for (Eigen::Index i = 0; i < 2; ++i) {
      const double z = scene.markers.points(i, 2);
      EXPECT_NEAR(x(i, 2) - z, -press * (z + a) / (2 * a), 1e-7) << plugin << " marker " << i;
      EXPECT_NEAR(x(i, 0), scene.markers.points(i, 0), 1e-7) << plugin;
    }
    // Against the scene's "measured" positions: marker 0's is exact, marker 1's is put at
    // z = 0 (its true place is 0.03 - 0.0008), so the error is that distance.
    const double d1 = std::abs(x(1, 2) - 0.0);
    EXPECT_NEAR(r.compared[0].markerMax, d1, 1e-7) << plugin;
    EXPECT_NEAR(r.compared[0].markerRms, std::sqrt(0.5 * d1 * d1), 1e-6) << plugin;
    // Registered by the least-squares translation (the mean difference, d1 / 2 in z): each
    // marker is d1 / 2 off.
    EXPECT_NEAR(r.compared[0].markerRmsTranslation, 0.5 * d1, 1e-6) << plugin;
    // The plate's force E A strain (ccx: the held nodes' reactions RF), both solvers; ccx's
    // within 1e-3 of reference_fem's on the same mesh.
    ASSERT_EQ(r.compared[0].plateForces.size(), 1u) << plugin;
    const Vec3 f = r.compared[0].plateForces[0];
    std::printf("%s: plate force %.6g N (E A strain %.6g N)\n", plugin, f.z(), E * 2 * a * press);
    EXPECT_NEAR(f.z(), E * 2 * a * press, 1e-4) << plugin;
    EXPECT_NEAR(f.head<2>().norm(), 0, 1e-4) << plugin;
    if (std::string(plugin) == "reference_fem")
      referenceForce = f.z();
    else
      EXPECT_NEAR(f.z(), referenceForce, 1e-3 * referenceForce) << "calculix against reference_fem";
  }
}

// The plate of tests/support/plate.h on its 10 cm cube (E 5500 Pa, nu 0.3, bottom face fixed),
// 2 mm in one solve, 10-node Neo-Hookean tets: calculix's force (the held nodes' RF) is
// reference_fem's on the same mesh to 1e-3, bonded and sliding, positive along the press, of
// the order of E A strain (1.1 N), and the sliding plate's is below the bonded one's.
TEST(Calculix, PlateForceOnTheSupportCubeMatchesReferenceFem) {
  if (calculix::findCcx().empty()) GTEST_SKIP() << "ccx not installed";
  const Organ organ = deform::testing::cubePress(0.5).organ;
  double force[2][2] = {};  // [plugin][sliding]
  int k = 0;
  for (const char* plugin : {"reference_fem", "calculix"}) {
    const ModelInfo& info = loader().load(plugin);
    ParamValues p = ParamValues::defaults(info.params);
    p.set("elements", 300LL);
    std::unique_ptr<Model> model = info.create();
    model->init(ModelSetup{organ, p, cache(), 1.0, Vec3::Zero()});
    for (const bool sliding : {false, true}) {
      const deform::testing::PlateRun r =
          deform::testing::pressByPlate(*model, organ, sliding, 0.002, 1, 0, 1.0);
      std::printf("%s, %s: plate force %.6g N, drop %.4f mm\n", plugin,
                  sliding ? "sliding" : "bonded", r.force, 1e3 * r.drop);
      ASSERT_TRUE(r.ok) << plugin;
      force[k][sliding] = r.force;
    }
    ++k;
  }
  for (int s = 0; s < 2; ++s) EXPECT_NEAR(force[1][s], force[0][s], 1e-3 * force[0][s]) << s;
  EXPECT_GT(force[1][0], 0.5 * 1.1);
  EXPECT_LT(force[1][0], 2 * 1.1);
  EXPECT_GT(force[1][1], 0);
  EXPECT_LT(force[1][1], force[1][0]);
}

// A sliding plate (issue 34) on a cube on frictionless faces (the base on z-rollers, two side
// faces on symmetry rollers): the top face slides out freely, so the cube is in uniaxial stress
// (u_z = -press (z + a) / 2a, u_x = nu eps (x + a)) and the plate's force is E A eps; a bonded
// plate holds the top face's lateral motion at zero and needs more force. Both solvers, linear
// elements and material (the exact answer is linear: every mesh reproduces it).
TEST(Calculix, SlidingPlateOnFrictionlessFacesGivesUniaxialStressAndBondedDoesNot) {
  const double a = 0.05, press = 0.001, E = 5500, nu = 0.3, eps = press / (2 * a);
  nlohmann::json j = nlohmann::json::parse(R"({
    "organ": {"mesh": "phantom:cube", "resolution": 0.3,
              "material": {"young": 5500, "poisson": 0.3, "density": 1000},
              "fixed": [{"box": [[-0.06, -0.06, -0.050001], [0.06, 0.06, -0.049999]], "axes": "z"},
                        {"box": [[-0.050001, -0.06, -0.06], [-0.049999, 0.06, 0.06]], "axes": "x"},
                        {"box": [[-0.06, -0.050001, -0.06], [0.06, -0.049999, 0.06]], "axes": "y"}]},
    "gravity": [0, 0, 0], "dt": 1.0, "duration": 1.0,
    "plates": [{"region": {"box": [[-0.06, -0.06, 0.049999], [0.06, 0.06, 0.06]]},
                "contact": "sliding",
                "trajectory": [{"t": 0, "offset": [0, 0, 0]}, {"t": 1, "offset": [0, 0, -0.001]}]}],
    "markers": {"points": [[0.01, -0.02, 0.0], [-0.03, 0.025, 0.03]]},
    "models": [{"plugin": "calculix"}], "reference": {"plugin": "reference_fem"}})");
  const bool ccx = !calculix::findCcx().empty();
  for (const char* contact : {"sliding", "bonded"}) {
    j["plates"][0]["contact"] = contact;
    const bool sliding = std::string(contact) == "sliding";
    const Scene scene = parseScene(j, "sliding.json");
    const Organ organ = loadOrgan(scene);
    double referenceForce = std::nan("");
    for (const char* plugin : {"reference_fem", "calculix"}) {
      if (!ccx && std::string(plugin) == "calculix") continue;
      const ModelInfo& info = loader().load(plugin);
      ASSERT_TRUE(info.has(Capability::Sliding)) << plugin;
      const ParamValues p = resolveParams(
          info.params, {{"elements", 300}, {"element_order", 1}, {"material", "linear"}}, "test",
          "/params");
      const harness::RunRecord r = harness::runModel(info, p, scene, organ, cache());
      const std::string what = std::string(plugin) + ", " + contact;
      ASSERT_EQ(r.status, harness::RunStatus::Ok) << what << ": " << r.message;
      EXPECT_TRUE(r.valid) << what << ": " << r.invalidReason;
      // The top corner (a, a, a): uniaxial stress when sliding, no lateral motion when bonded.
      Eigen::Index corner = 0;
      for (Eigen::Index v = 0; v < organ.surface.V.rows(); ++v)
        if (organ.surface.V.row(v).sum() > organ.surface.V.row(corner).sum()) corner = v;
      const Vec3 u = (r.finalSurface.row(corner) - organ.surface.V.row(corner)).transpose();
      EXPECT_NEAR(u.z(), -press, 1e-9) << what << ": the plate prescribes the normal";
      EXPECT_NEAR(u.x(), sliding ? nu * eps * 2 * a : 0.0, 1e-7) << what;
      EXPECT_NEAR(u.y(), sliding ? nu * eps * 2 * a : 0.0, 1e-7) << what;
      ASSERT_EQ(r.compared.size(), 1u);
      const MatX3& x = r.compared[0].markers;
      ASSERT_EQ(x.rows(), 2);
      for (Eigen::Index i = 0; sliding && i < 2; ++i) {
        const Vec3 X = scene.markers.points.row(i).transpose();
        EXPECT_NEAR(x(i, 2) - X.z(), -eps * (X.z() + a), 1e-7) << what << " marker " << i;
        EXPECT_NEAR(x(i, 0) - X.x(), nu * eps * (X.x() + a), 1e-7) << what << " marker " << i;
      }
      // Both solvers report the plate's force: reference_fem to 1e-6, ccx to 1e-4 (its .dat
      // prints 7 digits per node) and within 1e-3 of reference_fem's on the same mesh.
      ASSERT_EQ(r.compared[0].plateForces.size(), 1u) << what;
      const bool reference = std::string(plugin) == "reference_fem";
      const double tol = reference ? 1e-6 : 1e-4;
      const double f = r.compared[0].plateForces[0].z(), uniaxial = E * 4 * a * a * eps;
      std::printf("%s: plate force %.6g N (E A eps %.6g N)\n", what.c_str(), f, uniaxial);
      if (sliding) {
        EXPECT_NEAR(f, uniaxial, tol * uniaxial) << what << ": E A eps";
        EXPECT_NEAR(r.compared[0].plateForces[0].head<2>().norm(), 0, tol * uniaxial)
            << what << ": no tangential force on a frictionless plate";
      } else {
        EXPECT_GT(f, 1.05 * uniaxial) << what << ": a bonded plate restrains the top face";
      }
      if (reference)
        referenceForce = f;
      else
        EXPECT_NEAR(f, referenceForce, 1e-3 * referenceForce) << what << ": against reference_fem";
    }
  }
}

}  // namespace
