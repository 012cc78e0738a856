// What every conformance test program file shares: one plugin loader for the whole program
// (plugins stay loaded until every model is gone), the plugin names for INSTANTIATE_TEST_SUITE_P,
// and one precomputation cache.
#pragma once

#include <deform/engine/plugin_loader.h>
#include <deform/sdk/cache.h>
#include <deform/sdk/mesh.h>

#include <nlohmann/json.hpp>

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

/// The cube phantom (resolution 0.5, soft tissue) held by its bottom fifth, without gravity, at
/// dt 1 ms; b is its bounding box.
inline nlohmann::json cubeScene(const Box& b) {
  const Vec3 m = Vec3::Constant(0.05 * b.diagonal());
  nlohmann::json j;
  j["organ"] = {{"mesh", "phantom:cube"},
                {"resolution", 0.5},
                {"material", {{"young", 5500}, {"poisson", 0.3}, {"density", 1000}}},
                {"fixed",
                 {{"box",
                   {{b.lo.x() - m.x(), b.lo.y() - m.y(), b.lo.z() - m.z()},
                    {b.hi.x() + m.x(), b.hi.y() + m.y(), b.lo.z() + 0.2 * b.size().z()}}}}}};
  j["gravity"] = {0, 0, 0};
  j["dt"] = 1e-3;
  return j;
}

}  // namespace deform::harness
