// Fixtures shared by the test programs: a material, and the build tree's plugins and test cache
// for tests that load models as the harness does (the program defines DEFORM_BUILD_PLUGIN_DIR,
// and DEFORM_BUILD_DIR for the cache). Include as "../support/fixtures.h".
#pragma once

#include <deform/sdk/model.h>

#ifdef DEFORM_BUILD_PLUGIN_DIR
#include <deform/engine/plugin_loader.h>
#endif
#ifdef DEFORM_BUILD_DIR
#include <deform/sdk/cache.h>

#include <filesystem>
#endif

namespace deform::testing {

inline Material material(Real young, Real poisson, Real density = 1000) {
  Material m;
  m.young = young;
  m.poisson = poisson;
  m.density = density;
  return m;
}

#ifdef DEFORM_BUILD_PLUGIN_DIR
/// The build tree's plugins, loaded for the whole program (models may outlive a local loader).
inline PluginLoader& loader() {
  static PluginLoader* l = new PluginLoader({DEFORM_BUILD_PLUGIN_DIR});
  return *l;
}
#endif

#ifdef DEFORM_BUILD_DIR
/// The test programs' cache folder in the build tree.
inline Cache& cache() {
  static Cache c(std::filesystem::path(DEFORM_BUILD_DIR) / "test-cache");
  return c;
}
#endif

}  // namespace deform::testing
