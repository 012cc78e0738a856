#include <deform/engine/plugin_loader.h>
#include <deform/internal/sanitizers.h>
#include <dlfcn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <set>

namespace deform {

namespace fs = std::filesystem;

namespace {

using AbiVersionFn = int (*)();
using RegisterFn = void (*)(Registry&);

// Under AddressSanitizer a loaded plugin is never unmapped: what the libraries it brought in
// still hold (libgomp, through CHOLMOD) would otherwise read as a leak at exit, once
// LeakSanitizer no longer sees the unmapped memory that points to it (clang 14's runtime reported
// 8 bytes of libgomp's; gcc 12's did not).
constexpr int kLoadFlags = RTLD_NOW | RTLD_LOCAL | (DEFORM_ASAN ? RTLD_NODELETE : 0);

std::string join(const std::vector<std::string>& parts, const char* sep) {
  std::string s;
  for (size_t i = 0; i < parts.size(); ++i) s += (i ? sep : "") + parts[i];
  return s;
}

// Used only for its address: dladdr() on it tells where libdeform_engine.so itself lives.
void coreAnchor() {}

fs::path coreLibraryDir() {
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&coreAnchor), &info) == 0 || !info.dli_fname) return {};
  std::error_code ec;
  const fs::path lib = fs::canonical(info.dli_fname, ec);
  return ec ? fs::path() : lib.parent_path();
}

fs::path executableDir() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path() : exe.parent_path();
}

bool isElf(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  char magic[4] = {};
  in.read(magic, 4);
  return in.gcount() == 4 && std::memcmp(magic,
                                         "\x7f"
                                         "ELF",
                                         4) == 0;
}

// "deform_NAME.so" or "libdeform_NAME.so" -> NAME; empty when the file is not a plugin name.
std::string pluginNameOf(const std::string& file) {
  std::string stem;
  for (const char* prefix : {"libdeform_", "deform_"}) {
    const size_t n = std::strlen(prefix);
    if (file.size() > n + 3 && file.compare(0, n, prefix) == 0 &&
        file.compare(file.size() - 3, 3, ".so") == 0) {
      stem = file.substr(n, file.size() - n - 3);
      break;
    }
  }
  // The core's own libraries and back ends (core/CMakeLists.txt) are never plugins.
  for (const char* core : {"core", "sdk", "geometry", "kernels", "engine", "gmsh", "contact_bullet",
                           "instruments_ode"})
    if (stem == core) return std::string();
  return stem;
}

/// Loads the file and runs its registration in a forked child: "" when the child ended
/// normally, else "killed by signal 11 (SIGSEGV) while loading and registering". A plugin that
/// crashes there (its static initialisers, deform_abi_version or deform_register) must not take
/// this process down: `plugins` lists it, `stability` and the tables give it failed rows.
std::string crashWhileRegistering(const std::string& path) {
  std::fflush(nullptr);
  const pid_t pid = ::fork();
  if (pid < 0) return "";  // cannot probe: load it here as before
  if (pid == 0) {
    // Only the plugin's own code runs here; output and exit handlers stay the parent's.
    if (void* dl = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL)) {
      const auto abi = reinterpret_cast<AbiVersionFn>(dlsym(dl, "deform_abi_version"));
      const auto reg = reinterpret_cast<RegisterFn>(dlsym(dl, "deform_register"));
      try {
        if (abi && reg && abi() == DEFORM_ABI_VERSION) {
          Registry registry;
          reg(registry);
        }
      } catch (...) {
        // reported by the real load
      }
    }
    ::_exit(0);
  }
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (!WIFSIGNALED(status)) return "";
  const int sig = WTERMSIG(status);
  const char* name = sigabbrev_np(sig);
  return "killed by signal " + std::to_string(sig) +
         (name ? std::string(" (SIG") + name + ")" : std::string()) +
         " while loading and registering";
}

}  // namespace

struct PluginLoader::Handle {
  std::string path;  // canonical
  void* dl = nullptr;
  Registry registry;

  Handle() = default;
  Handle(const Handle&) = delete;
  Handle& operator=(const Handle&) = delete;
  ~Handle() {
    // The registry's factories live in the plugin's code: destroy them before unmapping it.
    registry = Registry();
    if (dl) dlclose(dl);
  }
};

PluginLoader::PluginLoader(std::vector<std::string> searchPath)
    : m_searchPath(searchPath.empty() ? defaultSearchPath() : std::move(searchPath)) {}

PluginLoader::~PluginLoader() {
  // Unload in reverse load order.
  while (!m_handles.empty()) m_handles.pop_back();
}

std::vector<std::string> PluginLoader::defaultSearchPath() {
  std::vector<std::string> dirs;
  if (const char* env = std::getenv("DEFORM_PLUGIN_PATH")) {
    std::string s(env);
    size_t start = 0;
    while (start <= s.size()) {
      const size_t end = std::min(s.find(':', start), s.size());
      if (end > start) dirs.push_back(s.substr(start, end - start));
      start = end + 1;
    }
  }
  // The plugin folders of the copy that is running come first: beside wherever
  // libdeform_engine.so was actually loaded from, and PREFIX/lib/deformbench/plugins next to
  // PREFIX/bin/deformbench (relocated installs). Only then the build tree's, which would
  // otherwise hand an installed copy the plugins of whatever was last built there, and the
  // configured install prefix's.
  if (const fs::path lib = coreLibraryDir(); !lib.empty()) {
    dirs.push_back((lib / "deformbench" / "plugins").lexically_normal().string());
  }
  if (const fs::path exe = executableDir(); !exe.empty()) {
    dirs.push_back((exe / ".." / "lib" / "deformbench" / "plugins").lexically_normal().string());
  }
#ifdef DEFORM_BUILD_PLUGIN_DIR
  dirs.emplace_back(DEFORM_BUILD_PLUGIN_DIR);
#endif
#ifdef DEFORM_INSTALL_PLUGIN_DIR
  dirs.emplace_back(DEFORM_INSTALL_PLUGIN_DIR);
#endif
  std::vector<std::string> unique;
  std::set<std::string> seen;
  for (std::string& d : dirs) {
    std::string key = fs::path(d).lexically_normal().string();
    while (key.size() > 1 && key.back() == '/') key.pop_back();
    if (seen.insert(key).second) unique.push_back(std::move(d));
  }
  return unique;
}

std::string PluginLoader::locate(const std::string& pluginName) const {
  if (pluginName.find('/') != std::string::npos) {
    // A path, not a name: accepted as is.
    std::error_code ec;
    if (fs::is_regular_file(pluginName, ec)) return pluginName;
    throw PluginError(PluginError::Kind::FileNotFound, pluginName, "no such plugin file");
  }
  const std::string file = "deform_" + pluginName + ".so";
  if (!pluginName.empty()) {
    for (const std::string& dir : m_searchPath) {
      for (const std::string& candidate : {file, "lib" + file}) {
        const fs::path p = fs::path(dir) / candidate;
        std::error_code ec;
        if (fs::is_regular_file(p, ec)) return p.string();
      }
    }
  }
  throw PluginError(PluginError::Kind::FileNotFound, file,
                    "plugin '" + pluginName + "' not found in: " + join(m_searchPath, ", ") +
                        " (add its folder with --plugin-dir DIR, or list folders in the "
                        "DEFORM_PLUGIN_PATH environment variable, ':'-separated)");
}

const std::vector<ModelInfo>& PluginLoader::loadFile(const std::string& path) {
  using Kind = PluginError::Kind;
  std::error_code ec;
  const fs::path canonical = fs::canonical(path, ec);
  if (ec || !fs::is_regular_file(canonical, ec)) {
    throw PluginError(Kind::FileNotFound, path, "no such plugin file");
  }
  for (const auto& h : m_handles) {
    if (h->path == canonical.string()) return h->registry.models();
  }

  if (const std::string crash = crashWhileRegistering(canonical.string()); !crash.empty())
    throw PluginError(Kind::InitFailure, path, "the plugin crashed: " + crash);

  auto handle = std::make_unique<Handle>();
  handle->path = canonical.string();
  dlerror();
  handle->dl = dlopen(handle->path.c_str(), kLoadFlags);
  if (!handle->dl) {
    const char* err = dlerror();
    const std::string why = err ? err : "unknown dlopen error";
    throw PluginError(Kind::NotSharedObject, path,
                      isElf(handle->path) ? "cannot be loaded as a plugin: " + why
                                          : "not a shared object (dlopen: " + why + ")");
  }

  auto abi = reinterpret_cast<AbiVersionFn>(dlsym(handle->dl, "deform_abi_version"));
  if (!abi) throw PluginError(Kind::MissingSymbol, path, "missing symbol deform_abi_version");
  int version = -1;
  try {
    version = abi();
  } catch (...) {
    throw PluginError(Kind::InitFailure, path, "deform_abi_version threw an exception");
  }
  if (version != DEFORM_ABI_VERSION) {
    throw PluginError(Kind::AbiMismatch, path,
                      "ABI version " + std::to_string(version) + ", this deformbench expects " +
                          std::to_string(DEFORM_ABI_VERSION) + " (rebuild the plugin)");
  }

  auto reg = reinterpret_cast<RegisterFn>(dlsym(handle->dl, "deform_register"));
  if (!reg) throw PluginError(Kind::MissingSymbol, path, "missing symbol deform_register");
  // Nothing may propagate out of the plugin's code unconverted: the harness reports a
  // PluginError as one line and carries on with the other models.
  std::string failure;
  try {
    reg(handle->registry);
  } catch (const std::exception& e) {
    failure = std::string("deform_register threw: ") + e.what();
  } catch (...) {
    failure = "deform_register threw an exception of unknown type";
  }
  if (!failure.empty()) throw PluginError(Kind::InitFailure, path, failure);
  if (handle->registry.models().empty()) {
    throw PluginError(Kind::InitFailure, path, "deform_register registered no model");
  }
  for (const ModelInfo& m : handle->registry.models()) {
    for (const ParamSpec& p : m.params) {
      const std::string why = calibrationDeclarationProblem(p);
      if (!why.empty())
        throw PluginError(Kind::InitFailure, path,
                          "model '" + m.name + "' parameter '" + p.key + "': " + why);
    }
  }
  m_handles.push_back(std::move(handle));
  return m_handles.back()->registry.models();
}

const ModelInfo& PluginLoader::load(const std::string& pluginName, const std::string& modelName) {
  const std::string path = locate(pluginName);
  const std::vector<ModelInfo>& models = loadFile(path);
  std::string want = modelName;
  if (want.empty()) {
    // A plugin given by path defaults to the model named after its file (deform_NAME.so).
    want = pluginName;
    if (pluginName.find('/') != std::string::npos) {
      const std::string file = fs::path(pluginName).filename().string();
      want = pluginNameOf(file).empty() ? file : pluginNameOf(file);
    }
  }
  for (const ModelInfo& m : models) {
    if (m.name == want) return m;
  }
  std::vector<std::string> names;
  for (const ModelInfo& m : models) names.push_back(m.name);
  throw PluginError(PluginError::Kind::InitFailure, path,
                    "plugin '" + pluginName + "' has no model '" + want +
                        "'; it registers: " + join(names, ", "));
}

std::vector<std::string> PluginLoader::discover() const {
  std::set<std::string> names;
  for (const std::string& dir : m_searchPath) {
    std::error_code ec;
    fs::directory_iterator it(dir, ec), end;
    for (; !ec && it != end; it.increment(ec)) {
      std::error_code fec;
      if (!it->is_regular_file(fec)) continue;
      std::string name = pluginNameOf(it->path().filename().string());
      if (!name.empty()) names.insert(std::move(name));
    }
  }
  return {names.begin(), names.end()};
}

std::vector<std::string> PluginLoader::loadedFiles() const {
  std::vector<std::string> files;
  for (const auto& h : m_handles) files.push_back(h->path);
  return files;
}

}  // namespace deform
