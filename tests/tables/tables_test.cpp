// The long harness verbs end to end: a quick table with a missing plugin, the stability sweep with
// a crashing model and --resume, bench --compare verdicts and exit codes, the HTML report, and
// progress lines.
#include <deform/engine/plugin_loader.h>
#include <deform/engine/scene.h>
#include <deform/sdk/cache.h>
#include <deform_harness/analytic.h>
#include <deform_harness/bench.h>
#include <deform_harness/calibration.h>
#include <deform_harness/cases.h>
#include <deform_harness/child_process.h>
#include <deform_harness/convergence.h>
#include <deform_harness/dispatch.h>
#include <deform_harness/progress.h>
#include <deform_harness/scripts.h>
#include <deform_harness/stability.h>
#include <deform_harness/sweep.h>
#include <deform_harness/tables.h>
#include <gtest/gtest.h>

#include <sys/wait.h>
#include "../../harness/src/tables/table_kit.h"  // the tables' internal kit: status cells
#include "../support/temp_dir.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <set>
#include <sstream>

namespace deform::harness {
namespace {

namespace fs = std::filesystem;
using json = nlohmann::json;

class TempDir : public ::testing::Test {
 protected:
  void SetUp() override { m_dir = deform::testing::freshTestDir("deform_tables_"); }
  void TearDown() override {
    if (!HasFailure()) fs::remove_all(m_dir);
  }
  fs::path m_dir;
};

json readJson(const fs::path& p) {
  std::ifstream in(p);
  return json::parse(in);
}

std::string readText(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// A plugin folder holding only the named plugins of the build tree (symlinks).
fs::path pluginSubset(const fs::path& dir, const std::vector<std::string>& names) {
  fs::create_directories(dir);
  PluginLoader all({DEFORM_BUILD_PLUGIN_DIR});
  for (const auto& n : names) {
    const fs::path so = all.locate(n);
    fs::create_symlink(so, dir / so.filename());
  }
  return dir;
}

int exitCodeOf(const std::string& cmd) {
  const int status = std::system(cmd.c_str());
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// ------------------------------------------------------------------------------------- tables

TEST_F(TempDir, QuickBemAccuracyFillsThePapersStaticMeasure) {
  PluginLoader probe({DEFORM_BUILD_PLUGIN_DIR});
  const auto found = probe.discover();
  if (std::find(found.begin(), found.end(), std::string("particle_bem")) == found.end())
    GTEST_SKIP() << "particle_bem is not built";
  PluginLoader loader({pluginSubset(m_dir / "plugins", {"particle_bem"}).string()});
  TablesOptions o;
  o.quick = true;
  o.referenceCheck = false;
  o.outDir = m_dir / "out";
  o.cases.cacheDir = m_dir / "cache";
  buildTables({"bem-accuracy"}, loader, o, nullptr);
  const json doc = readJson(o.outDir / "bem-accuracy.json");
  ASSERT_EQ(doc["rows"].size(), 7u);
  int filled = 0;
  for (const auto& row : doc["rows"]) {
    if (row["status"] != "ok") {
      EXPECT_FALSE(row.contains("static_loss_ratio")) << row.dump();
      continue;
    }
    ++filled;
    ASSERT_TRUE(row.contains("static_loss_ratio")) << row.dump();
    const double r = row["static_loss_ratio"];
    // R of a 284-vertex surface against a finer or equal one: positive, a few per cent.
    EXPECT_GT(r, 1e-4) << row.dump();
    EXPECT_LT(r, 0.1) << row.dump();
    const int fine = row["static_fine_vertices"];
    EXPECT_NEAR(fine, row["paper_fine_vertices"].get<int>(), 0.1 * fine) << row.dump();
    EXPECT_NEAR(row["static_vertex_ratio"].get<double>(), double(fine) / 284.0, 1e-9);
    EXPECT_EQ(row["note"], "") << "nothing to say when the static measure was computed";
  }
  EXPECT_EQ(filled, 2) << "--quick: 284 against 256 and 394";
  // The larger fine surface is further from the 284 coarse one (2.3% against 0.8% in the
  // particle_bem README): the measure grows with the vertex ratio here.
  EXPECT_LT(doc["rows"][0]["static_loss_ratio"].get<double>(),
            doc["rows"][1]["static_loss_ratio"].get<double>());
}

TEST_F(TempDir, BemAccuracyStaticMeasureFromTheOverrideFileOrSaysWhyBlank) {
  // No plugins at all: the cases are not run, the static measure cannot be computed.
  fs::create_directories(m_dir / "plugins");
  PluginLoader loader({(m_dir / "plugins").string()});
  TablesOptions o;
  o.quick = true;
  o.referenceCheck = false;
  o.outDir = m_dir / "out";
  o.cases.cacheDir = fs::path();
  buildTables({"bem-accuracy"}, loader, o, nullptr);
  json doc = readJson(o.outDir / "bem-accuracy.json");
  EXPECT_FALSE(doc["rows"][0].contains("static_loss_ratio"));
  EXPECT_NE(doc["rows"][0]["note"].get<std::string>().find("static measure not computed"),
            std::string::npos)
      << doc["rows"][0].dump();
  // A file of static rows in the output folder overrides the computation.
  {
    std::ofstream f(o.outDir / "bem-accuracy-static.json");
    f << R"([{"name": "bem-accuracy", "rows": [{"coarse_vertices": 284, "fine_vertices": 256,
             "vertex_ratio": 0.9, "loss_ratio": 0.0123}]}])";
  }
  buildTables({"bem-accuracy"}, loader, o, nullptr);
  doc = readJson(o.outDir / "bem-accuracy.json");
  EXPECT_EQ(doc["rows"][0]["static_loss_ratio"].get<double>(), 0.0123);
  EXPECT_EQ(doc["rows"][0]["static_fine_vertices"].get<int>(), 256);
  EXPECT_FALSE(doc["rows"][1].contains("static_loss_ratio")) << "not in the file";
}

TEST_F(TempDir, QuickHybridTimingRunsWhatLoadsAndSaysWhatIsMissing) {
  PluginLoader probe({DEFORM_BUILD_PLUGIN_DIR});
  for (const char* p : {"pbd", "massspring"})
    if (probe.discover().end() ==
        std::find(probe.discover().begin(), probe.discover().end(), std::string(p)))
      GTEST_SKIP() << p << " is not built";
  // Only pbd and mass-spring: hybrid_fem_pbd and reference_fem are missing on purpose.
  PluginLoader loader({pluginSubset(m_dir / "plugins", {"pbd", "massspring"}).string()});
  TablesOptions o;
  o.quick = true;
  o.outDir = m_dir / "out";
  o.cases.cacheDir = fs::path();
  const auto tables = buildTables({"hybrid-timing"}, loader, o, nullptr);
  ASSERT_EQ(tables.size(), 1u);
  for (const char* ext : {".md", ".csv", ".json"})
    EXPECT_TRUE(fs::exists(o.outDir / (std::string("hybrid-timing") + ext))) << ext;

  const json doc = readJson(o.outDir / "hybrid-timing.json");
  EXPECT_EQ(doc["format"], "deformbench-table/1");
  ASSERT_EQ(doc["rows"].size(), 4u) << "--quick: the cube at 2 and 20 N, up and down";
  std::vector<std::string> keys;
  for (const auto& c : doc["columns"]) keys.push_back(c["key"]);
  for (const char* k : {"paper_hybrid_ms", "paper_pbd_ms", "paper_massspring_ms", "paper_fem_ms"})
    EXPECT_NE(std::find(keys.begin(), keys.end(), k), keys.end()) << k;
  for (const auto& row : doc["rows"]) {
    ASSERT_TRUE(row["pbd_ms"].is_number()) << row.dump();
    EXPECT_GT(row["pbd_ms"].get<double>(), 0.0);
    EXPECT_GT(row["massspring_ms"].get<double>(), 0.0);
    EXPECT_TRUE(row["hybrid_ms"].is_null());
    const std::string status = row["status"];
    EXPECT_NE(status.find("missing plugin hybrid_fem_pbd"), std::string::npos) << status;
    EXPECT_NE(status.find("reference"), std::string::npos) << status;
    // The scene of the row reruns with `deformbench run`: it parses and names every model.
    const fs::path scene = o.outDir / row["scene"].get<std::string>();
    ASSERT_TRUE(fs::exists(scene)) << scene;
    const Scene s = parseSceneFile(scene.string());
    EXPECT_EQ(s.models.size(), 3u);
    EXPECT_TRUE(s.reference.has_value());
    // PBD and mass-spring run on the volume of the fine surface (the note says so).
    for (const ModelSpec& m : s.models) {
      if (m.plugin != "hybrid_fem_pbd") {
        EXPECT_EQ(m.params.value("network", ""), "volume") << m.plugin;
      }
    }
  }
  EXPECT_NE(doc["notes"].dump().find("run on the volume of the same fine surface"),
            std::string::npos);
  // The networks have no barrier against inversion. Pressed down by 20 N they fold through
  // themselves: both runs are invalid, and the status says why. At 2 N mass-spring inverts a
  // few slivers under the patch: valid, and the note counts them.
  const json& folded = doc["rows"][3];
  ASSERT_EQ(folded["direction"], "down");
  const std::string foldedStatus = folded["status"];
  for (const char* m : {"pbd: invalid (", "massspring: invalid ("})
    EXPECT_NE(foldedStatus.find(m), std::string::npos) << m << " in " << foldedStatus;
  EXPECT_NE(foldedStatus.find("tets inverted (over 0.5%)"), std::string::npos) << foldedStatus;
  const json& pressed = doc["rows"][1];
  ASSERT_EQ(pressed["direction"], "down");
  EXPECT_EQ(pressed["status"].get<std::string>().find("invalid"), std::string::npos)
      << pressed.dump();
  EXPECT_NE(pressed["note"].get<std::string>().find("massspring: "), std::string::npos)
      << pressed.dump();
  EXPECT_NE(pressed["note"].get<std::string>().find("tets inverted at the compared state"),
            std::string::npos)
      << pressed.dump();
  const std::string csv = readText(o.outDir / "hybrid-timing.csv");
  EXPECT_EQ(csv.substr(0, csv.find('\n')).rfind("phantom,force_N,direction,hybrid_ms", 0), 0u)
      << csv.substr(0, 80);
  EXPECT_EQ(std::count(csv.begin(), csv.end(), '\n'), 5);
  const std::string md = readText(o.outDir / "hybrid-timing.md");
  EXPECT_NE(md.find("| phantom | force N |"), std::string::npos);

  // The reference check: reference_fem is missing, so the table says its reference was not
  // checked (and runs no study) instead of claiming anything.
  bool notChecked = false;
  for (const auto& n : doc["notes"])
    if (n.get<std::string>().find("reference (hybrid/cube_down_20N): convergence not checked: "
                                  "missing plugin reference_fem") != std::string::npos)
      notChecked = true;
  EXPECT_TRUE(notChecked) << doc["notes"].dump();
  EXPECT_NE(md.find("convergence not checked"), std::string::npos);
  EXPECT_FALSE(fs::exists(o.outDir / "convergence"));

  // --no-reference-check: the table says the check was skipped (no plugin at all: nothing runs).
  fs::create_directories(m_dir / "no_plugins");
  PluginLoader none({(m_dir / "no_plugins").string()});
  o.referenceCheck = false;
  o.outDir = m_dir / "out_unchecked";
  buildTables({"hybrid-timing"}, none, o, nullptr);
  const json unchecked = readJson(o.outDir / "hybrid-timing.json");
  const std::string notes = unchecked["notes"].dump();
  EXPECT_NE(notes.find("convergence not checked (--no-reference-check)"), std::string::npos)
      << notes;
  EXPECT_EQ(notes.find("reference (hybrid/"), std::string::npos) << notes;
}

// ------------------------------------------------------------------------- reference check

/// Whether every named plugin is built.
bool built(const std::vector<std::string>& names) {
  PluginLoader probe({DEFORM_BUILD_PLUGIN_DIR});
  const auto found = probe.discover();
  for (const auto& n : names)
    if (std::find(found.begin(), found.end(), n) == found.end()) return false;
  return true;
}

/// The notes of a table file that contain `part`.
std::vector<std::string> notesWith(const json& table, const std::string& part) {
  std::vector<std::string> out;
  for (const auto& n : table["notes"])
    if (n.get<std::string>().find(part) != std::string::npos) out.push_back(n);
  return out;
}

TEST_F(TempDir, CalibrationsApplyToTheirOrganAndTheirRowsKeepValidity) {
  if (!built({"massspring", "reference_fem"}))
    GTEST_SKIP() << "massspring or reference_fem is not built";
  // Two calibrations of mass-spring: one fitted on the cube (the quick hybrid cases' phantom),
  // one on the liver. Only the cube's is twinned; the calibration table says so, and a default
  // run that did not settle is "invalid" there as in the paper table, never ok.
  const fs::path plugins = pluginSubset(m_dir / "plugins", {"massspring", "reference_fem"});
  // The cube's file says it was fitted on the volume network: its twins, run on the surface
  // network (--surface-baselines), carry a note.
  const auto calibration = [this](const std::string& name, const std::string& organ, double t) {
    const fs::path f = m_dir / (name + ".json");
    std::ofstream(f) << json{{"format", "deformbench-calibration/1"},
                             {"plugin", "massspring"},
                             {"model", "massspring"},
                             {"params", {{"thickness", t}}},
                             {"organs", {organ}},
                             {"held", {{"network", "volume"}}},
                             {"at_bound", {{"thickness", "max"}}}}
                            .dump();
    return readCalibrationFile(f.string());
  };
  PluginLoader loader({plugins.string()});
  TablesOptions o;
  o.quick = true;
  o.outDir = m_dir / "out";
  o.cases.cacheDir = m_dir / "cache";
  o.referenceElements = 800;
  o.referenceCheck = false;
  o.calibrations = {calibration("liver", "phantom:liver, resolution 0.27", 0.02),
                    calibration("cube", "phantom:cube, resolution 1", 0.2)};
  o.surfaceBaselines = true;  // the membrane, whose thickness these calibrations fit
  buildTables({"hybrid-accuracy"}, loader, o, nullptr);
  EXPECT_FALSE(readJson(o.outDir / "scenes/hybrid/cube_up_2N.json")["models"][2]["params"].contains(
      "network"))
      << "--surface-baselines: the paper's surface networks";
  const json doc = readJson(o.outDir / "calibration.json");
  ASSERT_EQ(doc["rows"].size(), 4u) << "one twin per quick case (all cube), none from the liver's";
  bool invalidDefault = false;
  for (const auto& row : doc["rows"]) {
    EXPECT_EQ(row["model"], "massspring");
    ASSERT_TRUE(row["rmse_50_calibrated_mm"].is_number()) << row.dump();
    const std::string status = row["status"];
    invalidDefault |= status.find("default invalid (did not settle)") != std::string::npos;
    EXPECT_NE(
        row["note"].get<std::string>().find(
            "was fitted with other parameters: network = \"surface\" (fitted with \"volume\")"),
        std::string::npos)
        << row.dump();
    EXPECT_NE(
        row["note"].get<std::string>().find("; calibration " + (m_dir / "cube.json").string() +
                                            ": thickness fitted at its upper bound"),
        std::string::npos)
        << row.dump();
  }
  EXPECT_TRUE(invalidDefault) << "pressed down, the default membrane creeps past the 2 s cap: "
                              << doc["rows"].dump();
  const std::string notes = doc["notes"].dump();
  EXPECT_NE(notes.find("applied to phantom:cube, resolution 1 only"), std::string::npos) << notes;
  const json results = readJson(o.outDir / "runs/hybrid/cube_up_2N/results.json");
  std::set<std::string> labels;
  for (const auto& run : results["runs"]) labels.insert(run["label"].get<std::string>());
  EXPECT_EQ(labels.count("massspring+cal"), 1u);
}

TEST_F(TempDir, UnderResolvedReferenceIsWarnedInTheTableAndTheStudyIsCached) {
  if (!built({"massspring", "reference_fem"}))
    GTEST_SKIP() << "massspring or reference_fem is not built";
  // One cheap model (a case needs one) and the reference, quadratic tets as everywhere. 800
  // target tets: the study's levels (100, 286, 800 targets) are all about the coarsest mesh the
  // cube's surface allows, so the reference cannot be shown converged.
  const fs::path plugins = pluginSubset(m_dir / "plugins", {"massspring", "reference_fem"});
  const fs::path out = m_dir / "out", cache = m_dir / "cache";
  PluginLoader loader({plugins.string()});
  TablesOptions o;
  o.quick = true;
  o.outDir = out;
  o.cases.cacheDir = cache;
  o.referenceElements = 800;
  const auto tables = buildTables({"hybrid-accuracy"}, loader, o, nullptr);
  const json doc = readJson(out / "hybrid-accuracy.json");
  // Pressed down with 20 N the quadratic reference spends its budget of Newton iterations (on
  // this coarse mesh, pulled up it answers): that row reads against an invalid reference, and the
  // pressed cube is studied at its largest load with a valid one, 2 N.
  for (const auto& row : doc["rows"]) {
    const std::string status = row["status"];
    const bool answered = row["force_N"] == 2.0 || row["direction"] == "up";
    EXPECT_EQ(status.find("reference: ") == std::string::npos, answered) << row.dump();
    if (answered) continue;
    EXPECT_FALSE(row.value("reference_valid", true)) << row.dump();
    EXPECT_NE(status.find("against an invalid reference"), std::string::npos) << status;
    EXPECT_NE(status.find("gave up at its budget of Newton iterations"), std::string::npos)
        << status;
  }
  const auto notes = notesWith(doc, "reference (hybrid/cube_down_2N): reference_fem P2");
  ASSERT_EQ(notes.size(), 1u) << doc["notes"].dump();
  EXPECT_TRUE(notes[0].find("estimated discretisation error") != std::string::npos ||
              notes[0].find("no discretisation error estimate") != std::string::npos)
      << notes[0];
  // Pulling and pressing are studied apart.
  const auto warnings = notesWith(doc, "warning: reference (hybrid/cube_");
  ASSERT_EQ(warnings.size(), 2u) << doc["notes"].dump();
  EXPECT_EQ(warnings[1].rfind("warning: reference (hybrid/cube_up_20N)", 0), 0u) << warnings[1];
  ASSERT_FALSE(doc["rows"].empty());
  // Every row names the reference it is judged against (order, tets) and its estimate, or why
  // there is none; the rows of other forces say which case's study that is (their direction's).
  for (const auto& row : doc["rows"]) {
    const std::string ref = row["reference"].is_string() ? row["reference"].get<std::string>() : "";
    EXPECT_EQ(ref.rfind("P2, ", 0), 0u) << row.dump();
    EXPECT_TRUE(ref.find("error") != std::string::npos ||
                ref.find("no estimate (") != std::string::npos)
        << ref;
    const bool up = row["direction"] == "up";
    const bool checked = row["force_N"] == (up ? 20.0 : 2.0);
    const std::string study =
        up ? "(study of hybrid/cube_up_20N)" : "(study of hybrid/cube_down_2N)";
    EXPECT_EQ(ref.find(study) == std::string::npos, checked) << ref;
  }
  // Every row with an answer shows the displacement its errors measure (the reference's, over
  // the same 50 vertices), and mass-spring, given the hybrid's damping, settles within the quick
  // cap under tension.
  for (const auto& row : doc["rows"]) {
    if (row["force_N"] != 2.0 && row["direction"] != "up") continue;
    ASSERT_TRUE(row["reference_disp_mm"].is_number()) << row.dump();
    EXPECT_GT(row["reference_disp_mm"].get<double>(), 0.1) << row.dump();
    if (row["direction"] == "up") {
      EXPECT_EQ(row["status"].get<std::string>().find("massspring: invalid"), std::string::npos)
          << row.dump();
    }
  }
  const std::string md = readText(out / "hybrid-accuracy.md");
  EXPECT_NE(md.find(notes[0]), std::string::npos);
  EXPECT_NE(md.find(warnings[0]), std::string::npos);
  EXPECT_EQ(tableWarnings(tables), warnings) << "what the command prints at the end";

  // The study: levels 2h, 1.4h, h whose third is the table's reference (same target, same mesh),
  // and a finer fourth, since the cube's surface bounds the coarse ones.
  const json study = readJson(out / "convergence/hybrid/cube_down_2N/convergence.json");
  ASSERT_EQ(study["levels"].size(), 4u);
  EXPECT_EQ(study["estimated_level"], 2);
  EXPECT_EQ(study["levels"][2]["target_elements"], 800);
  EXPECT_EQ(study["levels"][0]["target_elements"], 100);
  EXPECT_EQ(study["cached"], false);
  EXPECT_EQ(study["converged"], false);
  EXPECT_EQ(study["element_order"], 2) << "upper estimates at the quadratic tets' order";
  const json results = readJson(out / "runs/hybrid/cube_down_2N/results.json");
  long long referenceTets = -1;
  for (const auto& run : results["runs"])
    if (run["label"] == "reference_fem") referenceTets = run["counts"]["elements"];
  EXPECT_EQ(study["levels"][2]["elements"], referenceTets) << "the finest level is the same mesh";
  EXPECT_NE(notes[0].find(std::to_string(referenceTets) + " tets"), std::string::npos) << notes[0];
  // The finest level is not solved again: it reads the case's reference solve from the cache
  // (same problem, plugin and parameters; another label); the coarser levels are solved.
  const auto levelNotes = [&](int k) {
    const json r = readJson(out / ("convergence/hybrid/cube_down_2N/level_" + std::to_string(k)) /
                            "results.json");
    // A run without notes has no "notes" key.
    return r["runs"][0].value("notes", json::array()).dump();
  };
  EXPECT_NE(levelNotes(2).find("read from the cache"), std::string::npos) << levelNotes(2);
  EXPECT_EQ(levelNotes(1).find("read from the cache"), std::string::npos) << levelNotes(1);
  EXPECT_EQ(levelNotes(0).find("read from the cache"), std::string::npos) << levelNotes(0);

  // The same study again (as a second tables run would ask for it): read from the cache.
  ConvergeOptions co = referenceCheckOptions();
  co.outDir = m_dir / "again";
  co.cacheDir = cache;
  const ConvergenceResult cached =
      runConvergence((out / "scenes/hybrid/cube_down_2N.json").string(), loader, co, nullptr);
  EXPECT_TRUE(cached.cached);
  ASSERT_EQ(cached.levels.size(), 4u);
  EXPECT_EQ(cached.levels[2].elements, referenceTets);
  EXPECT_EQ(cached.d12, study["d12_m"].get<double>());
  // The RMS differences: over the same vertices as the max, so positive and not above it.
  ASSERT_TRUE(study["rms_d12_m"].is_number());
  EXPECT_GT(study["rms_d12_m"].get<double>(), 0.0);
  EXPECT_LE(study["rms_d12_m"].get<double>(), study["d12_m"].get<double>());
  EXPECT_LE(study["rms_d01_m"].get<double>(), study["d01_m"].get<double>());
  EXPECT_EQ(cached.rms12, study["rms_d12_m"].get<double>());
  EXPECT_FALSE(fs::exists(co.outDir / "level_0")) << "nothing was run";
  EXPECT_EQ(readJson(co.outDir / "convergence.json")["cached"], true);

  // The table again with its cases and the study's levels in child processes, two at a time
  // (tables --jobs 2), from a cold cache: the same study.
  TablesOptions oj = o;
  oj.outDir = m_dir / "out_jobs";
  oj.cases.cacheDir = m_dir / "cache_jobs";
  ChildCaseOptions child;
  child.executable = DEFORMBENCH_EXE;
  child.pluginArgs = pluginDirArgs(loader.searchPath());
  child.timeoutS = 300;
  oj.cases.child = child;
  const auto jobs = localDispatcher(2);
  oj.cases.dispatcher = jobs.get();
  buildTables({"hybrid-accuracy"}, loader, oj, nullptr);
  const fs::path jobsStudy = oj.outDir / "convergence/hybrid/cube_down_2N";
  const json viaJobs = readJson(jobsStudy / "convergence.json");
  ASSERT_EQ(viaJobs["levels"].size(), 4u);
  for (size_t k = 0; k < 4; ++k)
    EXPECT_EQ(viaJobs["levels"][k]["elements"], study["levels"][k]["elements"]) << k;
  EXPECT_EQ(viaJobs["d01_m"], study["d01_m"]);
  EXPECT_EQ(viaJobs["d12_m"], study["d12_m"]);
  EXPECT_TRUE(fs::exists(jobsStudy / "level_0/case.json")) << "level 0 ran in a child";
}

// The hybrid tables study, per phantom and direction, the largest load whose reference is valid:
// one whose surface passed through itself (invalid) does not stand for the smaller loads.
TEST(ReferenceCheck, HybridTablesStudyTheLargestLoadWithAValidReference) {
  const auto results = [](const std::set<std::string>& invalid) {
    tables::Results res;
    for (const char* id : {"hybrid/cube_up_2N", "hybrid/cube_down_2N", "hybrid/cube_up_20N",
                           "hybrid/cube_down_20N"}) {
      RunRecord ref;
      ref.isReference = true;
      ref.status = RunStatus::Ok;
      ref.valid = !invalid.count(id);
      res[id].result.emplace().runs.push_back(ref);
    }
    return res;
  };
  using V = std::vector<std::string>;
  EXPECT_EQ(tables::hybridChecks(results({}), true),
            (V{"hybrid/cube_down_20N", "hybrid/cube_up_20N"}));
  EXPECT_EQ(tables::hybridChecks(results({"hybrid/cube_down_20N"}), true),
            (V{"hybrid/cube_down_2N", "hybrid/cube_up_20N"}));
  // No valid reference in a direction: its largest load, whose cell then says why.
  EXPECT_EQ(tables::hybridChecks(results({"hybrid/cube_down_20N", "hybrid/cube_down_2N"}), true),
            (V{"hybrid/cube_down_20N", "hybrid/cube_up_20N"}));
}

TEST(ReferenceCheck, RichardsonRecoversTheOrderAndTheWarningFollowsTheEstimate) {
  // Levels of u_k = u + C h_k^2: the estimate recovers p = 2 and the finest level's error C h2^2.
  const double h0 = 0.01, h1 = 0.0071, h2 = 0.005, peak = 0.01;
  for (const double c : {0.5, 50.0}) {
    ConvergenceResult r;
    for (double h : {h0, h1, h2}) r.levels.push_back({0, 1000, h, peak, "ok", 1.0});
    richardsonEstimate(h0, h1, h2, c * (h0 * h0 - h1 * h1), c * (h1 * h1 - h2 * h2), peak, r);
    EXPECT_NEAR(r.order, 2.0, 1e-6);
    EXPECT_NEAR(r.errorEstimate, c * h2 * h2, 1e-9 * c);
    EXPECT_TRUE(r.asymptotic);
    // The same levels read as a reference (h1) between a coarser and a finer level: its error
    // is C h1^2, the finest pair's difference plus the finest level's error.
    ConvergenceResult middle;
    richardsonEstimate(h0, h1, h2, c * (h0 * h0 - h1 * h1), c * (h1 * h1 - h2 * h2), peak, middle,
                       EstimateOf::Middle);
    EXPECT_NEAR(middle.errorEstimate, c * h1 * h1, 1e-9 * c);
    EXPECT_NEAR(middle.errorEstimate, r.errorEstimate + c * (h1 * h1 - h2 * h2), 1e-9 * c);
    const std::string summary = convergenceSummary(r);
    EXPECT_NE(summary.find("p = 2.00"), std::string::npos) << summary;
    EXPECT_EQ(summary.find("RMS"), std::string::npos) << "no RMS differences given";
    r.rms01 = 2e-5;
    r.rms12 = 1e-5;
    EXPECT_NE(convergenceSummary(r).find("RMS level differences 0.2% then 0.1%"), std::string::npos)
        << convergenceSummary(r);
    const double percent = 100 * c * h2 * h2 / peak;  // 0.125% and 12.5%
    EXPECT_EQ(r.converged, percent <= 1) << percent;
    const std::string warning = convergenceWarning(r);
    EXPECT_EQ(warning.empty(), percent <= 1) << warning;
    if (percent > 1) {
      EXPECT_NE(warning.find("not converged to 1%"), std::string::npos) << warning;
    }
  }
  // Differences that shrink faster than order 4 (p = 6): the finest pair is extrapolated at
  // order 2 instead, an upper estimate; converged when that is within 1%, warned when not.
  for (const double c : {1e6, 1e12}) {
    ConvergenceResult fast;
    const auto h6 = [](double h) { return std::pow(h, 6); };
    const double d12 = c * (h6(h1) - h6(h2));
    richardsonEstimate(h0, h1, h2, c * (h6(h0) - h6(h1)), d12, 0.01, fast);
    EXPECT_NEAR(fast.order, 6.0, 1e-6);
    EXPECT_FALSE(fast.asymptotic);
    EXPECT_EQ(fast.reason, "not_asymptotic");
    EXPECT_NEAR(fast.errorEstimate, d12 * h2 * h2 / (h1 * h1 - h2 * h2), 1e-12 * d12);
    EXPECT_GT(fast.errorEstimate, d12 * std::pow(h2, 6) / (h6(h1) - h6(h2)));  // above p = 6's
    EXPECT_NE(fast.message.find("p = 6.00 is above 4"), std::string::npos) << fast.message;
    EXPECT_EQ(fast.converged, fast.relativeError <= 0.01);
    EXPECT_EQ(convergenceWarning(fast).empty(), fast.converged) << convergenceWarning(fast);
    // A linear-tet reference: at order 1, its elements' lower rate, a larger upper estimate.
    ConvergenceResult linear;
    linear.elementOrder = 1;
    richardsonEstimate(h0, h1, h2, c * (h6(h0) - h6(h1)), d12, 0.01, linear);
    EXPECT_NEAR(linear.errorEstimate, d12 * h2 / (h1 - h2), 1e-12 * d12);
    EXPECT_GT(linear.errorEstimate, fast.errorEstimate);
    EXPECT_NE(linear.message.find("extrapolated at order 1 instead"), std::string::npos)
        << linear.message;
  }
  // Levels that do not refine: no estimate, and the warning says the convergence is unknown.
  ConvergenceResult flat;
  richardsonEstimate(h0, h0, h0, 1e-3, 1e-3, 0.01, flat);
  EXPECT_TRUE(std::isnan(flat.relativeError));
  EXPECT_EQ(flat.reason, "not_refining");
  EXPECT_NE(convergenceSummary(flat).find("no discretisation error estimate"), std::string::npos);
  EXPECT_NE(convergenceWarning(flat).find("unknown"), std::string::npos);
}

TEST_F(TempDir, ConvergeLevelsRefineByEdgeLength) {
  if (!built({"reference_fem"})) GTEST_SKIP() << "reference_fem is not built";
  PluginLoader loader({pluginSubset(m_dir / "plugins", {"reference_fem"}).string()});
  // The dispatch test's cube under gravity (surface edges ~20 mm at resolution 0.4), P1.
  const nlohmann::ordered_json scene = {
      {"name", "converge-h"},
      {"organ",
       {{"mesh", "phantom:cube"},
        {"resolution", 0.4},
        {"material", {{"young", 3000}, {"poisson", 0.3}, {"density", 1000}}},
        {"fixed", {{"box", {{-0.06, -0.06, -0.06}, {0.06, 0.06, -0.045}}}}}}},
      {"gravity", {0, -9.81, 0}},
      {"dt", 0.01},
      {"duration", 0.01},
      {"models", {{{"plugin", "reference_fem"}, {"label", "unused"}}}},  // a scene needs one
      {"reference",
       {{"plugin", "reference_fem"}, {"params", {{"element_order", 1}, {"elements", 150}}}}},
      {"output", {{"surfaces", "none"}}}};
  ConvergeOptions o;
  o.baseEdgeLength = 0.02;
  o.outDir = m_dir / "h";
  o.cacheDir = fs::path();
  const ConvergenceResult r =
      runConvergence(scene, (m_dir / "scene.json").string(), loader, o, nullptr);
  ASSERT_EQ(r.levels.size(), 3u);
  // The levels ask for h, h/1.4, h/2 and the meshes made really differ by about those ratios.
  EXPECT_DOUBLE_EQ(r.levels[0].targetH, 0.02);
  EXPECT_NEAR(r.levels[0].targetH / r.levels[1].targetH, 1.4, 1e-12);
  EXPECT_NEAR(r.levels[0].targetH / r.levels[2].targetH, 2.0, 1e-12);
  for (const auto& l : r.levels) EXPECT_EQ(l.status, "ok");
  EXPECT_GT(r.levels[0].h / r.levels[1].h, 1.2) << r.levels[0].h << " " << r.levels[1].h;
  EXPECT_GT(r.levels[1].h / r.levels[2].h, 1.2) << r.levels[1].h << " " << r.levels[2].h;
  EXPECT_NE(r.reason, "levels_too_close") << r.message;
  const json doc = readJson(o.outDir / "convergence.json");
  EXPECT_NEAR(doc["levels"][2]["target_h_m"].get<double>(), 0.01, 1e-12);
  EXPECT_EQ(readJson(o.outDir / "level_1.json")["models"][0]["params"]["edge_length"],
            r.levels[1].targetH);
  // The reference's own check (2h, 1.4h, h of its 150 targets, ~40 mm): its finest level is the
  // reference as it runs (params untouched), and every level is as coarse as the surface allows,
  // so the study says the levels are too close, in the JSON and in the summary.
  ConvergeOptions own;
  own.hRatios = kReferenceCheckRatios;
  own.outDir = m_dir / "own";
  own.cacheDir = fs::path();
  const ConvergenceResult c =
      runConvergence(scene, (m_dir / "scene.json").string(), loader, own, nullptr);
  EXPECT_FALSE(
      readJson(own.outDir / "level_2.json")["models"][0]["params"].contains("edge_length"));
  EXPECT_NEAR(c.levels[0].targetH / c.levels[2].targetH, 2.0, 1e-12);
  EXPECT_EQ(c.reason, "levels_too_close") << c.message;
  EXPECT_EQ(readJson(own.outDir / "convergence.json")["reason"], "levels_too_close");
  EXPECT_NE(convergenceSummary(c).find("too close in size"), std::string::npos)
      << convergenceSummary(c);
  // Graded toward the top face's centre, the same check's levels refine there by 2 and 1.4
  // where the surface bounds the uniform ones: h is the size field's scale and Richardson applies.
  nlohmann::ordered_json gradedScene = scene;
  gradedScene["reference"]["params"].update(
      {{"focus_z", 0.05}, {"focus_radius", 0.01}, {"focus_ratio", 0.3}});
  ConvergeOptions graded = own;
  graded.outDir = m_dir / "graded";
  const ConvergenceResult g =
      runConvergence(gradedScene, (m_dir / "graded.json").string(), loader, graded, nullptr);
  ASSERT_EQ(g.levels.size(), 3u);
  EXPECT_TRUE(g.graded);
  EXPECT_EQ(readJson(graded.outDir / "convergence.json")["graded"], true);
  for (size_t k = 0; k < 3; ++k) {
    EXPECT_EQ(g.levels[k].status, "ok");
    EXPECT_DOUBLE_EQ(g.levels[k].h, g.levels[k].targetH);
    EXPECT_GT(g.levels[k].elements, c.levels[k].elements) << k;
  }
  EXPECT_GT(g.levels[1].elements, g.levels[0].elements);
  EXPECT_GT(g.levels[2].elements, g.levels[1].elements);
  EXPECT_NE(g.reason, "levels_too_close") << g.message;
  // The check the tables run adds a level finer than the reference (h / 1.4) when the surface
  // bounds the coarse ones, and estimates the reference's error (level 2) from the last three.
  ASSERT_FALSE(c.converged);
  ConvergeOptions finer = referenceCheckOptions();
  finer.outDir = m_dir / "finer";
  finer.cacheDir = fs::path();
  const ConvergenceResult f =
      runConvergence(scene, (m_dir / "scene.json").string(), loader, finer, nullptr);
  ASSERT_EQ(f.levels.size(), 4u);
  EXPECT_TRUE(f.finerLevelAdded);
  EXPECT_EQ(f.estimatedLevel, 2);
  EXPECT_NEAR(f.levels[2].targetH / f.levels[3].targetH, kFinerLevelStep, 1e-12);
  EXPECT_EQ(readJson(finer.outDir / "level_3.json")["models"][0]["params"]["edge_length"],
            f.levels[3].targetH);
  EXPECT_GT(f.levels[3].elements, f.levels[2].elements);
  const json fdoc = readJson(finer.outDir / "convergence.json");
  EXPECT_EQ(fdoc["finer_level_added"], true);
  EXPECT_EQ(fdoc["estimated_level"], 2);
  EXPECT_EQ(fdoc["levels"].size(), 4u);
  if (std::isfinite(f.relativeError)) {
    EXPECT_NE(convergenceSummary(f).find("of level 2 (the reference"), std::string::npos)
        << convergenceSummary(f);
  }
  // The same studies at once (as the tables check their references), with one that cannot be
  // prepared among them: each gets its own answer, the broken one a message.
  std::vector<ConvergenceStudyInput> batch = {
      {scene, (m_dir / "scene.json").string(), o},
      {nlohmann::ordered_json{{"name", "no-reference"}}, (m_dir / "bad.json").string(), o},
      {gradedScene, (m_dir / "graded.json").string(), graded},
      {scene, (m_dir / "scene.json").string(), finer}};
  for (size_t i = 0; i < batch.size(); ++i)
    batch[i].options.outDir = m_dir / ("batch" + std::to_string(i));
  const std::vector<ConvergenceResult> all = runConvergences(batch, loader, nullptr);
  ASSERT_EQ(all.size(), 4u);
  EXPECT_TRUE(all[1].levels.empty());
  EXPECT_FALSE(all[1].message.empty());
  const ConvergenceResult* alone[] = {&r, nullptr, &g, &f};
  for (size_t i : {0, 2, 3}) {
    ASSERT_EQ(all[i].levels.size(), alone[i]->levels.size()) << i;
    for (size_t k = 0; k < all[i].levels.size(); ++k)
      EXPECT_EQ(all[i].levels[k].elements, alone[i]->levels[k].elements) << i << " " << k;
    EXPECT_EQ(all[i].d01, alone[i]->d01) << i;
    EXPECT_EQ(all[i].d12, alone[i]->d12) << i;
    EXPECT_EQ(all[i].finerLevelAdded, alone[i]->finerLevelAdded) << i;
    EXPECT_EQ(readJson(batch[i].options.outDir / "convergence.json")["levels"].size(),
              all[i].levels.size())
        << i;
  }
}

TEST(ReferenceCheck, AddsAFinerLevelOnlyWhereItCouldShowOnePercent) {
  // The bound is what the analysis itself would estimate for the middle level if a finer level
  // continued the finest pair's convergence at order 4 (the highest it credits).
  const double h1 = 0.0129, h2 = 0.01, h3 = h2 / kFinerLevelStep, peak = 0.45;
  for (const double d12 : {0.0986, 0.006}) {
    const double best = finerLevelBestRelativeError(h1, h2, d12, peak);
    const double d23 =
        d12 * (std::pow(h2, 4) - std::pow(h3, 4)) / (std::pow(h1, 4) - std::pow(h2, 4));
    ConvergenceResult fourth;
    richardsonEstimate(h1, h2, h3, d12, d23, peak, fourth, EstimateOf::Middle);
    EXPECT_NEAR(fourth.order, 4, 1e-6);
    EXPECT_NEAR(fourth.relativeError, best, 1e-9 * best);
  }
  // hybrid/sphere_down_20N's P1 levels in `tables all` (22% of the peak apart): 12%, no level.
  EXPECT_GT(finerLevelBestRelativeError(h1, h2, 0.0986, peak), 0.12);
  EXPECT_LT(finerLevelBestRelativeError(h1, h2, 0.006, peak), 0.01);
  // A finest pair too close to bound anything, or no peak: a finer level may show anything.
  EXPECT_EQ(finerLevelBestRelativeError(0.0105, h2, 0.0986, peak), 0.0);
  EXPECT_EQ(finerLevelBestRelativeError(h1, h2, 0.0986, 0.0), 0.0);
}

TEST(ReferenceCheck, SaysWhyRichardsonDoesNotApply) {
  const double h0 = 0.01, h1 = 0.0071, h2 = 0.005, peak = 0.01;
  // Differences that grow with refinement: not monotone; the spread bounds the error.
  ConvergenceResult grow;
  richardsonEstimate(h0, h1, h2, 1e-5, 2e-5, peak, grow);
  EXPECT_TRUE(std::isnan(grow.relativeError));
  EXPECT_EQ(grow.reason, "not_monotone");
  EXPECT_NE(grow.message.find("do not shrink monotonically"), std::string::npos) << grow.message;
  EXPECT_NEAR(grow.boundRelative, 2e-3, 1e-12);
  EXPECT_NE(convergenceWarning(grow).find("bounded by the levels' spread, 0.2%"), std::string::npos)
      << convergenceWarning(grow);
  EXPECT_NE(convergenceSummary(grow).find("differ by up to 0.2%"), std::string::npos)
      << convergenceSummary(grow);
  // Levels whose measured sizes are 1.05 apart (the surface bounds the coarse ones): too close.
  ConvergenceResult close;
  richardsonEstimate(h0, h0 / 1.05, h2, 2e-5, 1e-5, peak, close);
  EXPECT_EQ(close.reason, "levels_too_close");
  EXPECT_NE(close.message.find("too close in size to extrapolate (h ratios 1.05 and"),
            std::string::npos)
      << close.message;
  // Its finest pair (1.9 apart) gives a two-level estimate at order 2 with Roache's factor 3.
  const double h1c = h0 / 1.05;
  EXPECT_NEAR(close.errorEstimate, 3 * 1e-5 * h2 * h2 / (h1c * h1c - h2 * h2), 1e-15);
  EXPECT_TRUE(close.converged);
  EXPECT_NE(convergenceSummary(close).find("at most 0.114%"), std::string::npos)
      << convergenceSummary(close);
  ConvergenceResult closeLinear;  // the same levels of linear tets: at order 1
  closeLinear.elementOrder = 1;
  richardsonEstimate(h0, h1c, h2, 2e-5, 1e-5, peak, closeLinear);
  EXPECT_NEAR(closeLinear.errorEstimate, 3 * 1e-5 * h2 / (h1c - h2), 1e-15);
  EXPECT_NE(closeLinear.message.find("at order 1 with Roache's"), std::string::npos)
      << closeLinear.message;
  // Both pairs too close: no estimate.
  ConvergenceResult tooClose;
  richardsonEstimate(h0, h0 / 1.05, h0 / 1.1, 2e-5, 1e-5, peak, tooClose);
  EXPECT_EQ(tooClose.reason, "levels_too_close");
  EXPECT_TRUE(std::isnan(tooClose.relativeError));
  EXPECT_FALSE(tooClose.converged);
  // Identical answers on refinement: nothing to extrapolate.
  ConvergenceResult same;
  richardsonEstimate(h0, h1, h2, 0, 0, peak, same);
  EXPECT_EQ(same.reason, "coincide");
  EXPECT_FALSE(same.converged);
  // A clean second-order study has no reason; the RMS analysis recovers its order as well.
  ConvergenceResult clean;
  const auto sq = [](double h) { return h * h; };
  richardsonEstimate(h0, h1, h2, sq(h0) - sq(h1), sq(h1) - sq(h2), peak, clean);
  EXPECT_EQ(clean.reason, "");
  EXPECT_TRUE(std::isnan(clean.boundRelative));
  richardsonRms(h0, h1, h2, 0.1 * (sq(h0) - sq(h1)), 0.1 * (sq(h1) - sq(h2)), peak, clean);
  EXPECT_NEAR(clean.rmsOrder, 2.0, 1e-6);
  EXPECT_NEAR(clean.rmsRelativeError, 0.1 * sq(h2) / peak, 1e-9);
  EXPECT_TRUE(clean.rmsConverged);
}

/// A small grasp-and-lift scene on the cube with the given models and reference.
json childCaseScene(const json& models, const json& reference) {
  json j = json::parse(R"({
    "name": "child-case",
    "organ": {"mesh": "phantom:cube", "resolution": 0.3,
              "fixed": {"box": [[-1, -1, -1], [1, 1, -0.04]]}},
    "gravity": [0, 0, 0], "dt": 0.01, "duration": 0.1,
    "tools": [{"type": "grasper", "radius": 0.02,
               "trajectory": [{"t": 0, "pos": [0, 0, 0.05], "jaw": "closed"},
                              {"t": 0.1, "pos": [0, 0, 0.06]}]}]
  })");
  j["models"] = models;
  j["reference"] = reference;
  return j;
}

TEST_F(TempDir, TableCaseInAChildSurvivesACrashAndAHangAndResumes) {
  PluginLoader loader({DEFORM_TEST_FIXTURE_PLUGIN_DIR, DEFORM_TABLES_TEST_PLUGIN_DIR});
  CaseOptions o;
  o.cacheDir = fs::path();
  ChildCaseOptions child;
  child.executable = DEFORMBENCH_EXE;
  child.pluginArgs = pluginDirArgs(loader.searchPath());
  child.timeoutS = 5;
  o.child = child;
  const json toy = {{"plugin", "toy"}, {"label", "toy"}, {"params", {{"gain", 0.5}}}};
  const json exact = {{"plugin", "toy"}, {"label", "exact"}, {"params", json::object()}};
  const auto crashy = [](const std::string& mode, const std::string& label) {
    return json{{"plugin", "crashy"}, {"label", label}, {"params", {{"mode", mode}}}};
  };
  const auto run = [&](const json& scene, const std::string& id) {
    return runSceneCase(scene, m_dir / "scenes" / (id + ".json"), m_dir / "runs" / id, loader, o);
  };

  // A model that crashes fails its own run only (each run is isolated in a process of its own,
  // issue 35): its row is failed with the signal, the other runs keep their results.
  const json crashScene = childCaseScene(json::array({crashy("segv", "crash"), toy}), exact);
  const CaseResult crashed = run(crashScene, "crash");
  EXPECT_TRUE(crashed.error.empty()) << crashed.error;
  for (const char* label : {"crash", "toy", "exact"}) {
    const RunRecord* r = crashed.run(label);
    ASSERT_NE(r, nullptr) << label;
    if (std::string(label) == "crash") {
      EXPECT_EQ(r->status, RunStatus::Failed) << label;
      EXPECT_NE(r->message.find("SIGSEGV"), std::string::npos) << r->message;
    } else {
      EXPECT_EQ(r->status, RunStatus::Ok) << label << ": " << r->message;
    }
  }
  // --resume reads the failed case back; --retry-failed runs it again.
  o.child->resume = true;
  EXPECT_TRUE(run(crashScene, "crash").resumed);
  o.child->retryFailed = true;
  EXPECT_FALSE(run(crashScene, "crash").resumed);
  o.child->resume = false;
  o.child->retryFailed = false;

  // A reference that hangs is killed at the limit; the models then run alone and keep their
  // figures (read back from the child's results.json), the reference is failed with the timeout.
  const json hangScene = childCaseScene(json::array({toy}), crashy("hang", "ref"));
  const CaseResult hung = run(hangScene, "hang");
  const RunRecord* ref = hung.run("ref");
  ASSERT_NE(ref, nullptr) << hung.error;
  EXPECT_EQ(ref->status, RunStatus::Failed);
  EXPECT_NE(ref->message.find("timeout"), std::string::npos) << ref->message;
  const RunRecord* model = hung.run("toy");
  ASSERT_NE(model, nullptr);
  EXPECT_EQ(model->status, RunStatus::Ok) << model->message;
  EXPECT_GT(model->stepStats.samples, 0);
  EXPECT_GT(model->stepStats.median, 0.0);
  EXPECT_FALSE(model->error.has_value()) << "no reference: no error";
  EXPECT_GT(hung.organVertices, 0);
  EXPECT_GE(hung.wallS, 5.0);
  EXPECT_FALSE(hung.resumed);

  // --resume: the finished case is read back, not run again; a changed scene is run again.
  o.child->resume = true;
  const CaseResult again = run(hangScene, "hang");
  EXPECT_TRUE(again.resumed);
  ASSERT_NE(again.run("ref"), nullptr);
  EXPECT_EQ(again.run("ref")->message, ref->message);
  EXPECT_EQ(again.run("toy")->stepStats.median, model->stepStats.median);
  json changed = hangScene;
  changed["reference"] = exact;
  const CaseResult rerun = run(changed, "hang");
  EXPECT_FALSE(rerun.resumed);
  ASSERT_NE(rerun.run("toy"), nullptr);
  EXPECT_EQ(rerun.run("toy")->status, RunStatus::Ok);
  ASSERT_TRUE(rerun.run("toy")->error.has_value()) << "against the toy reference";
  EXPECT_EQ(rerun.run("ref"), nullptr);
}

// ------------------------------------------------------------------------------- verification

TEST(Analytic, ElasticaReproducesMattiassonsTipLoadTable) {
  // Mattiasson 1981 (IJNME 17:145), cantilever with a tip load, by elliptic integrals:
  // P L^2 / EI -> tip v / L, u / L, rotation (rad).
  struct Row {
    double load, v, u, angle;
  };
  for (const Row& r : {Row{1, 0.30172, 0.05643, 0.46135}, Row{2, 0.49346, 0.16064, 0.78175},
                       Row{10, 0.81061, 0.55500, 1.43029}}) {
    const ElasticaTip t = elasticaCantilever(2.0, 3.0, 0, r.load * 3.0 / 4.0);
    ASSERT_TRUE(t.converged) << r.load;
    EXPECT_NEAR(t.sag / 2.0, r.v, 1e-5) << r.load;
    EXPECT_NEAR(t.shortening / 2.0, r.u, 1e-5) << r.load;
    EXPECT_NEAR(t.angle, r.angle, 1e-5) << r.load;
  }
}

TEST(Analytic, ElasticaUnderItsOwnWeightTendsToBeamTheoryAndStiffensAtLargeLoads) {
  const double L = 0.1, EI = 1e7 * 1e-8 / 12, q = 1000 * 9.81 * 1e-4;
  const ElasticaTip small = elasticaCantilever(L, EI, q, 0);
  ASSERT_TRUE(small.converged);
  const double eb = q * std::pow(L, 4) / (8 * EI);  // Euler-Bernoulli, q L^4 / 8 EI
  EXPECT_NEAR(small.sag, eb, 1e-3 * eb);
  EXPECT_NEAR(small.angle, q * L * L * L / (6 * EI), 1e-3 * small.angle);
  // Large: sag well below the linear answer, and the tip comes back towards the clamp.
  const ElasticaTip large = elasticaCantilever(L, EI, 3 * EI / (L * L * L), 0);
  ASSERT_TRUE(large.converged);
  EXPECT_LT(large.sag, 0.95 * 3.0 / 8 * L);
  EXPECT_GT(large.sag, 0.25 * L);
  EXPECT_GT(large.shortening, 0.02 * L);
  // Doubling the steps changes nothing the table prints.
  EXPECT_NEAR(elasticaCantilever(L, EI, 3 * EI / (L * L * L), 0, 4000).sag, large.sag, 1e-9 * L);
}

TEST(Analytic, NeoHookeanUniaxialLimits) {
  // Small strain: Young's modulus and Poisson's ratio.
  const UniaxialState s = neoHookeanUniaxialAtStretch(1e4, 0.3, 1 - 1e-5);
  ASSERT_TRUE(s.converged);
  EXPECT_NEAR(s.nominalStress, -1e4 * 1e-5, 1e-3 * 1e4 * 1e-5);
  EXPECT_NEAR((s.lateralStretch - 1) / 1e-5, 0.3, 1e-3);
  // Nearly incompressible: J = 1, b = a^-1/2.
  const UniaxialState inc = neoHookeanUniaxialAtStretch(1e4, 0.4999, 0.8);
  EXPECT_NEAR(inc.lateralStretch, 1 / std::sqrt(0.8), 1e-4);
  // The dead-load solve inverts the stretch solve.
  const UniaxialState d = neoHookeanUniaxialAtNominalStress(5500, 0.3, -1100);
  ASSERT_TRUE(d.converged);
  EXPECT_NEAR(neoHookeanUniaxialAtStretch(5500, 0.3, d.axialStretch).nominalStress, -1100, 1e-6);
  // Under a dead nominal stress of 20% of E the stretch is 0.835, not the linear 0.8.
  EXPECT_GT(d.axialStretch, 1 - 0.2);
  EXPECT_LT(d.axialStretch, 0.85);
}

TEST_F(TempDir, QuickVerificationTableListsEveryRowWithItsValue) {
  // The fixtures only: no reference_fem and no calculix, so nothing is solved and the table
  // says so; the values are the analytic and published ones.
  PluginLoader loader({DEFORM_TEST_FIXTURE_PLUGIN_DIR});
  TablesOptions o;
  o.quick = true;
  o.outDir = m_dir / "out";
  o.cases.cacheDir = fs::path();
  const auto tables = buildTables({"verification"}, loader, o, nullptr);
  ASSERT_EQ(tables.size(), 1u);
  const json doc = readJson(o.outDir / "verification.json");
  ASSERT_EQ(doc["rows"].size(), 5u);
  std::vector<std::string> keys;
  for (const auto& c : doc["columns"]) keys.push_back(c["key"]);
  for (const char* k : {"reference_fem_mm", "calculix_mm", "value_mm", "error_pct",
                        "reference_fem_s", "calculix_s", "status"})
    EXPECT_NE(std::find(keys.begin(), keys.end(), k), keys.end()) << k;
  const auto& rows = doc["rows"];
  EXPECT_NEAR(rows[0]["value_mm"].get<double>(),
              1e3 * cantileverSag(1e7, 0.3, 1000, 9.81, 0.1, 0.01), 1e-9);
  EXPECT_NEAR(rows[1]["value_mm"].get<double>(), 30.0, 5.0) << "elastica, q L^3 / EI = 3";
  EXPECT_NEAR(rows[2]["value_mm"].get<double>(), 8.235, 0.01) << "the cube's middle";
  EXPECT_EQ(rows[3]["value_mm"].get<double>(), 14.74);
  EXPECT_NEAR(rows[4]["value_mm"].get<double>(), 6.89, 0.01);
  for (size_t i : {1u, 3u, 4u}) EXPECT_EQ(rows[i]["status"], "skipped (--quick)") << rows[i].dump();
  for (size_t i : {0u, 2u}) {
    const std::string status = rows[i]["status"];
    EXPECT_NE(status.find("missing plugin reference_fem"), std::string::npos) << status;
    EXPECT_TRUE(rows[i]["reference_fem_mm"].is_null());
    EXPECT_NE(rows[i]["note"].get<std::string>().find("CalculiX: not available"),
              std::string::npos);
    EXPECT_TRUE(fs::exists(o.outDir / rows[i]["scene"].get<std::string>()));
  }
}

// ------------------------------------------------------------------------------ truth-cube

TEST(TruthCube, TheShippedDataReadsWithItsLevelsAndFiguresRegisterRigidShifts) {
  const tables::TruthCubeData d = tables::readTruthCubeData(
      std::string(DEFORM_SOURCE_DIR) + "/data/truth-cube/uniaxial_positions.csv");
  ASSERT_EQ(d.beads.size(), 343u);
  ASSERT_EQ(d.strains.size(), 2u);
  EXPECT_DOUBLE_EQ(d.strains[0], 0.05);
  EXPECT_DOUBLE_EQ(d.strains[1], 0.125);
  const MatX3 rest = tables::truthCubeSceneFrame(d, 0);
  // Scene frame: z up (the bottom layer k = 1 lowest, 10 mm above the base at z = -0.04).
  double bottom = 0, top = 0;
  for (size_t i = 0; i < d.beads.size(); ++i) {
    if (d.beads[i].ijk[2] == 1) bottom += rest(Eigen::Index(i), 2) / 49;
    if (d.beads[i].ijk[2] == 7) top += rest(Eigen::Index(i), 2) / 49;
  }
  EXPECT_NEAR(bottom, -0.03, 1e-9);
  EXPECT_GT(top, 0.025);
  EXPECT_LT(top, 0.035);
  for (int level : {1, 2}) {
    const MatX3 scan = tables::truthCubeSceneFrame(d, level);
    // The measured RMS bead displacements the issue quotes: 2.98 and 6.83 mm.
    const tables::TruthCubeFigures exact = tables::truthCubeFigures(d, rest, scan, level, false);
    EXPECT_NEAR(exact.measuredRms, level == 1 ? 2.977e-3 : 6.832e-3, 2e-6);
    EXPECT_NEAR(exact.rms, 0, 1e-15);
    EXPECT_NEAR(exact.bulge, exact.measuredBulge, 1e-15);
    // A model that matches the beads up to a rigid shift: no error after either registration.
    const MatX3 shifted = scan.rowwise() + Eigen::RowVector3d(0.001, -0.002, 0.0005);
    EXPECT_NEAR(tables::truthCubeFigures(d, rest, shifted, level, false).rms, 0, 1e-15);
    EXPECT_NEAR(tables::truthCubeFigures(d, rest, shifted, level, true).rms, 0, 1e-15);
    // A model that does not move: its error is the measured displacement less its mean.
    const tables::TruthCubeFigures still = tables::truthCubeFigures(d, rest, rest, level, false);
    EXPECT_GT(still.rms, 0.5 * exact.measuredRms);
    EXPECT_LT(still.rms, exact.measuredRms);
    EXPECT_EQ(still.layerRms.size(), 7u);
    EXPECT_GT(still.measuredBulge, 0) << "the beads' outer columns bulge out";
  }
}

TEST_F(TempDir, TruthCubeDataErrorsNameTheFileAndLine) {
  const fs::path f = m_dir / "beads.csv";
  std::ofstream(f)
      << "Truth Cube\nno strain,,,5% strain,,\ni,j,k,x0,y0,z0,x1,y1,z1\n1,1,1,0,0,0,1\n";
  try {
    tables::readTruthCubeData(f.string());
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.place(), "line 4") << e.what();
    EXPECT_NE(std::string(e.what()).find("expected 9 numbers"), std::string::npos) << e.what();
  }
  std::ofstream(f) << "x\nno strain,,,five,,\ni,j,k,x0,y0,z0,x1,y1,z1\n";
  EXPECT_THROW(tables::readTruthCubeData(f.string()), InputError);
}

TEST_F(TempDir, QuickTruthCubeTableWithoutTheSolversSaysWhy) {
  PluginLoader loader({DEFORM_TEST_FIXTURE_PLUGIN_DIR});
  TablesOptions o;
  o.quick = true;
  o.outDir = m_dir / "out";
  o.cases.cacheDir = fs::path();
  setenv("DEFORM_CALIBRATIONS_DIR", m_dir.c_str(), 1);  // no shipped calibration: no twin
  buildTables({"truth-cube"}, loader, o, nullptr);
  unsetenv("DEFORM_CALIBRATIONS_DIR");
  const json doc = readJson(o.outDir / "truth-cube.json");
  // reference_fem (two volumetric terms) at 2 levels x 2 registrations, one row per other model
  // (the Bullet peers included).
  ASSERT_EQ(doc["rows"].size(), 8u + 8u);
  for (const auto& row : doc["rows"]) {
    for (const char* k : {"model", "level", "rms_error_m", "max_error_m", "measured_rms_m",
                          "registration", "calibrated", "contact", "ms_per_step"})
      EXPECT_TRUE(row.contains(k)) << k << " in " << row.dump();
    EXPECT_EQ(row["contact"], "bonded");
    EXPECT_TRUE(row["rms_error_m"].is_null());
    EXPECT_NE(row["status"].get<std::string>().find("missing plugin"), std::string::npos)
        << row.dump();
  }
  EXPECT_EQ(doc["rows"][0]["registration"], "translation");
  EXPECT_EQ(doc["rows"][4]["registration"], "bottom_layer");
  // The generated scene parses and holds the plate and the 343 markers.
  const Scene s = parseSceneFile((o.outDir / "scenes/truth-cube/cube.json").string());
  ASSERT_EQ(s.plates.size(), 1u);
  EXPECT_EQ(s.markers.points.rows(), 343);
  EXPECT_EQ(s.markers.measured.size(), 2u);
  EXPECT_NEAR(s.plates[0].trajectory.back().pos.z(), -0.010, 1e-12);
}

// A model that meshes its own tets (bullet_deformable) is left out of --quick with a row saying
// so, and settles at its own defaults in the full table.
TEST_F(TempDir, TruthCubeQuickLeavesOutASelfMeshingModelAndSaysSo) {
  PluginLoader probe({DEFORM_BUILD_PLUGIN_DIR});
  const auto found = probe.discover();
  if (std::find(found.begin(), found.end(), std::string("bullet_deformable")) == found.end())
    GTEST_SKIP() << "bullet_deformable is not built";
  PluginLoader loader({pluginSubset(m_dir / "plugins", {"bullet_deformable"}).string()});
  const TruthCubeModel quick = truthCubeModel(loader, "bullet_deformable", true);
  EXPECT_NE(quick.problem.find("left out by --quick"), std::string::npos) << quick.problem;
  const TruthCubeModel full = truthCubeModel(loader, "bullet_deformable", false);
  EXPECT_EQ(full.problem, "");
  EXPECT_TRUE(full.dynamic);
  EXPECT_TRUE(full.entry["params"].empty()) << full.entry.dump();
}

TEST_F(TempDir, TruthCubeRunsADynamicModelOnItsVolumeNetworkInASettlingScenePerLevel) {
  PluginLoader probe({DEFORM_BUILD_PLUGIN_DIR});
  const auto found = probe.discover();
  if (std::find(found.begin(), found.end(), std::string("pbd")) == found.end())
    GTEST_SKIP() << "pbd is not built";
  PluginLoader loader({pluginSubset(m_dir / "plugins", {"pbd"}).string()});
  TablesOptions o;
  o.quick = true;
  // No shipped calibration (an empty folder): no twin.
  fs::create_directories(m_dir / "calibrations" / "truth-cube");
  setenv("DEFORM_CALIBRATIONS_DIR", (m_dir / "calibrations").c_str(), 1);
  const tables::TableDef t = tables::truthCube(o, loader);
  ASSERT_EQ(t.cases.size(), 3u) << "the quasi-static scene and one settling scene per level";
  EXPECT_EQ(t.cases[1].id, "truth-cube/dynamic_1");
  const Scene s = parseScene(json::parse(t.cases[2].scene.dump()), "dynamic_2.json");
  EXPECT_TRUE(s.compareAtEquilibrium);
  EXPECT_EQ(s.dt, 1e-3);
  ASSERT_EQ(s.models.size(), 1u);
  EXPECT_EQ(s.models[0].plugin, "pbd");
  EXPECT_EQ(s.models[0].params["network"], "volume");
  EXPECT_NEAR(s.plates[0].trajectory.back().pos.z(), -0.010, 1e-12);
  EXPECT_EQ(s.markers.points.rows(), 343);
  EXPECT_EQ(s.plates[0].contact, PlateContact::Bonded);
  // --contact sliding: the same scenes with a sliding plate, as cases of their own.
  o.truthCubeContact = "sliding";
  const tables::TableDef ts = tables::truthCube(o, loader);
  ASSERT_EQ(ts.cases.size(), 3u);
  EXPECT_EQ(ts.cases[0].id, "truth-cube/cube_sliding");
  EXPECT_EQ(ts.cases[1].id, "truth-cube/dynamic_1_sliding");
  for (const auto& c : ts.cases) {
    const Scene sl = parseScene(json::parse(c.scene.dump()), "sliding.json");
    ASSERT_EQ(sl.plates.size(), 1u);
    EXPECT_EQ(sl.plates[0].contact, PlateContact::Sliding) << c.id;
    EXPECT_EQ(sl.plates[0].normal, Vec3(0, 0, -1)) << c.id;
  }
  o.truthCubeContact = "glued";
  EXPECT_THROW(tables::truthCube(o, loader), InputError);

  // A shipped calibration of pbd on the Truth Cube that fits the organ's nu: its twin runs in
  // scenes of its own (the organ's material replaced), one per level; its rows say which level
  // it was trained on. A twin of the parameters alone runs beside its model.
  o.truthCubeContact = "bonded";
  const auto ship = [&](const json& extra) {
    json c = {{"format", "deformbench-calibration/1"},
              {"plugin", "pbd"},
              {"model", "pbd"},
              {"params", json::object()},
              {"organs", {"phantom:cube, resolution 1, scale 0.8"}},
              {"truth_cube", {{"level", 1}, {"strain", 0.05}, {"contact", "bonded"}}}};
    c.update(extra);
    std::ofstream(m_dir / "calibrations" / "truth-cube" / "pbd.json") << c.dump();
  };
  ship({{"material", {{"poisson", 0.45}}}});
  const tables::TableDef quick = tables::truthCube(o, loader);
  EXPECT_EQ(quick.cases.size(), 3u) << "--quick leaves the material's twin out";
  EXPECT_NE(json(quick.notes).dump().find("leaves out the twins whose fit holds the organ's nu"),
            std::string::npos);
  o.quick = false;
  const tables::TableDef tm = tables::truthCube(o, loader);
  ASSERT_EQ(tm.cases.size(), 5u);
  EXPECT_EQ(tm.cases[3].id, "truth-cube/dynamic_1_cal_pbd");
  const Scene twin = parseScene(json::parse(tm.cases[4].scene.dump()), "twin.json");
  ASSERT_EQ(twin.models.size(), 1u);
  EXPECT_EQ(twin.models[0].label, "pbd+cal");
  EXPECT_EQ(twin.organ.material.poisson, 0.45);
  EXPECT_EQ(twin.models[0].params["network"], "volume");
  ship({{"params", {{"damping", 3.0}}}});
  const tables::TableDef tp = tables::truthCube(o, loader);
  ASSERT_EQ(tp.cases.size(), 3u) << "the twin of the parameters runs beside its model";
  const Scene beside = parseScene(json::parse(tp.cases[1].scene.dump()), "beside.json");
  ASSERT_EQ(beside.models.size(), 2u);
  EXPECT_EQ(beside.models[1].label, "pbd+cal");
  EXPECT_EQ(beside.models[1].params["damping"], 3.0);
  EXPECT_EQ(beside.organ.material.poisson, 0.499);
  unsetenv("DEFORM_CALIBRATIONS_DIR");
}

TEST(Tables, UnknownTableIsAnInputError) {
  PluginLoader loader({DEFORM_TEST_FIXTURE_PLUGIN_DIR});
  TablesOptions o;
  o.outDir = fs::temp_directory_path() / "deform_tables_unknown";
  EXPECT_THROW(buildTables({"nonsense"}, loader, o, nullptr), InputError);
  EXPECT_EQ(tableNames().size(), 8u);
}

// ---------------------------------------------------------------------------------- stability

TEST_F(TempDir, StabilityRecordsACrashAndGoesOnAndResumeSkipsFinishedCases) {
  PluginLoader loader({DEFORM_TEST_FIXTURE_PLUGIN_DIR, DEFORM_TABLES_TEST_PLUGIN_DIR});
  StabilityOptions o;
  o.quick = true;
  o.outDir = m_dir / "stab";
  o.models = {"crashy", "toy"};
  o.cases = {"E1000_dt0.001", "pull"};
  o.executable = DEFORMBENCH_EXE;
  o.pluginDirs = {DEFORM_TEST_FIXTURE_PLUGIN_DIR, DEFORM_TABLES_TEST_PLUGIN_DIR};
  o.cacheDir = (m_dir / "cache").string();
  o.timeoutS = 30;
  const auto records = runStability(loader, o, nullptr);
  ASSERT_EQ(records.size(), 4u);
  std::map<std::pair<std::string, std::string>, StabilityRecord> by;
  for (const auto& r : records) by[{r.model, r.caseId}] = r;
  for (const char* c : {"E1000_dt0.001", "pull"}) {
    const StabilityRecord& r = by.at({"crashy", c});
    EXPECT_EQ(r.status, "failed") << c;
    EXPECT_NE(r.message.find("SIGSEGV"), std::string::npos) << r.message;
  }
  EXPECT_EQ(by.at({"toy", "pull"}).status, "stable") << by.at({"toy", "pull"}).message;
  EXPECT_EQ(by.at({"toy", "E1000_dt0.001"}).status, "unsupported")
      << "the toy has no point_force capability";
  for (const char* ext : {".md", ".csv", ".json"})
    EXPECT_TRUE(fs::exists(o.outDir / (std::string("stability") + ext)));
  const json table = readJson(o.outDir / "stability.json");
  EXPECT_EQ(table["rows"].size(), 4u);

  // --resume: nothing finished is run again; a removed case is.
  const fs::path kept = o.outDir / "cases" / "toy" / "pull.json";
  const fs::path removed = o.outDir / "cases" / "crashy" / "pull.json";
  const auto keptTime = fs::last_write_time(kept);
  fs::remove(removed);
  fs::remove_all(o.outDir / "runs" / "toy");
  o.resume = true;
  const auto again = runStability(loader, o, nullptr);
  ASSERT_EQ(again.size(), 4u);
  int resumed = 0;
  for (const auto& r : again) {
    resumed += r.resumed;
    if (r.model == "crashy" && r.caseId == "pull") {
      EXPECT_FALSE(r.resumed);
      EXPECT_EQ(r.status, "failed");
    }
  }
  EXPECT_EQ(resumed, 3);
  EXPECT_EQ(fs::last_write_time(kept), keptTime);
  EXPECT_FALSE(fs::exists(o.outDir / "runs" / "toy")) << "toy cases were not rerun";
  EXPECT_TRUE(fs::exists(removed));

  // Issue 35: --retry-failed runs the failed cases again and keeps the others.
  o.retryFailed = true;
  for (const auto& r : runStability(loader, o, nullptr))
    EXPECT_EQ(r.resumed, r.model == "toy") << r.model << " " << r.caseId << " " << r.status;
  o.retryFailed = false;
  // A case keyed by its scene's hash: the full set's case of the same id (another resolution and
  // duration) is not the quick one, so nothing is reused.
  EXPECT_FALSE(readJson(kept).value("scene_sha256", std::string()).empty());
  o.quick = false;
  for (const auto& r : runStability(loader, o, nullptr))
    EXPECT_FALSE(r.resumed) << r.model << " " << r.caseId;
  EXPECT_TRUE(fs::exists(o.outDir / "runs" / "toy" / "pull")) << "the toy's pull ran again";
}

TEST(Stability, ClassifiesTimeoutsSignalsAndExitCodes) {
  const fs::path none = "/nonexistent/results.json";
  const StabilityRecord t = classifyStabilityRun(0, true, 5, none, "");
  EXPECT_EQ(t.status, "failed");
  EXPECT_NE(t.message.find("timeout"), std::string::npos);
  const StabilityRecord bad = classifyStabilityRun(2 << 8, false, 5, none, "bad scene");
  EXPECT_EQ(bad.status, "failed");
  EXPECT_NE(bad.message.find("exit code 2: bad scene"), std::string::npos) << bad.message;
  EXPECT_FALSE(stabilityCases(true).empty());
  EXPECT_GT(stabilityCases(false).size(), stabilityCases(true).size());
}

// -------------------------------------------------------------------------------------- bench

json benchDoc(std::vector<std::tuple<std::string, double, double, double>> cases) {
  json j = {{"format", "deformbench-bench/1"}, {"cases", json::array()}};
  for (const auto& [id, med, lo, hi] : cases)
    j["cases"].push_back({{"id", id}, {"ms_median", med}, {"ms_min", lo}, {"ms_max", hi}});
  return j;
}

TEST(Bench, CompareJudgesEachCaseByItsRatioToPbdInTheSameRun) {
  const json oldDoc = benchDoc({{"pbd/s", 1, 0.99, 1.01},
                                {"a/s", 10, 9.9, 10.1},
                                {"b/s", 10, 9.9, 10.1},
                                {"c/s", 10, 9.9, 10.1},
                                {"d/s", 10, 7, 13},
                                {"gone/s", 1, 1, 1}});
  // The new machine runs everything 2x slower: PBD too. Only a's ratio to PBD grew.
  const json newDoc = benchDoc({{"pbd/s", 2, 1.98, 2.02},
                                {"a/s", 28, 27.8, 28.2},  // 40% slower than PBD's 2x, tight
                                {"b/s", 22, 21.8, 22.2},  // 10%: under the threshold
                                {"c/s", 12, 11.9, 12.1},  // faster against PBD
                                {"d/s", 28, 22, 34},      // 40% but within the noise (60%)
                                {"new/s", 2, 2, 2}});
  const BenchComparison c = compareBench(oldDoc, newDoc, 0.25);
  EXPECT_FALSE(c.absolute) << "files without cores and load are not one machine";
  EXPECT_EQ(c.regressions, 1);
  std::map<std::string, std::string> verdict;
  std::map<std::string, double> change;
  for (const auto& r : c.rows) {
    verdict[r.id] = r.verdict;
    change[r.id] = r.xRatio;
  }
  EXPECT_EQ(verdict["a/s"], "SLOWER");
  EXPECT_NEAR(change["a/s"], 1.4, 1e-12);
  EXPECT_EQ(verdict["b/s"], "ok");
  EXPECT_EQ(verdict["c/s"], "faster");
  EXPECT_EQ(verdict["d/s"], "ok");
  EXPECT_EQ(verdict["pbd/s"], "not compared") << "2x slower PBD on another machine says nothing";
  EXPECT_EQ(verdict["new/s"], "new");
  EXPECT_EQ(verdict["gone/s"], "missing");
  EXPECT_EQ(compareBench(oldDoc, newDoc, 0.5).regressions, 0) << "40% is under a 50% threshold";
  // A case whose preset changed between the files is another configuration: not judged.
  json changed = newDoc;
  changed["cases"][1]["params"] = {{"integrator", "symplectic_euler"}};
  const BenchComparison p = compareBench(oldDoc, changed, 0.25);
  EXPECT_EQ(p.regressions, 0);
  EXPECT_EQ(p.rows[1].id, "a/s");
  EXPECT_EQ(p.rows[1].verdict, "params changed");
  EXPECT_NEAR(p.rows[1].xRatio, 1.4, 1e-12) << "its figures are still shown";
  // The same idle machine: absolute times are judged too (PBD's 2x is a regression).
  json a = oldDoc, b = newDoc;
  for (json* d : {&a, &b})
    (*d)["machine"] = {
        {"cpu", "X"}, {"vector_units", "avx512"}, {"cores", 2}, {"load_average", {0.1}}};
  const BenchComparison same = compareBench(a, b, 0.25);
  EXPECT_TRUE(same.absolute) << same.absoluteWhy;
  EXPECT_EQ(same.rows[0].verdict, "SLOWER");
  // The same model name without AVX-512 (or a file that does not say) is another machine.
  for (const json& units : {json("avx2"), json()}) {
    json moved = b;
    if (units.is_null())
      moved["machine"].erase("vector_units");
    else
      moved["machine"]["vector_units"] = units;
    const BenchComparison other = compareBench(a, moved, 0.25);
    EXPECT_FALSE(other.absolute);
    EXPECT_NE(other.absoluteWhy.find("other machines"), std::string::npos) << other.absoluteWhy;
  }
  // Other OpenBLAS kernels (OPENBLAS_CORETYPE) on the same CPU; one file not saying is no bar.
  json kernels = b;
  kernels["machine"]["blas"] = "Haswell";
  EXPECT_TRUE(compareBench(a, kernels, 0.25).absolute);
  a["machine"]["blas"] = "Cooperlake";
  const BenchComparison otherBlas = compareBench(a, kernels, 0.25);
  EXPECT_FALSE(otherBlas.absolute);
  EXPECT_NE(otherBlas.absoluteWhy.find("other OpenBLAS kernels (Cooperlake; Haswell)"),
            std::string::npos)
      << otherBlas.absoluteWhy;
  b["machine"]["load_average"] = {1.5};  // busy: over half its cores
  const BenchComparison busy = compareBench(a, b, 0.25);
  EXPECT_FALSE(busy.absolute);
  EXPECT_NE(busy.absoluteWhy.find("busy machine"), std::string::npos) << busy.absoluteWhy;
}

TEST_F(TempDir, BenchCompareExitCodes) {
  const auto write = [&](const std::string& name, const json& j) {
    std::ofstream(m_dir / name) << j.dump();
    return (m_dir / name).string();
  };
  const std::string a = write("old.json", benchDoc({{"pbd/s", 1, 1, 1}, {"x/s", 10, 9.9, 10.1}}));
  const std::string slow =
      write("slow.json", benchDoc({{"pbd/s", 1, 1, 1}, {"x/s", 20, 19.9, 20.1}}));
  const std::string same =
      write("same.json", benchDoc({{"pbd/s", 1, 1, 1}, {"x/s", 10.5, 10.4, 10.6}}));
  const std::string bad = write("bad.json", json{{"format", "other"}});
  const std::string exe = std::string(DEFORMBENCH_EXE) + " bench --compare ";
  const std::string quiet = " > /dev/null 2>&1";
  EXPECT_EQ(exitCodeOf(exe + a + " " + slow + quiet), 1);
  EXPECT_EQ(exitCodeOf(exe + a + " " + same + quiet), 0);
  EXPECT_EQ(exitCodeOf(exe + a + " " + slow + " --threshold 1.5" + quiet), 0);
  EXPECT_EQ(exitCodeOf(exe + a + " " + bad + quiet), 2);
  EXPECT_THROW(readBenchFile(bad), InputError);
}

// ------------------------------------------------------------------------------------- report

bool matplotlibAvailable() {
  return exitCodeOf(pythonInterpreter() + " -c 'import matplotlib' > /dev/null 2>&1") == 0;
}

TEST_F(TempDir, ReportHasTheSectionsAndPictures) {
  if (scriptsDir().empty()) GTEST_SKIP() << "scripts folder not found";
  // A results folder with a model and a reference (the toy fixture plugin), plus a table and a
  // sweep file beside it.
  const fs::path scene = m_dir / "scene.json";
  std::ofstream(scene) << R"({
    "name": "toy-lift",
    "organ": {"mesh": "phantom:cube", "resolution": 0.3,
              "fixed": {"box": [[-1, -1, -1], [1, 1, -0.04]]}},
    "gravity": [0, 0, 0], "dt": 0.01, "duration": 0.3,
    "tools": [{"type": "grasper", "radius": 0.02,
               "trajectory": [{"t": 0, "pos": [0, 0, 0.05], "jaw": "closed"},
                              {"t": 0.2, "pos": [0, 0, 0.06]}]}],
    "models": [{"plugin": "toy", "params": {"gain": 0.5}}],
    "reference": {"plugin": "toy", "label": "exact", "params": {}}
  })";
  const std::string exe = DEFORMBENCH_EXE;
  const std::string pluginDir = std::string(" --plugin-dir ") + DEFORM_TEST_FIXTURE_PLUGIN_DIR;
  const fs::path out = m_dir / "results";
  ASSERT_EQ(exitCodeOf(exe + pluginDir + " run " + scene.string() + " --no-cache --out " +
                       out.string() + " > /dev/null 2>&1"),
            0);
  Table t;
  t.name = "demo-table";
  t.title = "a demo";
  t.columns = {{"name", "name"}, {"status", "status"}, {"paper_ms", "paper ms"}};
  t.rows = {{{"name", "x"}, {"status", "ok"}, {"paper_ms", 1.5}}};
  writeTable(t, out);
  json sweep = {{"format", "deformbench-sweep/1"},
                {"scene", {{"name", "toy-lift"}}},
                {"reference", "toy"},
                {"haptic_budget_ms", 1.0},
                {"reference_check",
                 {{"summary", "estimated discretisation error 0.5% of the peak <demo>"},
                  {"warning", nullptr}}},
                {"points", json::array()}};
  for (int i = 0; i < 3; ++i)
    sweep["points"].push_back({{"model", "toy"},
                               {"plugin", "toy"},
                               {"label", "toy[" + std::to_string(i) + "]"},
                               {"param", "gain"},
                               {"value", 0.3 * (i + 1)},
                               {"status", "ok"},
                               {"ms_median", 0.1 * (i + 1)},
                               {"ms_p95", 0.2},
                               {"rmse_50", 1e-3 / (i + 1)},
                               {"rmse_all", 5e-4},
                               {"max", 2e-3},
                               {"loss_ratio", 0.1},
                               {"pareto", true}});
  std::ofstream(out / "sweep.json") << sweep.dump();

  // What the viewer draws besides the surfaces: the rest shape and the interaction.
  EXPECT_TRUE(fs::exists(out / "rest_surface.obj"));
  const json res = json::parse(readText(out / "results.json"));
  EXPECT_EQ(res["organ"]["rest_surface"], "rest_surface.obj");
  ASSERT_EQ(res["interaction"]["tools"].size(), 1u);
  EXPECT_EQ(res["interaction"]["tools"][0]["trajectory"].size(), 2u);
  EXPECT_DOUBLE_EQ(res["interaction"]["tools"][0]["radius"].get<double>(), 0.02);
  EXPECT_EQ(res["interaction"]["fixed"]["boxes"].size(), 1u);

  ASSERT_EQ(exitCodeOf(exe + " report " + out.string() + " > /dev/null 2>&1"), 0);
  const std::string html = readText(out / "report.html");
  if (fs::exists("/usr/share/javascript/three/build/three.min.js")) {
    EXPECT_NE(html.find("<section id=\"viewer\">"), std::string::npos);
    EXPECT_NE(html.find("id=\"dbv-data\""), std::string::npos);
    EXPECT_NE(html.find("<a href=\"#viewer\">view</a>"), std::string::npos) << "rows link to it";
  }
  EXPECT_NE(html.find("<section id=\"tables\">"), std::string::npos);
  EXPECT_NE(html.find("id=\"table-demo-table\""), std::string::npos);
  EXPECT_NE(html.find("id=\"table-results\""), std::string::npos);
  EXPECT_NE(html.find("<section id=\"sweep\">"), std::string::npos);
  EXPECT_NE(html.find("toy(gain=0.5)"), std::string::npos);
  // The sweep's yardstick: the reference's own check, escaped.
  EXPECT_NE(html.find("own discretisation error, the yardstick of every floor above: estimated "
                      "discretisation error 0.5% of the peak &lt;demo&gt;."),
            std::string::npos);
  if (!matplotlibAvailable()) GTEST_SKIP() << "matplotlib missing: pictures not checked";
  EXPECT_NE(html.find("<section id=\"organs\">"), std::string::npos);
  size_t images = 0;
  for (size_t at = html.find("data:image/png;base64,"); at != std::string::npos;
       at = html.find("data:image/png;base64,", at + 1))
    ++images;
  EXPECT_GE(images, 2u) << "the sweep plot and the organ picture";
  EXPECT_TRUE(fs::exists(out / "sweep.png"));
}

TEST(Report, NotAFolderIsBadInput) {
  EXPECT_EQ(exitCodeOf(std::string(DEFORMBENCH_EXE) + " report /nonexistent/dir > /dev/null 2>&1"),
            2);
}

// ----------------------------------------------------------------------------------- progress

TEST(Progress, PlainLinesWhenNotATerminal) {
  std::FILE* f = std::tmpfile();
  ASSERT_NE(f, nullptr);
  {
    Progress p(3, "test", f);
    EXPECT_FALSE(p.live());
    p.start("a");
    p.finish("a", "ok");
    p.start("b");
    p.finish("b", "failed");
    EXPECT_EQ(p.done(), 2);
    EXPECT_NE(p.status().find("2/3"), std::string::npos);
    EXPECT_NE(p.status().find("left"), std::string::npos);
  }
  std::rewind(f);
  std::string text;
  char buf[256];
  while (std::fgets(buf, sizeof buf, f)) text += buf;
  std::fclose(f);
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 4) << text;
  EXPECT_EQ(text.find('\r'), std::string::npos);
  EXPECT_NE(text.find("[test 1/3"), std::string::npos) << text;
  EXPECT_NE(text.find("a: ok"), std::string::npos);
  EXPECT_EQ(Progress::formatSeconds(65), "1m05s");
  EXPECT_EQ(Progress::formatSeconds(3.25), "3.2s");
}

// ---------------------------------------------------------------------------------- sweep

TEST(Sweep, ParetoFrontsPerModelAndOverallAndTheAxes) {
  std::vector<SweepPoint> pts(5);
  for (SweepPoint& p : pts) p.model = p.plugin = "a";
  pts[0].status = pts[1].status = pts[2].status = pts[4].status = "ok";
  pts[3].status = "diverged";
  pts[0].msMedian = 1;
  pts[0].rmseNearest = 3;
  pts[1].msMedian = 2;
  pts[1].rmseNearest = 1;
  pts[2].msMedian = 3;
  pts[2].rmseNearest = 2;  // slower and worse than pts[1]
  pts[3].msMedian = 0.1;
  pts[3].rmseNearest = 0.1;  // diverged: not a candidate
  pts[4].model = pts[4].plugin = "b";
  pts[4].msMedian = 5;
  pts[4].rmseNearest = 2.5;  // dominated overall by pts[1], alone (so on the front) in model b
  markPareto(pts);
  EXPECT_TRUE(pts[0].pareto && pts[0].paretoOverall);
  EXPECT_TRUE(pts[1].pareto && pts[1].paretoOverall);
  EXPECT_FALSE(pts[2].pareto || pts[2].paretoOverall);
  EXPECT_FALSE(pts[3].pareto || pts[3].paretoOverall);
  EXPECT_TRUE(pts[4].pareto);
  EXPECT_FALSE(pts[4].paretoOverall);
  // The axes are the ones the model declares, values as JSON of their type; an older plugin's
  // single knob becomes the effort axis.
  ModelInfo info;
  info.knob = {"integrator", {std::string("explicit_euler"), 2LL}, {0.5}};
  EXPECT_EQ(sweepKnob(info, false).values, (std::vector<nlohmann::json>{"explicit_euler", 2}));
  EXPECT_TRUE(sweepKnob(info, true).values.at(0).is_number_float());
  EXPECT_EQ(sweepAxes(info, false).effort.param, "integrator");
  EXPECT_TRUE(sweepAxes(info, false).resolution.param.empty());
  info.resolution = {"elements", {100LL, 300LL, 900LL}, {100LL}};
  info.effort = {"iterations", {5LL, 20LL}, {5LL}};
  EXPECT_EQ(sweepAxes(info, false).resolution.values.size(), 3u);
  EXPECT_EQ(sweepAxes(info, true).effort.param, "iterations");
  EXPECT_TRUE(sweepKnob(ModelInfo{}, false).param.empty());
}

namespace {

/// A model's grid: error = floor + c / (resolution * effort), time = resolution * effort.
std::vector<SweepPoint> gridPoints(double floor, bool withEffort) {
  std::vector<SweepPoint> pts;
  for (const double r : {1.0, 2.0, 4.0, 8.0})
    for (const double e : withEffort ? std::vector<double>{1.0, 4.0} : std::vector<double>{1.0}) {
      SweepPoint p;
      p.model = p.plugin = "m";
      p.status = "ok";
      p.resolutionParam = "elements";
      p.resolution = r;
      if (withEffort) {
        p.effortParam = "iterations";
        p.effort = e;
      }
      p.msMedian = r * e;
      p.rmseNearest = p.rmseAll = floor + 1e-3 / (r * r);
      pts.push_back(p);
    }
  return pts;
}

}  // namespace

// Issue H4 items 1 and 3: slopes along each axis, and the floor where the error stops falling.
TEST(Sweep, SlopesAlongTheAxesAndTheFloor) {
  // No floor: the error halves twice per doubling of resolution (slope -2 in time), effort buys
  // nothing (slope 0 along it), and the error is still falling at the finest point.
  std::vector<SweepModelSummary> s = summariseSweep(gridPoints(0, true));
  ASSERT_EQ(s.size(), 1u);
  EXPECT_NEAR(s[0].rmse50.slopeResolution, -2, 1e-9);
  EXPECT_NEAR(s[0].rmse50.slopeEffort, 0, 1e-9);
  EXPECT_TRUE(s[0].rmse50.floor.known);
  EXPECT_FALSE(s[0].rmse50.floor.reached) << s[0].rmse50.floor.text;
  // Aitken over the front's last three errors (1/4, 1/16, 1/64 mm) extrapolates to 0.
  EXPECT_NEAR(s[0].rmse50.floor.estimateM, 0, 1e-12);
  EXPECT_NE(s[0].rmse50.floor.text.find("still falling along elements"), std::string::npos)
      << s[0].rmse50.floor.text;
  // A floor of 2 mm far above the discretisation error: reached, stated in mm.
  s = summariseSweep(gridPoints(2e-3, false));
  EXPECT_TRUE(s[0].rmse50.floor.reached) << s[0].rmse50.floor.text;
  EXPECT_NEAR(s[0].rmse50.floor.errorM, 2e-3 + 1e-3 / 64, 1e-12);
  EXPECT_NE(s[0].rmse50.floor.text.find("floor 2.02 mm"), std::string::npos)
      << s[0].rmse50.floor.text;
  // The descent along resolution: the error still falls at the finest resolution, so its floor
  // is extrapolated and taken off: the excess falls at slope -2 exactly, where ln(error) alone
  // reads about -0.19.
  const SweepMetricSummary::Descent& d = s[0].rmse50.descent;
  EXPECT_FALSE(d.reached);
  EXPECT_TRUE(d.estimated);
  EXPECT_NEAR(d.floorM, 2e-3, 1e-12);
  EXPECT_NEAR(d.slope, -2, 1e-6) << d.text;
  EXPECT_NEAR(s[0].rmse50.slopeResolution, -0.185, 0.01);
  EXPECT_NE(d.text.find("toward an estimated floor of 2 mm over 4 points"), std::string::npos)
      << d.text;
  // A finest resolution worse than the one before: the descent stops at the most accurate point
  // and is fitted on the error itself, up to it.
  std::vector<SweepPoint> past = gridPoints(0, false);
  past.back().rmseNearest = 1e-3;  // above the 4-element point's 1/16 mm
  s = summariseSweep(past);
  EXPECT_TRUE(s[0].rmse50.descent.reached);
  EXPECT_EQ(s[0].rmse50.descent.points, 3);
  EXPECT_NEAR(s[0].rmse50.descent.slope, -2, 1e-9);
  EXPECT_NEAR(s[0].rmse50.descent.floorM, 1e-3 / 16, 1e-15);
  // A resolution that costs no measurable time: the fall is given, never a slope against time.
  std::vector<SweepPoint> free = gridPoints(0, false);
  for (SweepPoint& p : free) p.msMedian = 1 + 0.01 * p.resolution.get<double>();
  s = summariseSweep(free);
  EXPECT_TRUE(s[0].rmse50.descent.sameCost);
  EXPECT_TRUE(std::isnan(s[0].rmse50.descent.slope));
  EXPECT_NE(s[0].rmse50.descent.text.find("falls from 1 mm to 0.0156 mm"), std::string::npos)
      << s[0].rmse50.descent.text;
  // Also when one point between is slow (noise): the most accurate costs what the coarsest does.
  free[1].msMedian = 1.5;
  EXPECT_TRUE(summariseSweep(free)[0].rmse50.descent.sameCost);
  // With an effort axis the descent runs through the most accurate point: at effort 1 (8 ms),
  // not at the costliest effort.
  s = summariseSweep(gridPoints(0, true));
  EXPECT_NEAR(s[0].rmse50.descent.slope, -2, 1e-6) << s[0].rmse50.descent.text;
  EXPECT_NE(s[0].rmse50.descent.text.find("(1.000 to 8.000 ms)"), std::string::npos)
      << s[0].rmse50.descent.text;
  // One valid point: no floor can be told.
  std::vector<SweepPoint> one = gridPoints(0, false);
  for (size_t i = 1; i < one.size(); ++i) one[i].valid = false;
  s = summariseSweep(one);
  EXPECT_FALSE(s[0].rmse50.floor.known);
  EXPECT_EQ(s[0].validPoints, 1);
}

// Issue 33 item 7 and issue 35 item 16: a row whose errors are against an invalid reference says
// so and carries reference_valid false; a row whose reference failed gives the reason.
TEST(TableKit, ARowAgainstAnInvalidReferenceIsMarkedAndAFailedOneSaysWhy) {
  CaseResult c;
  c.sceneFile = "cases/x.json";
  c.result = BenchmarkResult{};
  RunRecord model, ref;
  model.label = "pbd";
  model.referenceValid = false;
  ref.label = "reference_fem";
  ref.isReference = true;
  ref.valid = false;
  ref.invalidReason = "2 solves did not converge";
  c.result->runs = {model, ref};
  tables::ojson row;
  tables::caseCells(row, c, "pbd", c.run("pbd"), ".", true);
  EXPECT_EQ(row["status"],
            "ok; against an invalid reference (reference: invalid (2 solves did not converge))");
  EXPECT_EQ(row["reference_valid"], false);

  c.result->runs[1].status = RunStatus::Failed;
  c.result->runs[1].message = "init: cannot tetrahedralise";
  EXPECT_EQ(tables::referenceStatus(c), "reference: failed (init: cannot tetrahedralise)");
  c.result->runs[1].status = RunStatus::Ok;
  c.result->runs[1].valid = true;
  EXPECT_EQ(tables::referenceStatus(c), "");
}

}  // namespace
}  // namespace deform::harness
