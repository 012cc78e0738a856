// What every conformance test program file shares: one plugin loader for the whole program
// (plugins stay loaded until every model is gone), the plugin names for INSTANTIATE_TEST_SUITE_P,
// and one precomputation cache.
#pragma once

#include <deform/cache.h>
#include <deform/plugin_loader.h>

#include <string>
#include <vector>

namespace deform::harness {

inline PluginLoader& conformanceLoader() {
  static PluginLoader* l = new PluginLoader({DEFORM_BUILD_PLUGIN_DIR});
  return *l;
}

/// The plugins found in the build tree; none (the suites are then uninstantiated) when the
/// folder cannot be read.
inline std::vector<std::string> conformancePluginNames() {
  try {
    return PluginLoader({DEFORM_BUILD_PLUGIN_DIR}).discover();
  } catch (const std::exception&) {
    return {};
  }
}

inline Cache& conformanceCache() {
  static Cache c(Cache::defaultDir());
  return c;
}

}  // namespace deform::harness
