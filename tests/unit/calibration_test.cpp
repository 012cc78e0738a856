// The calibration's optimiser layer (calibration.h) on cheap synthetic objectives, the
// calibration declarations of ParamSpec, and the calibration file / twin helpers. The end-to-end
// runs of `deformbench calibrate` are in tests/calibration. Last, the shipped calibrations.
#include <deform/engine/plugin_loader.h>
#include <deform_harness/calibration.h>
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>

using namespace deform;
using namespace deform::harness;

namespace {

TEST(Calibration, DimensionScalesRoundTrip) {
  const CalibDimension lin{"a", 2, 6, false}, lg{"b", 1e-3, 10, true};
  EXPECT_DOUBLE_EQ(lin.value(0.5), 4);
  EXPECT_NEAR(lg.value(0.5), 0.1, 1e-12);  // the geometric middle
  EXPECT_NEAR(lg.unit(0.1), 0.5, 1e-12);
  EXPECT_DOUBLE_EQ(lin.unit(100), 1);  // clamped into the box
  EXPECT_DOUBLE_EQ(lg.unit(0), 0);
  // A Poisson ratio: equal steps in log(0.5 - nu), 0.3 -> 0.4999 (0.2 -> 1e-4 from 1/2).
  const CalibDimension nu{"nu", 0.3, 0.4999, false, true};
  EXPECT_NEAR(nu.value(0.5), 0.5 - std::sqrt(0.2 * 1e-4), 1e-12);
  EXPECT_NEAR(nu.unit(0.499), std::log(0.2 / 1e-3) / std::log(0.2 / 1e-4), 1e-12);
  EXPECT_NEAR(nu.value(nu.unit(0.49)), 0.49, 1e-12);
  EXPECT_DOUBLE_EQ(nu.unit(0.5), 1);  // clamped into the box
}

TEST(Calibration, HaltonPointsFillTheBox) {
  EXPECT_EQ(haltonPoint(1, 2), (std::vector<double>{0.5, 1.0 / 3}));
  EXPECT_EQ(haltonPoint(2, 2), (std::vector<double>{0.25, 2.0 / 3}));
  for (int i = 1; i < 50; ++i)
    for (double x : haltonPoint(i, 3)) {
      EXPECT_GT(x, 0);
      EXPECT_LT(x, 1);
    }
}

// A fit within 1% of its range (in its scale) of a bound is at that bound; a thickness (a length)
// cannot exceed the organ's smallest extent, a dimensionless ratio is left alone.
TEST(Calibration, AtBoundAndLengthsLimitedByTheOrgan) {
  const std::vector<CalibDimension> dims = {
      {"thickness", 1e-4, 0.3, true}, {"ratio", 0, 1, false}, {"damping", 0.01, 100, true}};
  const auto at = fittedAtBound(dims, {0.3, 0.5, 0.0101});
  EXPECT_EQ(at.size(), 2u);
  EXPECT_EQ(at.at("thickness"), "max");
  EXPECT_EQ(at.at("damping"), "min");
  EXPECT_TRUE(fittedAtBound(dims, {3e-3, 0.02, 1}).empty()) << "2% into the range is inside";

  ModelInfo info;
  info.params = {ParamSpec::real("thickness", "m", 0.01, 1e-6, 10, "membrane thickness"),
                 ParamSpec::real("ratio", "1", 0.1, 0, 10, "a ratio"),
                 ParamSpec::real("damping", "1/s", 1, 0, 1e4, "damping")};
  std::vector<CalibDimension> limited = dims;
  const auto notes = limitLengthsToOrgan(limited, info, 0.05);
  EXPECT_DOUBLE_EQ(limited[0].hi, 0.05);
  EXPECT_DOUBLE_EQ(limited[1].hi, 1);
  EXPECT_DOUBLE_EQ(limited[2].hi, 100);
  ASSERT_EQ(notes.size(), 1u);
  EXPECT_NE(notes.at("thickness").find("smallest extent, 0.05 m"), std::string::npos)
      << notes.at("thickness");
  EXPECT_TRUE(limitLengthsToOrgan(limited, info, 1.0).empty()) << "a bound already inside";
}

// A smooth bowl in the declared scales with its minimum at known parameter values.
double bowl(const std::vector<double>& v) {
  return std::pow(std::log10(v[0] / 3e-3), 2) + 4 * std::pow(v[1] - 0.7, 2);
}

TEST(Calibration, RecoversTheMinimumWithinTheBudget) {
  const std::vector<CalibDimension> dims = {{"thickness", 1e-4, 0.3, true}, {"ratio", 0, 1, false}};
  int calls = 0;
  const BatchObjective f = [&](const std::vector<std::vector<double>>& pts) {
    std::vector<double> out;
    for (const auto& p : pts) out.push_back(bowl(p));
    calls += int(pts.size());
    return out;
  };
  OptimiserOptions o;
  o.budget = 60;
  const OptimiserResult r = minimiseInBox(dims, {0.01, 0.1}, f, o);
  EXPECT_LE(calls, 60);
  EXPECT_EQ(r.evaluations, calls);
  EXPECT_EQ(r.localMethod, "bobyqa");
  EXPECT_NEAR(std::log10(r.best[0] / 3e-3), 0, 0.02);
  EXPECT_NEAR(r.best[1], 0.7, 0.01);
  // Deterministic: the same search again gives the same answer.
  const OptimiserResult again = minimiseInBox(dims, {0.01, 0.1}, f, o);
  EXPECT_EQ(again.best, r.best);
  EXPECT_EQ(again.evaluations, r.evaluations);
}

TEST(Calibration, FailedTrialsAreScoredAndTheSearchGoesOn) {
  // Above 0.5 the "model" diverges: the objective returns the worst value, NaN or infinity.
  const std::vector<CalibDimension> dims = {{"gain", 0.05, 1, false}};
  int failed = 0;
  const BatchObjective f = [&](const std::vector<std::vector<double>>& pts) {
    std::vector<double> out;
    for (const auto& p : pts) {
      if (p[0] > 0.5) {
        ++failed;
        out.push_back(failed % 2 ? NAN : INFINITY);
      } else {
        out.push_back(std::pow(p[0] - 0.3, 2));
      }
    }
    return out;
  };
  OptimiserOptions o;
  o.budget = 30;
  std::vector<double> seen;
  const OptimiserResult r = minimiseInBox(
      dims, {0.9}, f, o, [&](const std::vector<double>&, double v) { seen.push_back(v); });
  EXPECT_GT(failed, 0);
  EXPECT_EQ(r.localMethod, "cobyla");
  EXPECT_FALSE(std::isfinite(seen.front()));  // the start diverged
  EXPECT_NEAR(r.best[0], 0.3, 0.01);
}

TEST(Calibration, BudgetOfOneIsTheStartAlone) {
  const std::vector<CalibDimension> dims = {{"a", 0, 1, false}, {"b", 0, 1, false}};
  int calls = 0;
  const BatchObjective f = [&](const std::vector<std::vector<double>>& pts) {
    calls += int(pts.size());
    return std::vector<double>(pts.size(), 1.0);
  };
  OptimiserOptions o;
  o.budget = 1;
  const OptimiserResult r = minimiseInBox(dims, {0.2, 0.4}, f, o);
  EXPECT_EQ(calls, 1);
  EXPECT_EQ(r.evaluations, 1);
  EXPECT_NEAR(r.best[0], 0.2, 1e-12);
}

TEST(Calibration, DeclarationProblems) {
  const ParamSpec ok = ParamSpec::real("k", "1", 0.5, 0, 1, "").calibrate(0.01, 1, ParamScale::Log);
  EXPECT_EQ(calibrationDeclarationProblem(ok), "");
  EXPECT_TRUE(ok.calibratable);
  EXPECT_NE(calibrationDeclarationProblem(
                ParamSpec::real("k", "1", 0.5, 0, 1, "").calibrate(0, 1, ParamScale::Log)),
            "");
  EXPECT_NE(calibrationDeclarationProblem(
                ParamSpec::real("k", "1", 0.5, 0, 1, "").calibrate(0.1, 2, ParamScale::Linear)),
            "");
  EXPECT_NE(calibrationDeclarationProblem(
                ParamSpec::integer("n", 5, 1, 10, "").calibrate(1, 10, ParamScale::Linear)),
            "");
  EXPECT_EQ(calibrationDeclarationProblem(ParamSpec::real("k", "1", 0.5, 0, 1, "")), "");
}

TEST(Calibration, CalibrationFileAndTwins) {
  const auto dir = std::filesystem::temp_directory_path() / "deform_calibration_test";
  std::filesystem::create_directories(dir);
  const auto file = (dir / "calibration.json").string();
  {
    std::ofstream(file) << R"({"format": "deformbench-calibration/1", "model": "pbd",
      "plugin": "pbd", "metric": "rmse_all", "params": {"thickness": 0.004, "damping": 12}})";
  }
  const CalibrationParams c = readCalibrationFile(file);
  EXPECT_EQ(c.plugin, "pbd");
  EXPECT_EQ(c.params["damping"], 12);
  { std::ofstream(file) << R"({"format": "deformbench-table/1"})"; }
  EXPECT_THROW(readCalibrationFile(file), InputError);

  nlohmann::ordered_json scene = {
      {"models",
       {{{"plugin", "pbd"}, {"label", "pbd"}, {"params", {{"damping", 3}}}},
        {{"plugin", "massspring"}, {"params", nlohmann::ordered_json::object()}}}}};
  const auto added = addCalibratedTwins(scene, {c});
  ASSERT_EQ(added.size(), 1u);
  EXPECT_EQ(added[0].second, "pbd+cal");
  ASSERT_EQ(scene["models"].size(), 3u);
  EXPECT_EQ(scene["models"][1]["label"], "pbd+cal");
  EXPECT_EQ(scene["models"][1]["params"]["thickness"], 0.004);
  EXPECT_EQ(scene["models"][1]["params"]["damping"], 3);  // the scene's value wins

  // Per organ: a calibration fitted on the cube twins the cube's models only.
  {
    std::ofstream(file) << R"({"format": "deformbench-calibration/1", "model": "pbd",
      "plugin": "pbd", "metric": "rmse_50", "params": {"thickness": 0.028},
      "organs": ["phantom:cube, resolution 1"]})";
  }
  const CalibrationParams cube = readCalibrationFile(file);
  ASSERT_EQ(cube.organs.size(), 1u);
  EXPECT_EQ(calibrationOrgan("phantom:cube", 1.0, 1.0), cube.organs[0]);
  const auto twinsOn = [&cube](const std::string& mesh) {
    nlohmann::ordered_json s = {{"organ", {{"mesh", mesh}}},
                                {"models", {{{"plugin", "pbd"}, {"label", "pbd"}}}}};
    return addCalibratedTwins(s, {cube}).size();
  };
  EXPECT_EQ(twinsOn("phantom:cube"), 1u);
  EXPECT_EQ(twinsOn("phantom:liver"), 0u) << "fitted on the cube, not the liver";
  EXPECT_TRUE(calibrationApplies(c, calibrationOrgan("phantom:liver", 1.0, 1.0)))
      << "a file without organs applies to any organ";
  EXPECT_NE(calibrationOrgan("phantom:cube", 0.5, 1.0), cube.organs[0]);
  EXPECT_EQ(calibrationOrgan("mesh.stl", 1.0, 0.001),
            (std::filesystem::current_path() / "mesh.stl").string() + ", scale 0.001");
  {
    std::ofstream(file) << R"({"format": "deformbench-calibration/1", "model": "pbd",
      "plugin": "pbd", "params": {}, "organs": "phantom:cube"})";
  }
  EXPECT_THROW(readCalibrationFile(file), InputError);
  std::filesystem::remove_all(dir);
}

// "held": the other parameters the training ran with. A run with another value of one is named;
// parameters the file does not hold, and a sweep's knob, are not compared.
TEST(Calibration, HeldParametersNameWhatARunChanged) {
  const auto dir = std::filesystem::temp_directory_path() / "deform_calibration_held_test";
  std::filesystem::create_directories(dir);
  const auto file = (dir / "calibration.json").string();
  {
    std::ofstream(file) << R"({"format": "deformbench-calibration/1", "model": "pbd",
      "plugin": "pbd", "params": {"thickness": 0.004},
      "held": {"network": "surface", "iterations": 10}})";
  }
  const CalibrationParams c = readCalibrationFile(file);
  const nlohmann::json same = {{"network", "surface"}, {"iterations", 10}, {"thickness", 0.004}};
  EXPECT_TRUE(calibrationDifferences(c, same).empty());
  EXPECT_EQ(calibrationDifferenceNote(c, same), "");
  nlohmann::json other = same;
  other["network"] = "volume";
  other["iterations"] = 40;
  other["damping"] = 20;  // not held: not compared
  EXPECT_EQ(calibrationDifferences(c, other),
            (std::vector<std::string>{"iterations = 40 (fitted with 10)",
                                      "network = \"volume\" (fitted with \"surface\")"}));
  EXPECT_EQ(calibrationDifferences(c, other, {"iterations"}).size(), 1u);
  EXPECT_EQ(
      calibrationDifferenceNote(c, other, {"iterations"}),
      "calibration " + file +
          " was fitted with other parameters: network = \"volume\" (fitted with \"surface\")");

  // A file without "held" (written before it was recorded) names nothing.
  {
    std::ofstream(file) << R"({"format": "deformbench-calibration/1", "model": "pbd",
      "plugin": "pbd", "params": {"thickness": 0.004}})";
  }
  EXPECT_TRUE(calibrationDifferences(readCalibrationFile(file), other).empty());
  {
    std::ofstream(file) << R"({"format": "deformbench-calibration/1", "model": "pbd",
      "plugin": "pbd", "params": {}, "held": ["network"]})";
  }
  try {
    readCalibrationFile(file);
    ADD_FAILURE() << "a \"held\" that is not an object was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/held"), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

// "at_bound": a fit that ended at a bound of its search says so in every calibrated run's notes
// and in the Truth Cube table's note; a malformed entry is refused by its place.
TEST(Calibration, FitsAtABoundAreNamedWhereTheRunsAreRead) {
  const auto dir = std::filesystem::temp_directory_path() / "deform_calibration_bound_test";
  std::filesystem::create_directories(dir);
  const auto file = (dir / "calibration.json").string();
  {
    std::ofstream(file) << R"({"format": "deformbench-calibration/1", "model": "pbd",
      "plugin": "pbd", "params": {"thickness": 0.06, "damping": 3},
      "material": {"poisson": 0.4999},
      "at_bound": {"thickness": "max", "material.poisson": "max"}})";
  }
  const CalibrationParams c = readCalibrationFile(file);
  EXPECT_EQ(boundWords(c, "thickness"), "at its upper bound");
  EXPECT_EQ(boundWords(c, "damping"), "");
  EXPECT_EQ(calibrationBoundNote(c), "calibration " + file +
                                         ": material.poisson fitted at its upper bound, thickness "
                                         "fitted at its upper bound (the best fit may lie beyond "
                                         "the searched range)");
  {
    std::ofstream(file) << R"({"format": "deformbench-calibration/1", "model": "pbd",
      "plugin": "pbd", "params": {"damping": 3}, "at_bound": {}})";
  }
  EXPECT_EQ(calibrationBoundNote(readCalibrationFile(file)), "");
  {
    std::ofstream(file) << R"({"format": "deformbench-calibration/1", "model": "pbd",
      "plugin": "pbd", "params": {}, "at_bound": {"thickness": "upper"}})";
  }
  try {
    readCalibrationFile(file);
    ADD_FAILURE() << "an \"at_bound\" of another word was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("/at_bound"), std::string::npos) << e.what();
  }
  std::filesystem::remove_all(dir);
}

// The shipped calibrations (calibrations/<organ>/, scripts/ship_calibrations.sh): every phantom
// with a training set ships a fit of every calibratable model built here, made on that organ at
// resolution 1 from exactly the folder's training scenes, validated on its held-out ones, and no
// worse on the training set than the model's defaults.
TEST(ShippedCalibrations, EveryPhantomWithATrainingSetHasEveryCalibratableModel) {
  namespace fs = std::filesystem;
  const fs::path src = DEFORM_SOURCE_DIR;
  deform::PluginLoader loader({DEFORM_BUILD_PLUGIN_DIR});
  std::vector<std::string> calibratable;
  for (const std::string& plugin : loader.discover()) {
    try {
      const ModelInfo& info = loader.load(plugin);
      for (const ParamSpec& p : info.params)
        if (p.calibratable) {
          calibratable.push_back(plugin);
          break;
        }
    } catch (const std::exception&) {
      // a plugin that does not load here (a missing library) has nothing to calibrate
    }
  }
  ASSERT_FALSE(calibratable.empty());
  const auto scenesOf = [&](const fs::path& dir, const std::string& prefix) {
    std::set<std::string> out;
    for (const auto& e : fs::directory_iterator(dir)) {
      const std::string name = e.path().filename().string();
      if (name.rfind(prefix, 0) == 0 && e.path().extension() == ".json")
        out.insert(fs::relative(e.path(), src).string());
    }
    return out;
  };
  int checked = 0;
  for (const std::string organ : {"liver", "gallbladder", "cube"}) {
    const fs::path scenes = src / "scenes" / "calibration" / (organ == "liver" ? "" : organ);
    const std::set<std::string> train = scenesOf(scenes, "train_");
    const std::set<std::string> validate = scenesOf(scenes, "validate_");
    ASSERT_GE(train.size(), 3u) << organ;
    ASSERT_GE(validate.size(), 2u) << organ;
    for (const std::string& plugin : calibratable) {
      SCOPED_TRACE(organ + "/" + plugin);
      const fs::path file = src / "calibrations" / organ / (plugin + ".json");
      ASSERT_TRUE(fs::exists(file)) << "scripts/ship_calibrations.sh --organ " << organ
                                    << " --model " << plugin << " writes it";
      const CalibrationParams c = readCalibrationFile(file.string());
      EXPECT_EQ(c.plugin, plugin);
      EXPECT_EQ(c.organs, std::vector<std::string>{calibrationOrgan("phantom:" + organ, 1, 1)});
      std::ifstream in(file);
      const nlohmann::json doc = nlohmann::json::parse(in);
      std::set<std::string> trained, validated;
      for (const auto& s : doc["train"]["per_scene"]) trained.insert(s["scene"]);
      for (const auto& s : doc["validation"]["per_scene"]) validated.insert(s["scene"]);
      EXPECT_EQ(trained, train) << "the folder's training scenes, paths relative to the checkout";
      EXPECT_EQ(validated, validate);
      ASSERT_TRUE(doc["train"]["before"].is_number() && doc["train"]["after"].is_number())
          << doc["train"].dump();
      EXPECT_LE(doc["train"]["after"].get<double>(), doc["train"]["before"].get<double>());
      ++checked;
    }
  }
  EXPECT_EQ(checked, 3 * static_cast<int>(calibratable.size()));
}

}  // namespace
