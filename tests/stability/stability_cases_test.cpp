// The stability sweep's cases and verdicts (harness/src/stability.cpp): the verdict rules, beam
// theory, the sliver mesh, and every plugin of the build on two of the cases, run in process by
// the harness's runner: the stiff gravity cantilever must move (and the FEM models agree with beam
// theory), and a plugin with no fixed length parameter must give the same relative displacement
// at 1 cm, 10 cm and 1 m.
#include "../support/fixtures.h"

#include <deform/engine/plugin_loader.h>
#include <deform/geometry/mesh_check.h>
#include <deform/geometry/phantom.h>
#include <deform/sdk/mesh.h>
#include <deform_harness/runner.h>
#include <deform_harness/stability.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

namespace deform::harness {
namespace {

namespace fs = std::filesystem;
using ojson = nlohmann::ordered_json;

using deform::testing::loader;

/// The plugin's model, or nullptr when it does not load (a peer whose library is missing).
const ModelInfo* tryLoad(const std::string& plugin) {
  try {
    return &loader().load(plugin);
  } catch (const std::exception& e) {
    std::printf("skipped %s: %s\n", plugin.c_str(), e.what());
    return nullptr;
  }
}

StabilityCase findCase(const std::string& id) {
  for (const StabilityCase& c : stabilityCases(false))
    if (c.id == id) return c;
  ADD_FAILURE() << "no stability case " << id;
  return {};
}

TEST(StabilityVerdict, FollowsTheThresholdsOfTheIssue) {
  MatX3 rest = MatX3::Zero(4, 3);
  MatX3 ref = rest;
  ref.col(2).setConstant(-1e-3);  // every vertex 1 mm down
  StabilityRecord r;
  r.status = "stable";
  auto judge = [&](double scale, double sideways) {
    MatX3 m = ref * scale;
    m.col(0).setConstant(sideways);
    return judgeStability(r, &m, &ref, rest);
  };
  EXPECT_EQ(judge(1.0, 0).verdict, "accurate");
  EXPECT_NEAR(judge(1.1, 0).errorRatio, 0.1, 1e-12);
  EXPECT_EQ(judge(1.1, 0).verdict, "accurate");
  const StabilityRecord frozen = judge(0.05, 0);
  EXPECT_EQ(frozen.verdict, "inaccurate");
  EXPECT_EQ(frozen.reason, "frozen");
  EXPECT_NEAR(frozen.displacementRatio, 0.05, 1e-12);
  EXPECT_EQ(judge(2.5, 0).reason, "too_soft");
  EXPECT_EQ(judge(1.0, 5e-4).reason, "wrong_shape");
  EXPECT_EQ(judge(0.5, 0).reason, "wrong_shape");
  EXPECT_EQ(judgeStability(r, &ref, nullptr, rest).verdict, "unchecked");
  EXPECT_EQ(judgeStability(r, &ref, &rest, rest).verdict, "unchecked");  // reference at rest
  r.status = "diverged";
  EXPECT_EQ(judgeStability(r, nullptr, &ref, rest).verdict, "diverged");
  r.status = "failed";
  EXPECT_EQ(judgeStability(r, nullptr, &ref, rest).verdict, "failed");
  r.status = "unsupported";
  EXPECT_EQ(judgeStability(r, nullptr, &ref, rest).verdict, "unchecked");
}

/// The cube phantom's surface and its bottom tenth (the sweep's support), for the collapse tests.
struct Cube {
  MatX3 rest;
  std::vector<int> held;
  Cube() {
    rest = makePhantom("cube", 0.4).V;
    const double zLo = rest.col(2).minCoeff(), zHi = rest.col(2).maxCoeff();
    for (Eigen::Index i = 0; i < rest.rows(); ++i)
      if (rest(i, 2) <= zLo + 0.1 * (zHi - zLo)) held.push_back(int(i));
  }
  /// rest with the free vertices moved by d.
  MatX3 freeMoved(const Vec3& d) const {
    MatX3 m = rest;
    m.rowwise() += d.transpose();
    for (int v : held) m.row(v) = rest.row(v);
    return m;
  }
};

// Issue 35: pbd's cube fell through its own clamp (its surface 0.23 m below a 0.1 m cube clamped
// at its base) and read "stable / inaccurate too_soft". A collapse is its own verdict.
TEST(StabilityVerdict, ACollapseThroughTheSupportOrBeyondTheSizeIsCollapsed) {
  const Cube cube;
  const double size = 0.1;
  const MatX3 ref = cube.freeMoved(Vec3(0, 0, -0.002));  // the reference: 2 mm down
  StabilityRecord r;
  r.status = "stable";
  const MatX3 fell = cube.freeMoved(Vec3(0, 0, -1.2 * size));  // through the clamp
  const StabilityRecord through = judgeStability(r, &fell, &ref, cube.rest, 0.2, cube.held);
  EXPECT_EQ(through.verdict, "collapsed");
  EXPECT_NE(through.reason.find("through the support"), std::string::npos) << through.reason;
  const MatX3 away = cube.freeMoved(Vec3(2 * size, 0, 0));  // sideways, by twice its size
  const StabilityRecord far = judgeStability(r, &away, &ref, cube.rest, 0.2, cube.held);
  EXPECT_EQ(far.verdict, "collapsed");
  EXPECT_NE(far.reason.find("more than its size"), std::string::npos) << far.reason;
  // Soft but above its support: too soft, no collapse.
  const MatX3 soft = cube.freeMoved(Vec3(0, 0, -0.01));
  EXPECT_EQ(judgeStability(r, &soft, &ref, cube.rest, 0.2, cube.held).reason, "too_soft");
  // Where the reference itself moves the organ by over 10% of its size, no collapse verdict.
  const MatX3 bigRef = cube.freeMoved(Vec3(2 * size, 0, 0));
  EXPECT_EQ(judgeStability(r, &away, &bigRef, cube.rest, 0.2, cube.held).verdict, "accurate");
  EXPECT_EQ(collapseProblem(cube.rest, ref, cube.held), "");
  EXPECT_NE(collapseProblem(cube.rest, fell, cube.held), "");
  EXPECT_NEAR(relativeDisplacement(cube.rest, cube.freeMoved(Vec3(0, 0, 0))), 0, 1e-15);
}

// Issue 33: a reference whose own error is above the threshold cannot judge anyone.
TEST(StabilityVerdict, AnUnconvergedReferenceLeavesTheVerdictUnchecked) {
  const Cube cube;
  const MatX3 ref = cube.freeMoved(Vec3(0, 0, -0.002));
  StabilityRecord r;
  r.status = "stable";
  r.referenceError = 0.25;
  const StabilityRecord j = judgeStability(r, &ref, &ref, cube.rest, 0.2, cube.held);
  EXPECT_EQ(j.verdict, "unchecked");
  EXPECT_EQ(j.reason, "reference not converged");
  r.referenceError = 0.01;
  EXPECT_EQ(judgeStability(r, &ref, &ref, cube.rest, 0.2, cube.held).verdict, "accurate");
}

// Issue 35: the relative displacement must not change across 1 cm, 10 cm and 1 m.
TEST(StabilityVerdict, TheScaleGroupCallsAModelScaleDependentOverTenPercent) {
  std::vector<StabilityRecord> rows;
  const auto add = [&](const std::string& model, const char* id, double rel,
                       const std::string& verdict) {
    StabilityRecord r;
    r.model = model;
    r.caseId = id;
    r.group = "scale";
    r.relativeDisplacement = rel;
    r.verdict = verdict;
    rows.push_back(r);
  };
  // The issue's numbers: the reference constant, fem_hex 0.040 / 0.0094 / 0.040.
  add("reference", "scale_0.01m", 0.0092, "accurate");
  add("reference", "scale_0.1m", 0.0092, "accurate");
  add("reference", "scale_1m", 0.0095, "accurate");  // 3% apart: not scale-dependent
  add("fem_hex", "scale_0.01m", 0.040, "inaccurate");
  add("fem_hex", "scale_0.1m", 0.0094, "accurate");
  add("fem_hex", "scale_1m", 0.040, "collapsed");
  add("pbd", "scale_0.01m", 0.17, "unchecked");  // reference not converged: still the model's
  add("pbd", "scale_0.1m", 0.23, "unchecked");
  add("pbd", "scale_1m", -1, "diverged");  // unknown: not judged
  StabilityRecord other;
  other.model = "fem_hex";
  other.group = "force";
  other.verdict = "accurate";
  rows.push_back(other);
  rows[3].reason = "too_soft";
  const std::vector<std::string> lines = markScaleDependent(rows);
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0].rfind("fem_hex:", 0), 0u) << lines[0];
  for (int i = 0; i < 3; ++i) EXPECT_EQ(rows[size_t(i)].verdict, "accurate");
  EXPECT_EQ(rows[3].reason, "too_soft, scale_dependent");
  EXPECT_EQ(rows[4].verdict, "inaccurate");
  EXPECT_EQ(rows[4].reason, "scale_dependent");
  EXPECT_EQ(rows[5].verdict, "collapsed");
  EXPECT_EQ(rows[6].verdict, "unchecked") << "pbd: a diverged scale case leaves it unjudged";
  EXPECT_EQ(rows[9].verdict, "accurate");
}

TEST(StabilityCases, BeamTheoryAndTheNewCases) {
  // Issue #20: 1.4868 mm for the 10 MPa beam, Euler-Bernoulli 1.4715 mm of it.
  EXPECT_NEAR(cantileverSag(1e7, 0.3, 1000, 9.81, 0.1, 0.01), 1.4868e-3, 1e-7);
  EXPECT_NEAR(cantileverSag(1e4, 0.3, 1000, 9.81, 0.1, 0.01),
              1000 * cantileverSag(1e7, 0.3, 1000, 9.81, 0.1, 0.01), 1e-12);
  for (const char* id :
       {"cantilever_E10000", "cantilever_E1e+06", "cantilever_E1e+07", "scale_0.01m", "scale_0.1m",
        "scale_1m", "nu0.45", "nu0.49", "nu0.499", "E1e+07_dt0.0167", "E1e+07_dt0.0333", "slivers"})
    EXPECT_EQ(findCase(id).id, id);
  int quickCantilevers = 0;
  for (const StabilityCase& c : stabilityCases(true)) quickCantilevers += c.group == "cantilever";
  EXPECT_EQ(quickCantilevers, 1);
  EXPECT_FALSE(findCase("pull").reference);
  EXPECT_TRUE(findCase("slivers").reference);
}

TEST(StabilityCases, SliverMeshIsClosedWithNeedlesAndTheSameShape) {
  const SurfaceMesh base = makePhantom("liver", 0.4);
  const SurfaceMesh s = sliverMesh(0.4);
  EXPECT_GT(s.numVertices(), base.numVertices() + 50);
  EXPECT_EQ(s.numFaces() - base.numFaces(), 2 * (s.numVertices() - base.numVertices()));
  EXPECT_TRUE(validateSurface(s).usable());
  EXPECT_NEAR(signedVolume(s.V, s.F), signedVolume(base.V, base.F),
              1e-9 * std::abs(signedVolume(base.V, base.F)));
  double minAngle = 180;
  for (int f = 0; f < s.numFaces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      const Vec3 a = s.V.row(s.F(f, k)), b = s.V.row(s.F(f, (k + 1) % 3)),
                 c = s.V.row(s.F(f, (k + 2) % 3));
      const double cosine = (b - a).normalized().dot((c - a).normalized());
      minAngle = std::min(minAngle, std::acos(std::clamp(cosine, -1.0, 1.0)) * 180 / M_PI);
    }
  }
  EXPECT_LT(minAngle, 3.0);
}

/// Runs `plugin` on the case's scene in process (its params: the plugin's defaults, or the
/// given ones), for `duration` s. Returns the run and the rest surface.
std::pair<RunRecord, MatX3> runCase(const StabilityCase& c, const std::string& plugin,
                                    const ojson& params, double duration) {
  ojson scene = stabilityScene(c, plugin, params, true);
  scene["duration"] = duration;
  scene["output"] = {{"surfaces", "none"}};
  const fs::path dir = fs::temp_directory_path() / ("deform_stability_test_" + plugin + c.id);
  fs::create_directories(dir);
  const fs::path file = dir / "scene.json";
  std::ofstream(file) << scene.dump(2);
  BenchmarkOptions o;
  o.outDir = dir / "out";
  const BenchmarkResult res = runBenchmark(file.string(), loader(), o);
  fs::remove_all(dir);
  EXPECT_EQ(res.runs.size(), 1u);
  return {res.runs.at(0), res.organ.surface.V};
}

double tipSag(const MatX3& x, const MatX3& rest) {
  double sum = 0;
  int n = 0;
  for (Eigen::Index i = 0; i < rest.rows(); ++i) {
    if (rest(i, 0) < 0.1 - 1e-9) continue;
    sum += rest(i, 2) - x(i, 2);
    ++n;
  }
  return sum / n;
}

// Issue #20: fem_hex left this beam at 4e-18 m. Every plugin of the project with gravity must
// move it; the FEM models at their defaults must be within 20% of beam theory. (The Bullet peers
// are left to the sweep: bullet_deformable takes minutes here, bullet_softbody diverges.)
TEST(StabilityPlugins, StiffCantileverMovesForEveryPluginWithGravity) {
  const StabilityCase c = findCase("cantilever_E1e+07");
  const double theory = c.beamTheory;
  int ran = 0;
  for (const std::string& plugin : loader().discover()) {
    if (plugin.rfind("bullet_", 0) == 0) continue;  // peers: the sweep's verdicts cover them
    const ModelInfo* info = tryLoad(plugin);
    if (!info || !info->has(Capability::Gravity)) continue;
    // The FEM models settle within 0.3 s (their lowest mode: ~60 ms); the others need only
    // move, so 0.1 s and the sweep's quick precomputations keep the test short.
    const bool fem = plugin == "fem_hex" || plugin == "reference_fem";
    ojson params = ojson::object();
    if (plugin == "particle_bem") params = {{"coarse_vertices", 200}, {"points", 150}};
    if (plugin == "metaballs") params = {{"spheres", 150}};
    const auto t0 = std::chrono::steady_clock::now();
    const auto [run, rest] = runCase(c, plugin, params, fem ? 0.3 : 0.1);
    std::printf("%-18s %.1f s\n", plugin.c_str(),
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    ASSERT_EQ(run.status, RunStatus::Ok) << plugin << ": " << run.message;
    const double sag = tipSag(run.finalSurface, rest);
    std::printf("%-18s tip sag %.4g m (beam theory %.4g m, ratio %.3f)\n", plugin.c_str(), sag,
                theory, sag / theory);
    EXPECT_GT(sag, 0.01 * theory) << plugin << " does not move";
    if (plugin == "reference_fem") {
      // Issue 33: the stability sweep's reference (reference_fem at its defaults, quadratic)
      // within 2% of beam theory; the P1 preset it replaced was 18% stiff.
      EXPECT_NEAR(sag, theory, 0.02 * theory) << plugin;
    }
    if (fem) {
      // fem_hex at its default 967 target hexahedra: the 2.2 mm cells overhang the 10 mm beam;
      // counted whole, with trilinear elements, it sagged 1.00 mm (67% of theory). The cells'
      // volume fractions and the incompatible modes (its defaults) fix both. Its clamp (clamp =
      // points: the grid nodes inside the box pinned, the clamped surface points held through
      // the embedding) holds the cells that carry the root face, which shortens the beam by up
      // to a cell: 79% of theory (94% in fem_hex's own test, which pins only the grid nodes
      // behind the root face and lets that face move).
      const double margin = plugin == "fem_hex" ? 0.25 : 0.2;
      EXPECT_NEAR(sag, theory, margin * theory) << plugin;
    }
    ++ran;
  }
  EXPECT_GE(ran, 1);
}

/// A plugin whose parameters include a length with a non-zero default (a thickness, a load
/// radius) is not expected to be scale-invariant.
bool hasFixedLength(const ModelInfo& info) {
  for (const ParamSpec& p : info.params)
    if (p.unit == "m" && p.type == ParamType::Real && std::get<double>(p.defaultValue) != 0)
      return true;
  return false;
}

// The same problem at 1 cm, 10 cm and 1 m (force x s^2, density / s^2: the same dynamics in
// other units): the relative displacement must not change.
TEST(StabilityPlugins, ScaleInvarianceWithoutAFixedLength) {
  int ran = 0;
  for (const std::string& plugin : loader().discover()) {
    if (plugin.rfind("bullet_", 0) == 0) continue;  // peers: the sweep's verdicts cover them
    const ModelInfo* info = tryLoad(plugin);
    if (!info || hasFixedLength(*info) || !info->has(Capability::PointForce)) continue;
    if (plugin == "reference_fem") continue;  // the reference: slow at its P2 defaults
    ojson params = ojson::object();
    // metaballs: 24 voxels along the side keep its three constructions to seconds (48: 20 s each).
    if (plugin == "metaballs") params = {{"spheres", 150}, {"voxel_resolution", 24}};
    double rel[3];
    int k = 0;
    const auto t0 = std::chrono::steady_clock::now();
    for (const char* id : {"scale_0.01m", "scale_0.1m", "scale_1m"}) {
      const StabilityCase c = findCase(id);
      const auto [run, rest] = runCase(c, plugin, params, 0.05);
      ASSERT_EQ(run.status, RunStatus::Ok) << plugin << " " << id << ": " << run.message;
      const double size = boundingBox(rest).size().maxCoeff();
      rel[k++] = std::sqrt((run.finalSurface - rest).rowwise().squaredNorm().mean()) / size;
    }
    std::printf("%-18s relative displacement %.5g (1 cm) %.5g (10 cm) %.5g (1 m), %.1f s\n",
                plugin.c_str(), rel[0], rel[1], rel[2],
                std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    EXPECT_GT(rel[1], 0) << plugin;
    // metaballs was 2% less at 1 cm and 11% more at 1 m: its construction settled ties by
    // round-off of the coordinates in metres; it now runs in the surface's own frame.
    EXPECT_NEAR(rel[0], rel[1], 0.05 * rel[1]) << plugin << " at 1 cm";
    EXPECT_NEAR(rel[2], rel[1], 0.05 * rel[1]) << plugin << " at 1 m";
    ++ran;
  }
  EXPECT_GE(ran, 1);
}

}  // namespace
}  // namespace deform::harness
