// deformbench SDK: finding and loading plugins. A plugin named NAME is the file
// deform_NAME.so (or libdeform_NAME.so) in one of the search folders, in this order:
// $DEFORM_PLUGIN_PATH (colon-separated), the running copy's own plugin folder (beside the loaded
// libdeform_engine.so, or PREFIX/lib/deformbench/plugins next to PREFIX/bin), the build tree, the
// configured install prefix. Only the plugins a scene names are loaded. Each failure is a
// distinct PluginError naming the file.
#pragma once

#include <deform/sdk/error.h>
#include <deform/sdk/registry.h>

#include <memory>
#include <string>
#include <vector>

namespace deform {

class PluginLoader {
 public:
  /// searchPath empty: defaultSearchPath().
  explicit PluginLoader(std::vector<std::string> searchPath = {});
  ~PluginLoader();  // unloads every plugin: destroy all models first
  PluginLoader(const PluginLoader&) = delete;
  PluginLoader& operator=(const PluginLoader&) = delete;

  static std::vector<std::string> defaultSearchPath();
  const std::vector<std::string>& searchPath() const { return m_searchPath; }

  /// Path of the shared object for a plugin name; throws PluginError(FileNotFound).
  std::string locate(const std::string& pluginName) const;

  /// Loads the named plugin (once) and returns the model registered under modelName (default:
  /// the plugin's own name). Throws PluginError.
  const ModelInfo& load(const std::string& pluginName, const std::string& modelName = "");

  /// Loads a shared object by path; returns the models it registered. Throws PluginError.
  const std::vector<ModelInfo>& loadFile(const std::string& path);

  /// Plugin names of every plugin file found in the search path (not loaded), sorted.
  std::vector<std::string> discover() const;

  /// Files loaded so far, in load order.
  std::vector<std::string> loadedFiles() const;

 private:
  struct Handle;
  std::vector<std::string> m_searchPath;
  std::vector<std::unique_ptr<Handle>> m_handles;
};

}  // namespace deform
