// Scene parsing: strict validation with the JSON path in every message, defaults, relative mesh
// paths, malformed JSON with line/column, parameter resolution and organ loading.
#include <deform/engine/scene.h>
#include <deform/geometry/mesh_io.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>

#include "../support/temp_dir.h"

namespace deform {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

json minimalScene() {
  return json::parse(R"({"organ": {"mesh": "phantom:cube"}, "models": [{"plugin": "pbd"}]})");
}

json fullScene() {
  return json::parse(R"({
    "name": "liver-lift",
    "organ": {"mesh": "phantom:liver", "scale": 1.0, "resolution": 0.5, "repair": false,
              "material": {"young": 5500, "poisson": 0.3, "density": 1000},
              "fixed": {"box": [[-1, -1, -1], [1, 1, -0.04]], "vertices": [3, 1, 3]}},
    "gravity": [0, 0, -9.81],
    "dt": 0.001,
    "duration": 1.0,
    "tools": [{"type": "grasper", "radius": 0.005,
               "trajectory": [{"t": 0.0, "pos": [0, 0, 0.05], "jaw": "open"},
                              {"t": 0.1, "pos": [0, 0, 0.05], "jaw": "closed"},
                              {"t": 0.6, "pos": [0, 0, 0.07]}]}],
    "loads": [{"type": "point_force", "at": [0, 0, 0.05], "force": [0, 0, 2.0], "start": 0.0, "end": 1.0},
              {"type": "pin_head", "at": [0, 0, 0.05], "stiffness": 200,
               "path": [{"t": 0, "pos": [0, 0, 0.05]}, {"t": 1, "pos": [0, 0, 0.06]}]}],
    "models": [{"plugin": "pbd", "params": {"iterations": 10}},
               {"plugin": "fem_hex", "label": "hex", "params": {"elements": 967}}],
    "reference": {"plugin": "reference_fem", "params": {}},
    "samples": {"nearest": [10, 50]},
    "compare_at": [0.5, 1.0],
    "output": {"surfaces": "every:10"}
  })");
}

/// Parses j, expects an InputError whose message holds the JSON path and the problem.
void expectError(const json& j, const std::string& path, const std::string& problem) {
  try {
    parseScene(j, "scene.json");
    ADD_FAILURE() << "no error; expected " << path << ": " << problem;
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_EQ(e.file(), "scene.json");
    EXPECT_EQ(e.place(), path) << what;
    EXPECT_NE(what.find(problem), std::string::npos) << what;
    EXPECT_NE(what.find("scene.json: " + path + ": "), std::string::npos) << what;
  }
}

TEST(Scene, MinimalSceneGetsDefaults) {
  const Scene s = parseScene(minimalScene(), "dir/my_scene.json");
  EXPECT_EQ(s.name, "my_scene");
  EXPECT_EQ(s.organ.mesh, "phantom:cube");
  EXPECT_DOUBLE_EQ(s.dt, 1e-3);
  EXPECT_DOUBLE_EQ(s.duration, 1.0);
  EXPECT_EQ(s.numSteps(), 1000);
  EXPECT_EQ(s.gravity, Vec3(0, 0, -9.81));
  EXPECT_EQ(s.nearest, (std::vector<int>{10, 50}));
  EXPECT_EQ(s.surfaces, SurfaceOutput::Final);
  ASSERT_EQ(s.models.size(), 1u);
  EXPECT_EQ(s.models[0].plugin, "pbd");
  EXPECT_EQ(s.models[0].model, "pbd");
  EXPECT_EQ(s.models[0].jsonPath, "/models/0");
  EXPECT_TRUE(s.models[0].params.is_object());
  EXPECT_FALSE(s.reference.has_value());
}

TEST(Scene, FullSceneFromDesignParses) {
  const Scene s = parseScene(fullScene(), "scene.json");
  EXPECT_EQ(s.name, "liver-lift");
  EXPECT_DOUBLE_EQ(s.organ.resolution, 0.5);
  EXPECT_DOUBLE_EQ(s.organ.material.young, 5500);
  ASSERT_EQ(s.organ.fixed.boxes.size(), 1u);
  EXPECT_EQ(s.organ.fixed.boxes[0].hi, Vec3(1, 1, -0.04));
  EXPECT_EQ(s.organ.fixed.surfaceVertices, (std::vector<int>{3, 1, 3}));
  ASSERT_EQ(s.tools.size(), 1u);
  ASSERT_EQ(s.tools[0].trajectory.size(), 3u);
  EXPECT_FALSE(s.tools[0].trajectory[0].jawClosed);
  EXPECT_TRUE(s.tools[0].trajectory[1].jawClosed);
  EXPECT_TRUE(s.tools[0].trajectory[2].jawClosed) << "a frame without jaw keeps the previous state";
  ASSERT_EQ(s.loads.size(), 2u);
  EXPECT_EQ(s.loads[0].type, LoadType::PointForce);
  EXPECT_EQ(s.loads[0].force, Vec3(0, 0, 2));
  EXPECT_EQ(s.loads[1].type, LoadType::PinHead);
  EXPECT_DOUBLE_EQ(s.loads[1].stiffness, 200);
  EXPECT_EQ(s.loads[1].path.size(), 2u);
  ASSERT_EQ(s.models.size(), 2u);
  EXPECT_EQ(s.models[1].label, "hex");
  EXPECT_EQ(s.models[1].params["elements"], 967);
  ASSERT_TRUE(s.reference.has_value());
  EXPECT_EQ(s.reference->plugin, "reference_fem");
  EXPECT_EQ(s.reference->jsonPath, "/reference");
  EXPECT_EQ(s.compareAt, (std::vector<Real>{0.5, 1.0}));
  EXPECT_EQ(s.surfaces, SurfaceOutput::Every);
  EXPECT_EQ(s.surfaceEvery, 10);
}

TEST(Scene, FixedBoxesListAndModelName) {
  json j = minimalScene();
  j["organ"]["fixed"] = json::parse(R"({"boxes": [[[0,0,0],[1,1,1]], [[2,2,2],[3,3,3]]]})");
  j["models"][0]["model"] = "pbd_xpbd";
  const Scene s = parseScene(j, "scene.json");
  EXPECT_EQ(s.organ.fixed.boxes.size(), 2u);
  EXPECT_EQ(s.models[0].model, "pbd_xpbd");
}

TEST(Scene, LoadRadiusAndEquilibriumComparison) {
  json j = minimalScene();
  j["loads"] = json::parse(R"([{"type": "point_force", "at": [0, 0, 0.05], "force": [0, 0, 1]},
                               {"type": "point_force", "at": [0, 0, 0.05], "force": [0, 0, 1],
                                "radius": 0.02}])");
  Scene s = parseScene(j, "x.json");
  EXPECT_DOUBLE_EQ(s.loads[0].radius, 0.01) << "the default patch radius";
  EXPECT_DOUBLE_EQ(s.loads[1].radius, 0.02);
  EXPECT_FALSE(s.compareAtEquilibrium);
  j["compare_at"] = "equilibrium";
  s = parseScene(j, "x.json");
  EXPECT_TRUE(s.compareAtEquilibrium);
  EXPECT_TRUE(s.compareAt.empty());
  EXPECT_DOUBLE_EQ(s.settleSpeed, 1e-4);
  EXPECT_EQ(s.settleSteps, 20);
}

TEST(Scene, NumStepsRounds) {
  json j = minimalScene();
  j["dt"] = 0.1;
  j["duration"] = 0.3;  // 0.3 / 0.1 = 2.9999999999999996
  EXPECT_EQ(parseScene(j, "s.json").numSteps(), 3);
}

TEST(SceneErrors, UnknownKeysAnywhere) {
  json j = minimalScene();
  j["colour"] = "red";
  expectError(j, "/colour", "unknown key 'colour'");

  j = minimalScene();
  j["organ"]["material"] = {{"yuong", 1000}};
  expectError(j, "/organ/material/yuong", "unknown key 'yuong' (did you mean 'young'? allowed");

  j = fullScene();
  j["tools"][0]["trajectory"][1]["jaws"] = "open";
  expectError(j, "/tools/0/trajectory/1/jaws", "unknown key 'jaws'");

  j = fullScene();
  j["models"][1]["parameters"] = json::object();
  expectError(j, "/models/1/parameters", "unknown key 'parameters'");

  j = fullScene();
  j["loads"][0]["stiffness"] = 3;  // a pin_head key on a point force
  expectError(j, "/loads/0/stiffness", "unknown key 'stiffness'");

  j = fullScene();
  j["output"]["meshes"] = "all";
  expectError(j, "/output/meshes", "unknown key 'meshes'");

  j = fullScene();
  j["samples"]["farthest"] = {3};
  expectError(j, "/samples/farthest", "unknown key 'farthest' (allowed");  // nothing near

  j = fullScene();
  j["organ"]["fixed"]["sphere"] = 1;
  expectError(j, "/organ/fixed/sphere", "unknown key 'sphere'");

  j = fullScene();
  j["loads"][1]["path"][0]["jaw"] = "open";  // pins have no jaws
  expectError(j, "/loads/1/path/0/jaw", "unknown key 'jaw'");
}

TEST(SceneErrors, WrongTypes) {
  json j = minimalScene();
  j["dt"] = "0.001";
  expectError(j, "/dt", "expected a number, got string");

  j = minimalScene();
  j["organ"]["mesh"] = 3;
  expectError(j, "/organ/mesh", "expected a string, got number");

  j = minimalScene();
  j["gravity"] = {0, -9.81};
  expectError(j, "/gravity", "expected an array of 3 numbers");

  j = fullScene();
  j["tools"][0]["trajectory"][2]["pos"][1] = nullptr;
  expectError(j, "/tools/0/trajectory/2/pos/1", "expected a number, got null");

  j = minimalScene();
  j["organ"]["repair"] = "yes";
  expectError(j, "/organ/repair", "expected true or false, got string");

  j = minimalScene();
  j["models"] = {{"plugin", "pbd"}};
  expectError(j, "/models", "expected an array, got object");

  j = minimalScene();
  j["models"][0]["params"] = json::array();
  expectError(j, "/models/0/params", "expected an object, got array");

  j = minimalScene();
  j["samples"] = {{"nearest", {10, 2.5}}};
  expectError(j, "/samples/nearest/1", "expected an integer, got 2.5");

  j = minimalScene();
  j["organ"] = "phantom:cube";
  expectError(j, "/organ", "expected an object, got string");
}

TEST(SceneErrors, MissingRequiredKeys) {
  json j = minimalScene();
  j.erase("organ");
  expectError(j, "/organ", "required key is missing");
  j = minimalScene();
  j.erase("models");
  expectError(j, "/models", "required key is missing");
  j = minimalScene();
  j["organ"].erase("mesh");
  expectError(j, "/organ/mesh", "required key is missing");
  j = fullScene();
  j["loads"][1].erase("stiffness");
  expectError(j, "/loads/1/stiffness", "required key is missing");
  j = fullScene();
  j["tools"][0]["trajectory"][0].erase("t");
  expectError(j, "/tools/0/trajectory/0/t", "required key is missing");
}

TEST(SceneErrors, OutOfRangeValues) {
  const auto with = [](const std::string& pointer, json value) {
    json j = fullScene();
    j[json::json_pointer(pointer)] = std::move(value);
    return j;
  };
  expectError(with("/dt", 0), "/dt", "must be > 0, got 0");
  expectError(with("/dt", -1e-3), "/dt", "must be > 0, got -0.001");
  expectError(with("/duration", 0), "/duration", "must be > 0");
  expectError(with("/duration", 1e-4), "/duration", "shorter than one time step");
  expectError(with("/organ/material/poisson", 0.5), "/organ/material/poisson",
              "must be in (-1, 0.5), got 0.5");
  expectError(with("/organ/material/poisson", -1), "/organ/material/poisson",
              "must be in (-1, 0.5), got -1");
  expectError(with("/organ/material/young", 0), "/organ/material/young", "must be > 0");
  expectError(with("/organ/material/density", -5), "/organ/material/density", "must be > 0");
  expectError(with("/organ/scale", 0), "/organ/scale", "must be > 0");
  expectError(with("/organ/resolution", -1), "/organ/resolution", "must be > 0");
  expectError(with("/tools/0/radius", 0), "/tools/0/radius", "must be > 0");
  expectError(with("/tools/0/trajectory/1/t", 0.0), "/tools/0/trajectory/1/t",
              "strictly increasing");
  expectError(with("/tools/0/trajectory/0/t", -1), "/tools/0/trajectory/0/t", "must be >= 0");
  expectError(with("/tools/0/trajectory/1/jaw", "half"), "/tools/0/trajectory/1/jaw",
              "expected \"open\" or \"closed\", got \"half\"");
  expectError(with("/tools/0/type", "scalpel"), "/tools/0/type", "\"grasper\" or \"probe\"");
  expectError(with("/tools/0/trajectory", json::array()), "/tools/0/trajectory",
              "at least one keyframe");
  expectError(with("/loads/0/type", "torque"), "/loads/0/type",
              "\"point_force\", \"pin_head\" or \"traction\"");
  expectError(with("/loads/0/end", 0.0), "/loads/0/end", "must be > start");
  expectError(with("/loads/1/stiffness", 0), "/loads/1/stiffness", "must be > 0");
  expectError(with("/organ/fixed/box/1/2", -2), "/organ/fixed/box", "low -1 > high -2");
  expectError(with("/organ/fixed/vertices/1", -1), "/organ/fixed/vertices/1", "must be >= 0");
  expectError(with("/compare_at/1", 1.5), "/compare_at/1", "must be in (0, duration = 1]");
  expectError(with("/compare_at/1", 0.25), "/compare_at/1", "strictly increasing");
  expectError(with("/compare_at", "settled"), "/compare_at", "or \"equilibrium\"");
  expectError(with("/loads/0/radius", 0), "/loads/0/radius", "must be > 0");
  expectError(with("/samples/nearest/0", 0), "/samples/nearest/0", "must be >= 1");
  expectError(with("/output/surfaces", "every:0"), "/output/surfaces", "integer N >= 1");
  expectError(with("/output/surfaces", "every:x"), "/output/surfaces", "integer N >= 1");
  expectError(with("/output/surfaces", "sometimes"), "/output/surfaces",
              "\"final\", \"every:N\" or \"none\"");
  expectError(with("/models", json::array()), "/models", "at least one model");
  expectError(with("/models/0/plugin", "../evil"), "/models/0/plugin", "plugin names are");
  expectError(with("/models/0/label", "hex"), "/models/1/label", "duplicate label \"hex\"");
  expectError(with("/organ/mesh", "phantom:kidney"), "/organ/mesh", "unknown phantom 'kidney'");
  expectError(with("/name", ""), "/name", "must not be empty");
}

TEST(SceneErrors, ResolutionOnlyForPhantoms) {
  json j = minimalScene();
  j["organ"]["mesh"] = "organ.obj";
  j["organ"]["resolution"] = 2;
  expectError(j, "/organ/resolution", "applies only to phantom meshes");
}

class SceneFiles : public ::testing::Test {
 protected:
  void SetUp() override {
    m_dir = deform::testing::freshTestDir(
        "deform_scene_test_" + std::to_string(::testing::UnitTest::GetInstance()->random_seed()) +
        "_");
    fs::create_directories(m_dir / "scenes");
  }
  void TearDown() override { fs::remove_all(m_dir); }
  std::string write(const std::string& rel, const std::string& text) {
    const fs::path p = m_dir / rel;
    std::ofstream(p) << text;
    return p.string();
  }
  fs::path m_dir;
};

TEST_F(SceneFiles, MalformedJsonGivesLineAndColumn) {
  const std::string path = write("scenes/bad.json",
                                 "{\n  \"organ\": {\"mesh\": \"phantom:cube\"},\n"
                                 "  \"dt\": 0.001,,\n  \"models\": []\n}\n");
  try {
    parseSceneFile(path);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), path);
    EXPECT_EQ(e.place(), "line 3, column 15") << e.what();
    EXPECT_NE(std::string(e.what()).find("malformed JSON"), std::string::npos) << e.what();
    EXPECT_EQ(std::string(e.what()).find("[json.exception"), std::string::npos) << e.what();
  }
}

TEST_F(SceneFiles, TruncatedJsonAndMissingFile) {
  const std::string path = write("scenes/cut.json", "{\"organ\": {\"mesh\": \"phan");
  EXPECT_THROW(parseSceneFile(path), InputError);
  EXPECT_THROW(parseSceneFile((m_dir / "nope.json").string()), InputError);
}

TEST_F(SceneFiles, MeshPathIsRelativeToTheSceneFile) {
  const std::string path =
      write("scenes/s.json",
            R"({"organ": {"mesh": "../meshes/organ.obj"}, "models": [{"plugin": "pbd"}]})");
  const Scene s = parseSceneFile(path);
  EXPECT_EQ(fs::path(s.organ.mesh), (m_dir / "meshes/organ.obj").lexically_normal());
  EXPECT_EQ(s.file, path);
  EXPECT_EQ(s.sha256.size(), 64u);
  EXPECT_EQ(s.name, "s");
}

TEST_F(SceneFiles, ShaChangesWithTheBytes) {
  const std::string a = write("scenes/a.json", minimalScene().dump());
  const std::string b = write("scenes/b.json", minimalScene().dump(2));
  EXPECT_NE(parseSceneFile(a).sha256, parseSceneFile(b).sha256);
}

// ---------------------------------------------------------------------------------- params

std::vector<ParamSpec> specs() {
  return {ParamSpec::integer("iterations", 10, 1, 1000, "solver iterations"),
          ParamSpec::real("stiffness", "1", 0.5, 0.0, 1.0, "constraint stiffness"),
          ParamSpec::flag("volume", true, "volume constraints"),
          ParamSpec::choice("solver", "gauss_seidel", {"gauss_seidel", "jacobi"}, "sweep")};
}

void expectParamError(const json& given, const std::string& path, const std::string& problem) {
  try {
    resolveParams(specs(), given, "s.json", "/models/0/params");
    ADD_FAILURE() << "no error; expected " << path;
  } catch (const InputError& e) {
    EXPECT_EQ(e.place(), path) << e.what();
    EXPECT_NE(std::string(e.what()).find(problem), std::string::npos) << e.what();
  }
}

TEST(Params, DefaultsAndGivenValues) {
  const ParamValues v = resolveParams(specs(), json::parse(R"({"iterations": 20, "stiffness": 1})"),
                                      "s.json", "/models/0/params");
  EXPECT_EQ(v.integer("iterations"), 20);
  EXPECT_DOUBLE_EQ(v.real("stiffness"), 1.0);
  EXPECT_TRUE(v.flag("volume"));
  EXPECT_EQ(v.choice("solver"), "gauss_seidel");
  const json j = paramsToJson(v);
  EXPECT_EQ(j["iterations"], 20);
  EXPECT_TRUE(j["iterations"].is_number_integer());
  EXPECT_EQ(j["solver"], "gauss_seidel");
  EXPECT_EQ(j["volume"], true);
  EXPECT_EQ(j.size(), 4u);
}

TEST(Params, Errors) {
  expectParamError({{"iterations", 0}}, "/models/0/params/iterations", "must be >= 1, got 0");
  expectParamError({{"iterations", 2000}}, "/models/0/params/iterations", "must be <= 1000");
  expectParamError({{"iterations", 2.5}}, "/models/0/params/iterations", "expected an integer");
  expectParamError({{"stiffness", "hard"}}, "/models/0/params/stiffness", "expected a number");
  expectParamError({{"volume", 1}}, "/models/0/params/volume", "expected true or false");
  expectParamError({{"solver", "newton"}}, "/models/0/params/solver",
                   "expected one of \"gauss_seidel\", \"jacobi\"");
  expectParamError({{"iteratons", 3}}, "/models/0/params/iteratons",
                   "unknown parameter 'iteratons' (did you mean 'iterations'? declared");
  expectParamError(json::array(), "/models/0/params", "expected an object");
}

TEST(Params, SpecJsonHasOpenRangesAsNull) {
  const json j = paramSpecToJson(ParamSpec::real("young", "Pa", 5500, 0, INFINITY, "E"));
  EXPECT_EQ(j["key"], "young");
  EXPECT_EQ(j["unit"], "Pa");
  EXPECT_EQ(j["type"], "real");
  EXPECT_EQ(j["min"], 0.0);
  EXPECT_TRUE(j["max"].is_null());
  const json c = paramSpecToJson(specs()[3]);
  EXPECT_EQ(c["choices"].size(), 2u);
  EXPECT_EQ(c["default"], "gauss_seidel");
}

// ----------------------------------------------------------------------------------- organ

const char* kTetObj =
    "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 5 5 5\n"
    "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";

TEST_F(SceneFiles, LoadOrganDropsUnreferencedVerticesAndScales) {
  write("tet.obj", kTetObj);
  const std::string path = write("scenes/s.json", R"({"organ": {"mesh": "../tet.obj", "scale": 0.01,
      "fixed": {"vertices": [3]}}, "models": [{"plugin": "pbd"}]})");
  const Scene s = parseSceneFile(path);
  std::vector<std::string> log;
  const Organ o = loadOrgan(s, &log);
  EXPECT_EQ(o.surface.numVertices(), 4);
  EXPECT_EQ(o.surface.numFaces(), 4);
  EXPECT_NEAR(o.surface.V(1, 0), 0.01, 1e-15);
  ASSERT_EQ(log.size(), 1u);
  EXPECT_NE(log[0].find("dropped 1 vert"), std::string::npos) << log[0];
  ASSERT_EQ(o.fixed.surfaceVertices.size(), 1u);
  EXPECT_EQ(o.surface.V.row(o.fixed.surfaceVertices[0]), Vec3(0, 0, 0.01).transpose());
}

TEST_F(SceneFiles, LoadOrganRefusesAnOpenMeshNamingTheFile) {
  write("open.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\n");
  const std::string path = write(
      "scenes/s.json", R"({"organ": {"mesh": "../open.obj"}, "models": [{"plugin": "pbd"}]})");
  try {
    loadOrgan(parseSceneFile(path));
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("open.obj"), std::string::npos) << e.what();
  }
}

TEST_F(SceneFiles, LoadOrganRepairsAnInvertedMeshOnlyWhenAsked) {
  write("inv.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 4 2\nf 1 3 4\nf 2 4 3\n");
  const std::string plain =
      write("scenes/a.json", R"({"organ": {"mesh": "../inv.obj"}, "models": [{"plugin": "pbd"}]})");
  try {
    loadOrgan(parseSceneFile(plain));
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("repair"), std::string::npos) << e.what();
  }
  const std::string repaired =
      write("scenes/b.json",
            R"({"organ": {"mesh": "../inv.obj", "repair": true}, "models": [{"plugin": "pbd"}]})");
  std::vector<std::string> log;
  const Organ o = loadOrgan(parseSceneFile(repaired), &log);
  EXPECT_GT(signedVolume(o.surface.V, o.surface.F), 0);
  EXPECT_FALSE(log.empty());
}

TEST_F(SceneFiles, LoadOrganMissingMeshFile) {
  const std::string path =
      write("scenes/s.json", R"({"organ": {"mesh": "absent.obj"}, "models": [{"plugin": "pbd"}]})");
  try {
    loadOrgan(parseSceneFile(path));
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.place(), "/organ/mesh");
    EXPECT_NE(std::string(e.what()).find("absent.obj"), std::string::npos);
  }
}

TEST_F(SceneFiles, LoadOrganFixedVertexOutOfRange) {
  write("tet.obj", kTetObj);
  const std::string path = write("scenes/s.json", R"({"organ": {"mesh": "../tet.obj",
      "fixed": {"vertices": [0, 9]}}, "models": [{"plugin": "pbd"}]})");
  try {
    loadOrgan(parseSceneFile(path));
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.place(), "/organ/fixed/vertices/1") << e.what();
  }
}

TEST(Organ, PhantomIsValidAndScaled) {
  json j = minimalScene();
  j["organ"]["scale"] = 2.0;
  const Organ a = loadOrgan(parseScene(minimalScene(), "s.json"));
  const Organ b = loadOrgan(parseScene(j, "s.json"));
  ASSERT_GT(a.surface.numVertices(), 0);
  EXPECT_EQ(a.source, "phantom:cube");
  EXPECT_NEAR(boundingBox(b.surface.V).diagonal(), 2 * boundingBox(a.surface.V).diagonal(), 1e-12);
}

TEST(Scene, PlatesAreBondedBoxesWithAnOffsetTrajectory) {
  json j = minimalScene();
  // The phantom cube spans [-0.05, 0.05]^3 (minimalScene's organ).
  j["plates"] =
      json::parse(R"([{"region": {"box": [[-1, -1, 0.049], [1, 1, 1]]}, "contact": "bonded",
                                 "trajectory": [{"t": 0, "offset": [0, 0, 0]},
                                                {"t": 1, "offset": [0, 0, -0.004]}]}])");
  const Scene s = parseScene(j, "scene.json");
  ASSERT_EQ(s.plates.size(), 1u);
  EXPECT_EQ(s.plates[0].contact, PlateContact::Bonded);
  ASSERT_EQ(s.plates[0].trajectory.size(), 2u);
  EXPECT_EQ(s.plates[0].trajectory[1].pos, Vec3(0, 0, -0.004));
  EXPECT_EQ(s.plates[0].region.lo.z(), 0.049);
  EXPECT_NO_THROW(loadOrgan(s));

  json bad = j;
  bad["plates"][0]["contact"] = "glued";
  expectError(bad, "/plates/0/contact", "expected \"bonded\" or \"sliding\"");
  bad = j;
  bad["plates"][0]["trajectory"] = json::array();
  expectError(bad, "/plates/0/trajectory", "needs at least one keyframe");
  bad = j;
  bad["plates"][0]["trajectory"][1]["pos"] = {0, 0, 0};
  expectError(bad, "/plates/0/trajectory/1/pos", "unknown key 'pos'");
  bad = j;
  bad["plates"][0]["trajectory"][1]["t"] = 0;
  expectError(bad, "/plates/0/trajectory/1/t", "strictly increasing");
  bad = j;
  bad["plates"][0].erase("region");
  expectError(bad, "/plates/0/region", "required key is missing");
  // An empty region: one error naming the box, when the organ is loaded.
  bad = j;
  bad["plates"][0]["region"]["box"] = {{-1, -1, 0.2}, {1, 1, 1}};
  try {
    loadOrgan(parseScene(bad, "scene.json"));
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "scene.json");
    EXPECT_EQ(e.place(), "/plates/0/region/box");
    EXPECT_NE(std::string(e.what()).find("hold nothing"), std::string::npos) << e.what();
  }
}

TEST(Scene, SlidingPlatesHaveAnAxisNormalFromTheirTrajectoryOrGiven) {
  json j = minimalScene();
  j["plates"] =
      json::parse(R"([{"region": {"box": [[-1, -1, 0.049], [1, 1, 1]]}, "contact": "sliding",
                                 "trajectory": [{"t": 0, "offset": [0, 0, 0]},
                                                {"t": 1, "offset": [0, 0, -0.004]}]}])");
  Scene s = parseScene(j, "scene.json");
  ASSERT_EQ(s.plates.size(), 1u);
  EXPECT_EQ(s.plates[0].contact, PlateContact::Sliding);
  EXPECT_EQ(s.plates[0].normal, Vec3(0, 0, -1));  // the direction of the largest offset
  json given = j;
  given["plates"][0]["normal"] = {0, 0, 2};
  EXPECT_EQ(parseScene(given, "scene.json").plates[0].normal, Vec3(0, 0, 1));
  json bad = given;
  bad["plates"][0]["contact"] = "bonded";
  expectError(bad, "/plates/0/normal", "only a sliding plate has a normal");
  bad = j;
  bad["plates"][0]["normal"] = {0, 1, 1};
  expectError(bad, "/plates/0/normal", "must lie along x, y or z");
  bad = j;
  bad["plates"][0]["trajectory"][1]["offset"] = {0.001, 0, -0.004};
  expectError(bad, "/plates/0/normal", "the direction of its largest offset");
  bad = j;
  bad["plates"][0]["trajectory"][1]["offset"] = {0, 0, 0};
  expectError(bad, "/plates/0/normal", "never moves needs a \"normal\"");
  bad = j;
  bad["plates"][0]["normal"] = {0, 0, 0};
  expectError(bad, "/plates/0/normal", "non-zero");
}

TEST_F(SceneFiles, MarkersFromAListOrAFileWithMeasuredPositions) {
  json j = minimalScene();
  j["duration"] = 1.0;
  j["markers"] = json::parse(R"({"points": [[0, 0, 0], [0.01, 0, 0]],
                                 "measured": [{"t": 1.0, "points": [[0, 0, -0.001], [0.01, 0, 0]]}]})");
  Scene s = parseScene(j, "scene.json");
  ASSERT_EQ(s.markers.points.rows(), 2);
  EXPECT_EQ(s.markers.points(1, 0), 0.01);
  ASSERT_EQ(s.markers.measured.size(), 1u);
  EXPECT_EQ(s.markers.measured[0].points(0, 2), -0.001);

  // A file beside the scene: comma or space separated, '#' comments.
  {
    std::ofstream f(m_dir / "beads.csv");
    f << "# x, y, z in m\n0, 0, 0\n\n0.01 0.0 0.0\n";
  }
  json jf = minimalScene();
  jf["markers"] = {{"file", "beads.csv"}};
  s = parseScene(jf, (m_dir / "scene.json").string());
  ASSERT_EQ(s.markers.points.rows(), 2);
  EXPECT_EQ(s.markers.points(1, 0), 0.01);
  {
    std::ofstream f(m_dir / "bad.csv");
    f << "0, 0, 0\n1, 2\n";
  }
  jf["markers"] = {{"file", "bad.csv"}};
  try {
    parseScene(jf, (m_dir / "scene.json").string());
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.place(), "line 2") << e.what();
    EXPECT_NE(std::string(e.what()).find("three numbers"), std::string::npos) << e.what();
  }

  json bad = j;
  bad["markers"]["measured"][0]["t"] = 0.5;
  expectError(bad, "/markers/measured/0/t", "compared instants");
  bad = j;
  bad["markers"]["measured"][0]["points"] = {{0, 0, 0}};
  expectError(bad, "/markers/measured/0", "1 measured positions for 2 markers");
  // A scene compared at equilibrium measures its one compared instant, "t": "equilibrium".
  json eq = j;
  eq["compare_at"] = "equilibrium";
  eq["markers"]["measured"][0]["t"] = "equilibrium";
  EXPECT_TRUE(parseScene(eq, "scene.json").markers.measured[0].atEquilibrium);
  bad = eq;
  bad["markers"]["measured"][0]["t"] = 1.0;
  expectError(bad, "/markers/measured/0/t", "one frame at \"t\": \"equilibrium\"");
  bad = eq;
  bad["markers"]["measured"].push_back(eq["markers"]["measured"][0]);
  expectError(bad, "/markers/measured/1/t", "must be the only one");
  bad = j;
  bad["markers"]["measured"][0]["t"] = "equilibrium";
  expectError(bad, "/markers/measured/0/t", "needs \"compare_at\": \"equilibrium\"");
  bad["markers"]["measured"][0]["t"] = "end";
  expectError(bad, "/markers/measured/0/t", "expected a time in s or \"equilibrium\"");
  bad = j;
  bad["markers"]["file"] = "beads.csv";
  expectError(bad, "/markers", "exactly one of");
  bad = j;
  bad["markers"]["points"] = json::array();
  expectError(bad, "/markers/points", "at least one point");
}

}  // namespace
}  // namespace deform

namespace deform {
namespace {

// Every shipped scene (scenes/ and its folders: calibration sets, nearly incompressible variants)
// parses, its organ loads, each grasp closes within its radius of the organ's surface and each
// load point lies on it (within 3 mm), so the scenes exercise what they claim.
TEST(ShippedScenes, ToolsAndLoadsMeetTheOrgan) {
  const fs::path dir = fs::path(DEFORM_SOURCE_DIR) / "scenes";
  int checked = 0;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (entry.path().extension() != ".json") continue;
    SCOPED_TRACE(fs::relative(entry.path(), dir).string());
    const Scene scene = parseSceneFile(entry.path().string());
    if (scene.organ.mesh.rfind("phantom:", 0) != 0 && !fs::exists(scene.organ.mesh)) continue;
    const Organ organ = loadOrgan(scene);
    ++checked;
    EXPECT_GE(scene.models.size(), 1u);
    const MatX3& V = organ.surface.V;
    for (size_t i = 0; i < scene.tools.size(); ++i) {
      const ToolSpec& tool = scene.tools[i];
      for (const KeyFrame& k : tool.trajectory) {
        if (!k.jawClosed) continue;
        const Real d = (V.row(nearestVertex(V, k.pos)).transpose() - k.pos).norm();
        EXPECT_LE(d, tool.radius) << "tool " << i << " closes " << d << " m from the surface";
        break;  // the closing frame
      }
    }
    for (size_t i = 0; i < scene.loads.size(); ++i) {
      const Vec3 at = scene.loads[i].at;
      const Real d = (V.row(nearestVertex(V, at)).transpose() - at).norm();
      EXPECT_LE(d, 0.003) << "load " << i << " is " << d << " m from the surface";
    }
    // The fixed region pins part of the organ, not all of it.
    int fixed = 0;
    for (Eigen::Index v = 0; v < V.rows(); ++v)
      for (const Box& b : organ.fixed.boxes)
        if (b.contains(V.row(v).transpose())) {
          ++fixed;
          break;
        }
    fixed += static_cast<int>(organ.fixed.surfaceVertices.size());
    EXPECT_GT(fixed, 0);
    EXPECT_LT(fixed, V.rows() / 2);
  }
  EXPECT_GE(checked, 20);
}

}  // namespace
}  // namespace deform

namespace deform {
namespace {

TEST(SceneFile, DuplicateKeysAreErrorsWithTheirPath) {
  const fs::path p = fs::temp_directory_path() / "deform_scene_duplicate.json";
  const auto expectDuplicate = [&](const std::string& text, const std::string& place) {
    std::ofstream(p) << text;
    try {
      parseSceneFile(p.string());
      ADD_FAILURE() << "no error for " << text;
    } catch (const InputError& e) {
      EXPECT_EQ(e.place(), place) << e.what();
      EXPECT_NE(std::string(e.what()).find("duplicate key"), std::string::npos) << e.what();
    }
  };
  expectDuplicate(R"({"organ": {"mesh": "phantom:cube"}, "dt": 0.001, "dt": 0.01,
                      "models": [{"plugin": "pbd"}]})",
                  "/dt");
  expectDuplicate(R"({"organ": {"mesh": "phantom:cube"}, "models": [{"plugin": "pbd"},
                      {"plugin": "pbd", "params": {"a": 1, "b": [1, {"c": 2, "c": 3}]}}]})",
                  "/models/1/params/b/1/c");
  std::ofstream(p) << R"({"organ": {"mesh": "phantom:cube"}, "models": [{"plugin": "pbd"},
                         {"plugin": "pbd", "params": {"a": [1, 2], "b": {"a": 1}}}]})";
  EXPECT_NO_THROW(parseSceneFile(p.string())) << "the same key in different objects is fine";
  fs::remove(p);
}

// Issue 35 item 3: a coupling unstable at the scene's dt (ODE's semi-implicit Euler step:
// (k dt^2 + 2 c dt) / m must stay below 4) is refused at load, naming the numbers.
TEST(SceneParse, AnUnstableCouplingIsRefusedNamingTheNumbers) {
  json j = minimalScene();
  j["dt"] = 0.001;
  j["objects"] = json::parse(R"([{"shape": "box", "size": [0.01, 0.01, 0.01], "mass": 0.1,
      "pos": [0, 0, 0.06], "stiffness": 4e5, "damping": 1,
      "trajectory": [{"t": 0, "pos": [0, 0, 0.06]}, {"t": 1, "pos": [0, 0, 0.05]}]}])");
  try {
    parseScene(j, "scenes/box.json");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "scenes/box.json");
    EXPECT_EQ(e.place(), "/objects/0");
    const std::string what = e.what();
    EXPECT_NE(what.find("(k dt^2 + 2 c dt) / m = 4.02 with k 4e+05 N/m, c 1 N s/m, m 0.1 kg"),
              std::string::npos)
        << what;
    EXPECT_NE(what.find("must stay below 4"), std::string::npos) << what;
  }
  j["objects"][0]["stiffness"] = 1e5;  // (0.1 + 0.002) / 0.1 = 1.02: stable
  EXPECT_NO_THROW(parseScene(j, "x.json"));
  j["objects"][0].erase("trajectory");  // a free object has no coupling
  j["objects"][0]["stiffness"] = 1e9;
  EXPECT_NO_THROW(parseScene(j, "x.json"));
  // A grasper moves its jaws too (1.2 x its mass, 0.06 kg): at dt 10 ms 2390 N/m is 3.98, 2410
  // N/m 4.02.
  json g = minimalScene();
  g["dt"] = 0.01;
  g["duration"] = 0.1;
  g["tools"] = json::parse(R"([{"type": "grasper", "dynamics": {"mass": 0.05, "stiffness": 2390,
      "damping": 0}, "trajectory": [{"t": 0, "pos": [0, 0, 0.05], "jaw": "closed"}]}])");
  EXPECT_NO_THROW(parseScene(g, "x.json"));
  g["tools"][0]["dynamics"]["stiffness"] = 2410;
  EXPECT_THROW(parseScene(g, "x.json"), InputError);
}

TEST(Scene, FixedRegionsWithAxesAreRollersAndTheOldFormsStayValid) {
  json j = minimalScene();
  j["organ"]["fixed"] = json::parse(R"([
    {"box": [[-1, -1, -1], [1, 1, -0.04]]},
    {"boxes": [[[-1, -1, -1], [-0.049, 1, 1]], [[-1, -1, -1], [1, -0.049, 1]]], "axes": "xy"},
    {"box": [[-1, -1, 0.049], [1, 1, 1]], "axes": "z"},
    {"vertices": [4]},
    {"box": [[0, 0, 0], [1, 1, 1]], "axes": "yxz"}
  ])");
  const Scene s = parseScene(j, "scene.json");
  const FixedRegion& f = s.organ.fixed;
  ASSERT_EQ(f.boxes.size(), 2u) << "a box holding x, y and z is a clamp";
  ASSERT_EQ(f.rollers.size(), 3u);
  EXPECT_EQ(f.rollers[0].axes, 3);
  EXPECT_EQ(f.rollers[1].axes, 3);
  EXPECT_EQ(f.rollers[2].axes, 4);
  EXPECT_EQ(f.rollers[2].box.lo.z(), 0.049);
  EXPECT_EQ(f.surfaceVertices, std::vector<int>{4});
  // The old single-object form.
  j["organ"]["fixed"] = json::parse(R"({"box": [[-1, -1, -1], [1, 1, -0.04]]})");
  const Scene old = parseScene(j, "scene.json");
  EXPECT_EQ(old.organ.fixed.boxes.size(), 1u);
  EXPECT_TRUE(old.organ.fixed.rollers.empty());
}

TEST(Scene, BadRollersNameTheFileAndThePlace) {
  json j = minimalScene();
  j["organ"]["fixed"] = json::parse(R"({"box": [[-1, -1, -1], [1, 1, 1]], "axes": "w"})");
  expectError(j, "/organ/fixed/axes", "expected letters of \"xyz\"");
  j["organ"]["fixed"] = json::parse(R"([{"box": [[-1, -1, -1], [1, 1, 1]]},
                                        {"box": [[-1, -1, -1], [1, 1, 1]], "axes": "zz"}])");
  expectError(j, "/organ/fixed/1/axes", "axis 'z' given twice");
  j["organ"]["fixed"] = json::parse(R"({"box": [[-1, -1, -1], [1, 1, 1]], "axes": ""})");
  expectError(j, "/organ/fixed/axes", "must name at least one axis");
  j["organ"]["fixed"] = json::parse(R"({"vertices": [1], "axes": "z"})");
  expectError(j, "/organ/fixed/axes", "applies to \"box\" or \"boxes\"");
  j["organ"]["fixed"] = json::parse(R"({"box": [[-1, -1, -1], [1, 1, 1]], "axes": "z",
                                        "vertices": [1]})");
  expectError(j, "/organ/fixed/vertices", "pinned fully");
  j["organ"]["fixed"] = json::parse(R"([{"box": [[-1, -1, -1], [1, 1, 1]], "axis": "z"}])");
  expectError(j, "/organ/fixed/0/axis", "unknown key 'axis' (did you mean 'axes'?");
}

TEST(Scene, TractionLoadsSpreadOverTheRegionsSurface) {
  json j = minimalScene();
  j["loads"] = json::parse(R"([{"type": "traction", "region": {"box": [[-1, -1, 0.049], [1, 1, 1]]},
                                "force": [0, 0, -3], "end": 2}])");
  const Scene s = parseScene(j, "scene.json");
  ASSERT_EQ(s.loads.size(), 1u);
  EXPECT_EQ(s.loads[0].type, LoadType::Traction);
  EXPECT_EQ(s.loads[0].force, Vec3(0, 0, -3));
  EXPECT_EQ(s.loads[0].region.lo.z(), 0.049);
  EXPECT_EQ(s.loads[0].end, 2.0);
  EXPECT_NO_THROW(loadOrgan(s));

  json bad = j;
  bad["loads"][0].erase("region");
  expectError(bad, "/loads/0/region", "required key is missing");
  bad = j;
  bad["loads"][0]["at"] = {0, 0, 0};
  expectError(bad, "/loads/0/at", "unknown key 'at'");
  bad = j;
  bad["loads"][0]["region"] = {{"sphere", 1}};
  expectError(bad, "/loads/0/region/sphere", "unknown key 'sphere'");
  bad = j;
  bad["loads"][0]["type"] = "pressure";
  expectError(bad, "/loads/0/type", "\"traction\"");
  // A region with no whole surface triangle inside: an error naming the box, at organ loading.
  bad = j;
  bad["loads"][0]["region"]["box"] = {{-1, -1, 0.2}, {1, 1, 1}};
  try {
    loadOrgan(parseScene(bad, "scene.json"));
    ADD_FAILURE() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "scene.json");
    EXPECT_EQ(e.place(), "/loads/0/region/box");
    EXPECT_NE(std::string(e.what()).find("no surface triangle"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace deform
