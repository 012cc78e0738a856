#include <deform/engine/plugin_loader.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <optional>

namespace deform {
namespace {

namespace fs = std::filesystem;

// Sets an environment variable for the lifetime of the object.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const char* value) : m_name(name) {
    if (const char* old = std::getenv(name)) m_old = old;
    if (value)
      ::setenv(name, value, 1);
    else
      ::unsetenv(name);
  }
  ~ScopedEnv() {
    if (m_old)
      ::setenv(m_name, m_old->c_str(), 1);
    else
      ::unsetenv(m_name);
  }

 private:
  const char* m_name;
  std::optional<std::string> m_old;
};

bool contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

// A closed, outward-oriented cube of side `side` metres with its lower corner at the origin.
Organ cubeOrgan(Real side) {
  Organ o;
  o.source = "test:cube";
  o.surface.V.resize(8, 3);
  for (int i = 0; i < 8; ++i)
    o.surface.V.row(i) << side * (i & 1), side * ((i >> 1) & 1), side * ((i >> 2) & 1);
  o.surface.F.resize(12, 3);
  o.surface.F << 0, 2, 1, 1, 2, 3, 4, 5, 6, 5, 7, 6, 0, 1, 4, 1, 5, 4, 2, 6, 3, 3, 6, 7, 0, 4, 2, 2,
      4, 6, 1, 3, 5, 3, 7, 5;
  return o;
}

#ifdef DEFORM_FIXTURE_PLUGIN_DIR
const std::string kFixtures = DEFORM_FIXTURE_PLUGIN_DIR;

PluginError loadError(const std::string& plugin, const std::string& model = "") {
  PluginLoader loader({kFixtures});
  try {
    loader.load(plugin, model);
  } catch (const PluginError& e) {
    EXPECT_TRUE(loader.loadedFiles().empty() || !model.empty());
    return e;
  }
  ADD_FAILURE() << "loading '" << plugin << "' did not throw";
  return PluginError(PluginError::Kind::InitFailure, "", "");
}

TEST(PluginLoader, FileNotFoundListsTheFoldersSearched) {
  const PluginError e = loadError("no_such_plugin");
  EXPECT_EQ(e.kind(), PluginError::Kind::FileNotFound);
  EXPECT_EQ(e.file(), "deform_no_such_plugin.so");
  EXPECT_TRUE(contains(e.what(), "plugin 'no_such_plugin' not found in: " + kFixtures)) << e.what();
  // ... and says how to add a folder.
  EXPECT_TRUE(contains(e.what(), "--plugin-dir")) << e.what();
  EXPECT_TRUE(contains(e.what(), "DEFORM_PLUGIN_PATH")) << e.what();

  PluginLoader two({kFixtures, "/nonexistent/plugins"});
  try {
    two.locate("nope");
    FAIL();
  } catch (const PluginError& e2) {
    EXPECT_TRUE(contains(e2.what(), "not found in: " + kFixtures + ", /nonexistent/plugins"))
        << e2.what();
  }
  EXPECT_THROW(two.loadFile(kFixtures + "/deform_absent.so"), PluginError);
}

TEST(PluginLoader, TextFileIsNotASharedObject) {
  const PluginError e = loadError("notso");
  EXPECT_EQ(e.kind(), PluginError::Kind::NotSharedObject);
  EXPECT_EQ(fs::path(e.file()).filename(), "deform_notso.so");
  EXPECT_TRUE(contains(e.what(), "deform_notso.so")) << e.what();
  EXPECT_TRUE(contains(e.what(), "not a shared object")) << e.what();
}

TEST(PluginLoader, MissingRegisterSymbol) {
  const PluginError e = loadError("noregister");
  EXPECT_EQ(e.kind(), PluginError::Kind::MissingSymbol);
  EXPECT_TRUE(contains(e.what(), "deform_noregister.so")) << e.what();
  EXPECT_TRUE(contains(e.what(), "missing symbol deform_register")) << e.what();
}

TEST(PluginLoader, WrongAbiVersionIsRefusedBeforeRegistering) {
  // The fixture's deform_register aborts: reaching it would kill the test.
  const PluginError e = loadError("badabi");
  EXPECT_EQ(e.kind(), PluginError::Kind::AbiMismatch);
  EXPECT_TRUE(contains(e.what(), "deform_badabi.so")) << e.what();
  EXPECT_TRUE(contains(
      e.what(), "ABI version 99, this deformbench expects " + std::to_string(DEFORM_ABI_VERSION)))
      << e.what();
}

TEST(PluginLoader, ThrowingRegisterIsAnInitFailure) {
  const PluginError e = loadError("throws");
  EXPECT_EQ(e.kind(), PluginError::Kind::InitFailure);
  EXPECT_TRUE(contains(e.what(), "deform_throws.so")) << e.what();
  EXPECT_TRUE(contains(e.what(), "fixture failure on purpose")) << e.what();
}

TEST(PluginLoader, RegisteringNothingIsAnInitFailure) {
  const PluginError e = loadError("empty");
  EXPECT_EQ(e.kind(), PluginError::Kind::InitFailure);
  EXPECT_TRUE(contains(e.what(), "registered no model")) << e.what();
}

TEST(PluginLoader, UnknownModelListsTheModelsThePluginHas) {
  const PluginError e = loadError("toy", "toy_soft");
  EXPECT_EQ(e.kind(), PluginError::Kind::InitFailure);
  EXPECT_TRUE(contains(e.what(), "no model 'toy_soft'")) << e.what();
  EXPECT_TRUE(contains(e.what(), "toy, toy_rigid")) << e.what();
}

TEST(PluginLoader, LoadsTheToyOnceAndKeepsItsModels) {
  PluginLoader loader({"/nonexistent", kFixtures});
  EXPECT_EQ(fs::path(loader.locate("toy")).filename(), "deform_toy.so");
  const ModelInfo& toy = loader.load("toy");
  EXPECT_EQ(toy.name, "toy");
  EXPECT_TRUE(toy.has(Capability::Grasp));
  ASSERT_NE(toy.param("gain"), nullptr);
  const ModelInfo& rigid = loader.load("toy", "toy_rigid");
  EXPECT_EQ(rigid.name, "toy_rigid");
  // Same file again, by name and by path: the same registrations, one handle.
  EXPECT_EQ(&loader.load("toy"), &toy);
  const auto& models = loader.loadFile(kFixtures + "/./deform_toy.so");
  EXPECT_EQ(&models[0], &toy);
  EXPECT_EQ(models.size(), 2u);
  ASSERT_EQ(loader.loadedFiles().size(), 1u);
  EXPECT_EQ(loader.loadedFiles()[0], fs::canonical(kFixtures + "/deform_toy.so").string());
  // A failure in between changes nothing that was loaded.
  EXPECT_THROW(loader.load("notso"), PluginError);
  EXPECT_EQ(loader.loadedFiles().size(), 1u);
  EXPECT_EQ(&loader.load("toy", "toy_rigid"), &rigid);
}

TEST(PluginLoader, LibPrefixedFileNameAndPathNames) {
  PluginLoader loader({kFixtures});
  EXPECT_EQ(fs::path(loader.locate("prefixed")).filename(), "libdeform_prefixed.so");
  EXPECT_EQ(loader.load("prefixed").name, "prefixed");
  // A path instead of a name: the default model is named after the file.
  EXPECT_EQ(loader.load(kFixtures + "/deform_toy.so").name, "toy");
}

TEST(PluginLoader, LoadedFactoryBuildsAWorkingModel) {
  PluginLoader loader({kFixtures});
  const ModelInfo& info = loader.load("toy");
  const Organ organ = cubeOrgan(0.1);
  ParamValues params = ParamValues::defaults(info.params);
  params.set("gain", 0.5);
  Cache cache("");
  const ModelSetup setup{organ, params, cache, 0.01, Vec3(0, 0, -9.81)};
  std::unique_ptr<Model> model = info.create();
  model->init(setup);
  StepInput in;
  in.dt = 0.01;
  GraspInput g;
  g.vertices = {7};
  g.targets = organ.surface.V.row(7) + Eigen::RowVector3d(0, 0, 0.02);
  in.grasps.push_back(g);
  ASSERT_EQ(model->step(in), StepStatus::Ok);
  EXPECT_NEAR(model->surface()(0, 2), 0.01, 1e-15);  // half of the 2 cm asked for
  model->reset();
  EXPECT_EQ(model->surface(), organ.surface.V);
  model.reset();  // models go before the loader that owns their code
}

TEST(PluginLoader, DiscoverFindsTheFixturesThroughDeformPluginPath) {
  const std::string path = "/nonexistent/a::" + kFixtures + ":";
  ScopedEnv env("DEFORM_PLUGIN_PATH", path.c_str());
  const std::vector<std::string> dirs = PluginLoader::defaultSearchPath();
  ASSERT_GE(dirs.size(), 3u);
  EXPECT_EQ(dirs[0], "/nonexistent/a");  // empty entries are skipped
  EXPECT_EQ(dirs[1], kFixtures);
  // Then the running copy's own folders (beside the loaded core library, or PREFIX/lib next to
  // PREFIX/bin), and only after them the build tree: an installed copy keeps its own plugins.
  const auto build = std::find(dirs.begin(), dirs.end(), DEFORM_BUILD_PLUGIN_DIR);
  ASSERT_NE(build, dirs.end());
  EXPECT_GE(build - dirs.begin(), 3);
  const std::string own = "/lib/deformbench/plugins";
  for (auto d = dirs.begin() + 2; d != build; ++d)
    EXPECT_TRUE(d->size() > own.size() && d->compare(d->size() - own.size(), own.size(), own) == 0)
        << *d;

  PluginLoader loader;
  EXPECT_EQ(loader.searchPath(), dirs);
  const std::vector<std::string> found = loader.discover();
  for (const char* name : {"badabi", "empty", "noregister", "notso", "prefixed", "throws", "toy"}) {
    EXPECT_NE(std::find(found.begin(), found.end(), name), found.end()) << name;
  }
  EXPECT_TRUE(std::is_sorted(found.begin(), found.end()));
  EXPECT_EQ(std::adjacent_find(found.begin(), found.end()), found.end());
  EXPECT_TRUE(loader.loadedFiles().empty());  // discovering loads nothing
  EXPECT_EQ(loader.load("toy").name, "toy");
}
#endif  // DEFORM_FIXTURE_PLUGIN_DIR

// --- The out-of-tree example plugin (tests/plugin_fixtures/install_test.cmake sets these up).

// Checks what examples/minimal_plugin registers and that its model behaves as its header says:
// under gravity alone each particle settles where its tether balances its weight, m g = k d.
void checkTethered(const ModelInfo& info) {
  EXPECT_EQ(info.name, "tethered");
  EXPECT_TRUE(info.has(Capability::Grasp));
  EXPECT_TRUE(info.has(Capability::PointForce));
  EXPECT_TRUE(info.has(Capability::Gravity));
  ASSERT_NE(info.param("stiffness"), nullptr);
  EXPECT_EQ(info.param("stiffness")->unit, "N/m");
  ASSERT_NE(info.param("damping"), nullptr);

  Organ organ = cubeOrgan(0.1);
  organ.material.density = 1000;
  ParamValues params = ParamValues::defaults(info.params);
  params.set("stiffness", 50.0);
  params.set("damping", 5.0);
  Cache cache("");
  const Vec3 g(0, 0, -9.81);
  const ModelSetup setup{organ, params, cache, 0.01, g};
  auto model = info.create();
  model->init(setup);
  EXPECT_EQ(model->counts().at("nodes"), 8);
  StepInput in;
  in.dt = 0.01;
  in.gravity = g;
  for (int s = 0; s < 1000; ++s) ASSERT_EQ(model->step(in), StepStatus::Ok);
  const Real mass = 1000 * 0.1 * 0.1 * 0.1 / 8;  // kg per particle
  const Real sag = mass * 9.81 / 50.0;           // m
  for (int i = 0; i < 8; ++i) {
    EXPECT_NEAR(model->surface()(i, 2), organ.surface.V(i, 2) - sag, 1e-4 * sag) << i;
    EXPECT_NEAR(model->surface()(i, 0), organ.surface.V(i, 0), 1e-12) << i;
  }
  // A grasped particle is where the grasp puts it.
  model->reset();
  EXPECT_EQ(model->surface(), organ.surface.V);
  GraspInput grasp;
  grasp.vertices = {3};
  grasp.targets = organ.surface.V.row(3) + Eigen::RowVector3d(0.01, 0, 0);
  in.grasps = {grasp};
  model->step(in);
  EXPECT_EQ(model->nodes().row(3), grasp.targets.row(0));
}

TEST(InstalledPlugin, LoadsByPath) {
  const char* file = std::getenv("DEFORM_INSTALLED_PLUGIN");
  if (!file) GTEST_SKIP() << "run by the plugin_sdk_install_export test";
  PluginLoader loader({fs::path(file).parent_path().string()});
  const std::vector<ModelInfo>& models = loader.loadFile(file);
  ASSERT_EQ(models.size(), 1u);
  checkTethered(models[0]);
  EXPECT_EQ(&loader.load("tethered"), &models[0]);
}

TEST(InstalledPlugin, FoundInRelocatedInstall) {
  const char* prefix = std::getenv("DEFORM_INSTALLED_PREFIX");
  const char* file = std::getenv("DEFORM_INSTALLED_PLUGIN");
  if (!prefix || !file) GTEST_SKIP() << "run by the plugin_sdk_install_export test";
  PluginLoader loader;  // default search path only
  const auto found = loader.discover();
  EXPECT_NE(std::find(found.begin(), found.end(), "tethered"), found.end());
  EXPECT_EQ(fs::canonical(loader.locate("tethered")), fs::canonical(file));
  checkTethered(loader.load("tethered"));
}

}  // namespace
}  // namespace deform
