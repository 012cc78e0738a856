// fem_hex against reference_fem on the liver phantom under the shipped standard scenes
// (scenes/liver_grasp_lift.json, scenes/liver_poke.json): issue F3's validation. Both plugins are
// loaded through the plugin loader and run by the harness's runner, as `deformbench run` does;
// the errors are the harness's (docs/results-format.md, "Metrics"). Each test prints its figures.
//
// Changed from the shipped scenes: the reference is quasi-static, so fem_hex is run to
// equilibrium too, with implicit Euler steps of dt = 50 ms (20 steps; the inertia term M/dt^2 is
// then comparable to the stiffness of the liver's lowest mode only, and every later step is one
// more linearised Newton step towards the corotational equilibrium) and no mass damping. At the
// shipped dt = 1 ms and default damping the lowest mode (~0.35 s period) still rings at t = 1 s
// (see its history note). The reference is the scenes' own (elements = 5000, 30k tets) with
// linear tets pinned (`element_order: 1`): the bounds below were set against it, and quadratic
// tets on the full liver's 30k tets cost minutes per solve (reference_fem's README).
//
// What the bounds rest on (history note): the lift prescribes a displacement, so under it
// the displacement field does not depend on the stiffness's scale; the error there comes from
// the grasp (fem_hex holds the grasped surface points through its embedding, in effect the
// 11.5 mm cells carrying them at 967 hexahedra; the reference holds those surface vertices as its
// nodes) and from the discretisation (locking, boundary cells, embedding), and must shrink with
// refinement. The poke is a point force on one vertex: the displacement at the load is singular
// (~1/(load spread)), set by each model's own local mesh size, so near the load the models need
// not agree and fem_hex's displacement there grows with refinement; away from the load they must
// agree, better with refinement.
#include "../support/fixtures.h"

#include <deform/engine/plugin_loader.h>
#include <deform/engine/scene.h>
#include <deform/sdk/cache.h>
#include <deform_harness/runner.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>

namespace deform::harness {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

json readJson(const fs::path& p) {
  std::ifstream in(p);
  if (!in) throw std::runtime_error("cannot read " + p.string());
  return json::parse(in);
}

fs::path shippedScene(const std::string& name) {
  return fs::path(DEFORM_SOURCE_DIR) / "scenes" / (name + ".json");
}

using deform::testing::loader;

/// fem_hex at each element count and the scene's reference, run on the scene `j` (whose models
/// are replaced). Returns the records, fem_hex runs first (in `elements` order), the reference
/// last, with the harness's errors filled in.
struct Comparison {
  Scene scene;
  Organ organ;
  std::vector<RunRecord> runs;
  const RunRecord& reference() const { return runs.back(); }
};

Comparison compare(json j, const fs::path& file, const std::vector<int>& elements) {
  j["models"] = json::array();
  for (int n : elements) {
    j["models"].push_back({{"plugin", "fem_hex"},
                           {"label", "fem_hex " + std::to_string(n)},
                           {"params", {{"elements", n}, {"rayleigh_mass", 0.0}}}});
  }
  j["reference"]["params"]["element_order"] = 1;  // see the file comment
  j["dt"] = 0.05;
  j["output"] = {{"surfaces", "every:2"}};  // to check that fem_hex has settled
  Comparison c;
  c.scene = parseScene(j, file.string());
  c.organ = loadOrgan(c.scene);
  const std::vector<PlannedRun> planned = planRuns(c.scene, loader(), BenchmarkOptions{});
  forceSingleThreadedNumerics();
  Cache cache(Cache::defaultDir());
  for (const PlannedRun& p : planned) {
    RunRecord r = runModel(*p.info, p.params, c.scene, c.organ, cache);
    r.label = p.label;
    r.isReference = p.isReference;
    c.runs.push_back(std::move(r));
  }
  std::stable_partition(c.runs.begin(), c.runs.end(),
                        [](const RunRecord& r) { return !r.isReference; });
  computeRunErrors(c.scene, c.organ, c.runs);
  return c;
}

/// Surface vertices nearest p on the rest surface (the harness's rmse_k set).
std::vector<int> nearestVertices(const MatX3& V, const Vec3& p, int k) {
  std::vector<int> idx(V.rows());
  for (int i = 0; i < V.rows(); ++i) idx[i] = i;
  std::partial_sort(idx.begin(), idx.begin() + k, idx.end(), [&](int a, int b) {
    return (V.row(a).transpose() - p).squaredNorm() < (V.row(b).transpose() - p).squaredNorm();
  });
  idx.resize(k);
  return idx;
}

Vec3 meanDisplacement(const MatX3& x, const MatX3& rest, const std::vector<int>& vertices) {
  Vec3 u = Vec3::Zero();
  for (int v : vertices) u += (x.row(v) - rest.row(v)).transpose();
  return u / static_cast<Real>(vertices.size());
}

Real sumDisplacement(const MatX3& x, const MatX3& rest) {
  return (x - rest).rowwise().norm().sum();
}

Real peakDisplacement(const MatX3& x, const MatX3& rest) {
  return (x - rest).rowwise().norm().maxCoeff();
}

Real rmse(const RunRecord& r, int k) {
  for (const auto& [kk, v] : r.error->rmseNearest)
    if (kk == k) return v;
  ADD_FAILURE() << "no rmse_" << k;
  return 0;
}

/// Prints the harness's error figures of every fem_hex run and returns nothing; checks that all
/// runs finished and have errors.
void printAndCheckRuns(const Comparison& c) {
  const RunRecord& ref = c.reference();
  ASSERT_EQ(ref.status, RunStatus::Ok) << ref.message;
  const Real peak = peakDisplacement(ref.finalSurface, c.organ.surface.V);
  std::printf("%s: reference %s, %lld tets, peak displacement %.2f mm\n", c.scene.name.c_str(),
              ref.label.c_str(), ref.counts.count("elements") ? ref.counts.at("elements") : -1LL,
              1e3 * peak);
  std::printf("%-14s %6s %9s %9s %9s %9s %7s %9s %10s %9s\n", "model", "hexes", "rmse_10",
              "rmse_50", "rmse_all", "max", "loss", "ms/step", "settle", "CG capped");
  for (const RunRecord& r : c.runs) {
    if (r.isReference) continue;
    ASSERT_EQ(r.status, RunStatus::Ok) << r.label << ": " << r.message;
    ASSERT_TRUE(r.error.has_value()) << r.label;
    ASSERT_GE(r.series.size(), 2u);
    const Real settle =
        peakDisplacement(r.series.back().positions, r.series[r.series.size() - 2].positions);
    std::printf("%-14s %6lld %7.2fmm %7.2fmm %7.2fmm %7.2fmm %7.3f %9.3f %8.3fmm %9lld\n",
                r.label.c_str(), r.counts.at("elements"), 1e3 * rmse(r, 10), 1e3 * rmse(r, 50),
                1e3 * r.error->rmseAll, 1e3 * r.error->max, r.error->lossRatio, r.stepStats.median,
                1e3 * settle,
                r.numeric.count("pcg_not_converged") ? r.numeric.at("pcg_not_converged") : -1LL);
    // The compared instant is a state of rest: fem_hex has settled. Its surface moves less in the
    // last 0.1 s than 5% of its error (else the error would be part dynamics).
    EXPECT_LT(settle, 0.05 * r.error->rmseAll) << r.label << " still moving";
  }
}

/// The shipped scene at 967 and 4000 hexahedra against the reference, its runs printed and
/// checked (printAndCheckRuns; the caller returns on a fatal failure).
Comparison compareShipped(const std::string& name) {
  const fs::path file = shippedScene(name);
  Comparison c = compare(readJson(file), file, {967, 4000});
  printAndCheckRuns(c);
  return c;
}

TEST(FemHexLiverValidation, ValidationScenesMatchTheShippedScenes) {
  // plugins/fem_hex/validation/*.json (for `deformbench run`, README) are the shipped scenes with
  // fem_hex as the models: organ, tools, loads, time and reference must stay identical.
  for (const std::string name : {"liver_grasp_lift", "liver_poke"}) {
    SCOPED_TRACE(name);
    json shipped = readJson(shippedScene(name));
    json mine =
        readJson(fs::path(DEFORM_SOURCE_DIR) / "plugins/fem_hex/validation" / (name + ".json"));
    for (json* j : {&shipped, &mine}) {
      j->erase("name");
      j->erase("description");
      j->erase("models");
    }
    EXPECT_EQ(shipped, mine);
  }
}

// A run whose steps gave up (here the CG solve, capped at one iteration at a tolerance below
// round-off, which refactorising at the current rotations cannot meet) is invalid: fem_hex
// reports them as numeric unconverged_steps, which the harness's validity rule reads (issue 35
// item 4; an unconverged rotation counts the same way). The same run uncapped stays valid.
TEST(FemHexLiverValidation, UnconvergedStepsMakeTheRunInvalid) {
  json j = {
      {"name", "capped"},
      {"organ",
       {{"mesh", "phantom:cube"},
        {"resolution", 0.4},
        {"fixed", {{"box", {{-1, -1, -1}, {1, 1, -0.04}}}}}}},
      {"gravity", {0, 0, -9.81}},
      {"dt", 0.001},
      {"duration", 0.01},
      {"models",
       {{{"plugin", "fem_hex"},
         {"label", "capped"},
         {"params", {{"elements", 100}, {"pcg_max_iterations", 1}, {"pcg_tolerance", 1e-15}}}},
        {{"plugin", "fem_hex"}, {"label", "default"}, {"params", {{"elements", 100}}}}}}};
  const Scene scene = parseScene(j, "capped.json");
  const Organ organ = loadOrgan(scene);
  const std::vector<PlannedRun> planned = planRuns(scene, loader(), BenchmarkOptions{});
  ASSERT_EQ(planned.size(), 2u);
  Cache cache(Cache::defaultDir());
  for (const PlannedRun& p : planned) {
    SCOPED_TRACE(p.label);
    const RunRecord r = runModel(*p.info, p.params, scene, organ, cache);
    ASSERT_EQ(r.status, RunStatus::Ok) << r.message;
    EXPECT_EQ(r.numeric.at("rotation_not_converged"), 0);
    if (p.label == "capped") {
      EXPECT_GT(r.numeric.at("unconverged_steps"), 0);
      EXPECT_FALSE(r.valid);
      EXPECT_NE(r.invalidReason.find("did not converge"), std::string::npos) << r.invalidReason;
    } else {
      EXPECT_EQ(r.numeric.at("unconverged_steps"), 0);
      EXPECT_TRUE(r.valid) << r.invalidReason;
    }
  }
}

TEST(FemHexLiverValidation, GraspLiftAgainstReference) {
  const Comparison c = compareShipped("liver_grasp_lift");
  if (HasFatalFailure()) return;
  const RunRecord &ref = c.reference(), &hex = c.runs[0], &fine = c.runs[1];
  const MatX3& X = c.organ.surface.V;
  const Vec3 grasp = c.scene.tools[0].trajectory[1].pos;  // where the jaws close
  const Vec3 lift = c.scene.tools[0].trajectory.back().pos - grasp;
  const std::vector<int> near = nearestVertices(X, grasp, 10);
  const Real peakRef = peakDisplacement(ref.finalSurface, X);
  for (const RunRecord* r : {&hex, &fine, &ref}) {
    const Vec3 u = meanDisplacement(r->finalSurface, X, near);
    std::printf(
        "%-28s 10 vertices at the grasp moved (%.2f, %.2f, %.2f) mm (tool: %.2f mm up); "
        "sum |u| / reference's %.3f\n",
        r->label.c_str(), 1e3 * u.x(), 1e3 * u.y(), 1e3 * u.z(), 1e3 * lift.z(),
        sumDisplacement(r->finalSurface, X) / sumDisplacement(ref.finalSurface, X));
    // The grasped region follows the tool up (the surface vertices are interpolated from grasped
    // and free nodes, so they need not reach the tool's 25 mm, but most of it).
    EXPECT_GT(u.z(), 0.5 * lift.z()) << r->label;
    EXPECT_LT(u.z(), 1.2 * lift.z()) << r->label;
  }
  EXPECT_TRUE(hex.emptyGrasps.empty()) << "fem_hex's grasp closed on no node";
  // Reaction on the tool: the tissue pulls it down in every model, of the same order (the same
  // material, the same grasped surface lifted by the same 25 mm). Since the grasp is defined on
  // the surface (issue G1) fem_hex holds the grasped points through its embedding (a penalty on
  // J q - t): several held points per cell span its trilinear field, so in effect the cells that
  // carry them are held, at 967 hexahedra (~1 cm cells) a wider, stiffer hold than the
  // reference's surface nodes: its reaction is a few times the reference's (3.6x; 1.8x at 4000).
  for (const RunRecord* r : {&hex, &fine, &ref}) ASSERT_FALSE(r->graspForces.empty()) << r->label;
  const Real fRef = ref.graspForces.back().force.z();
  EXPECT_LT(std::abs(fine.graspForces.back().force.z() - fRef),
            std::abs(hex.graspForces.back().force.z() - fRef))
      << "refinement brings the grasp reaction closer to the reference's";
  for (const RunRecord* r : {&hex, &fine}) {
    const Real f = r->graspForces.back().force.z();
    std::printf("%-28s grasp reaction z %.3f N, reference %.3f N (ratio %.2f)\n", r->label.c_str(),
                f, fRef, f / fRef);
    EXPECT_LT(f, 0.0) << r->label;
    EXPECT_GT(f / fRef, 0.5) << r->label;
    EXPECT_LT(f / fRef, 6.0) << r->label;
  }
  EXPECT_LT(fRef, 0.0);
  // At 967 hexahedra fem_hex is better than a model that does not move at all (loss ratio 1),
  // with its RMS error over the surface below a quarter of the lift.
  EXPECT_LT(hex.error->lossRatio, 1.0);
  EXPECT_LT(hex.error->rmseAll, 0.25 * peakRef);
  // Refinement brings fem_hex closer to the reference, everywhere and at the grasp.
  EXPECT_LT(fine.error->rmseAll, hex.error->rmseAll);
  EXPECT_LT(fine.error->lossRatio, hex.error->lossRatio);
  // The 10 ungrasped vertices nearest the grasp lie in carrying cells at both resolutions, which
  // move rigidly with the tool: their error is the same (the reference's departure from a rigid
  // lift there), not smaller.
  EXPECT_LE(rmse(fine, 10), rmse(hex, 10) * (1 + 1e-9));
  EXPECT_LT(rmse(fine, 50), rmse(hex, 50));
}

TEST(FemHexLiverValidation, PokeAgainstReference) {
  const Comparison c = compareShipped("liver_poke");
  if (HasFatalFailure()) return;
  const RunRecord &ref = c.reference(), &hex = c.runs[0], &fine = c.runs[1];
  const MatX3& X = c.organ.surface.V;
  const Vec3 force = c.scene.loads[0].force;
  const int loaded = nearestVertices(X, c.scene.loads[0].at, 1)[0];
  const Vec3 at = X.row(loaded).transpose();
  // Far field: surface vertices more than 30 mm from the loaded one (3 cells at 967 hexahedra).
  std::vector<int> far;
  for (int v = 0; v < X.rows(); ++v)
    if ((X.row(v).transpose() - at).norm() > 0.03) far.push_back(v);
  auto rmseOver = [&](const MatX3& x, const std::vector<int>& vs) {
    Real s = 0;
    for (int v : vs) s += (x.row(v) - ref.finalSurface.row(v)).squaredNorm();
    return std::sqrt(s / static_cast<Real>(vs.size()));
  };
  const Real peakRef = peakDisplacement(ref.finalSurface, X);
  const Vec3 uRefFar = meanDisplacement(ref.finalSurface, X, far);
  std::printf("%zu of %lld surface vertices farther than 30 mm from the load\n", far.size(),
              static_cast<long long>(X.rows()));
  for (const RunRecord* r : {&hex, &fine, &ref}) {
    const Vec3 u = meanDisplacement(r->finalSurface, X, {loaded});
    const Vec3 uFar = meanDisplacement(r->finalSurface, X, far);
    std::printf("%-28s loaded vertex z %.2f mm; far field: mean z %.2f mm, rmse %.2f mm\n",
                r->label.c_str(), 1e3 * u.z(), 1e3 * uFar.z(),
                1e3 * rmseOver(r->finalSurface, far));
    // Along the force, at the load and on average far from it (the force and gravity push down).
    EXPECT_GT(u.dot(force), 0.0) << r->label;
    EXPECT_GT(uFar.dot(force), 0.0) << r->label;
    // Far from the load the models agree on the sag to within the stiffness margin. fem_hex holds
    // the clamped surface points through its embedding (clamp = points), which, several points
    // to a cell, holds the cells carrying them: at 967 hexahedra (11.5 mm cells around two large
    // fixed boxes) that stiffens it, far-field sag 0.54 of the reference's (0.50 when those
    // cells' nodes were pinned, 1.0 with only the nodes inside the boxes pinned, when the
    // clamped surface itself moved 2.4 mm); 0.92 at 4000.
    EXPECT_GT(uFar.z() / uRefFar.z(), 0.4) << r->label;
    EXPECT_LT(uFar.z() / uRefFar.z(), 1.5) << r->label;
  }
  // The point load's displacement is singular: fem_hex spreads the force over one cell's nodes,
  // so its displacement at the load grows as the cells shrink (967 -> 4000: cells 1.6x smaller).
  const Real dHex = (hex.finalSurface.row(loaded) - X.row(loaded)).norm();
  const Real dFine = (fine.finalSurface.row(loaded) - X.row(loaded)).norm();
  EXPECT_GT(dFine, 1.1 * dHex);
  // Far field and whole surface: bounded at both resolutions, and closer with refinement now that
  // the held clamp makes the coarse grid the stiffer one (far field 4.3 and 7.3 mm against the
  // reference's 7.9; the reference, linear tets at 5000 elements, is itself stiffer than
  // converged: quadratic tets on the same mesh give 9.4 mm, docs/notes/g3-fem-hex-element.md).
  for (const RunRecord* r : {&hex, &fine}) {
    EXPECT_LT(rmseOver(r->finalSurface, far), 0.5 * peakRef) << r->label;
    EXPECT_LT(r->error->lossRatio, 0.6) << r->label;
  }
  EXPECT_LT(fine.error->lossRatio, hex.error->lossRatio);
  EXPECT_LT(rmseOver(fine.finalSurface, far), rmseOver(hex.finalSurface, far));
}

}  // namespace
}  // namespace deform::harness
