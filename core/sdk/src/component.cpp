// Loading the core's optional back ends (component.h).
#include <deform/internal/component.h>
#include <deform/sdk/error.h>

#include <dlfcn.h>

#include <filesystem>
#include <map>
#include <mutex>

namespace deform {

namespace {

/// The folder of the shared object holding this function: the SDK library's.
std::filesystem::path sdkFolder() {
  Dl_info info{};
  if (dladdr(reinterpret_cast<void*>(&sdkFolder), &info) == 0 || !info.dli_fname) return {};
  return std::filesystem::path(info.dli_fname).parent_path();
}

}  // namespace

void* coreComponentSymbol(const std::string& library, const char* symbol, const std::string& what) {
  static std::mutex mutex;
  static std::map<std::string, void*> handles;  // opened once, never closed
  std::lock_guard<std::mutex> lock(mutex);
  void*& handle = handles[library];
  if (!handle) {
    const std::filesystem::path path = sdkFolder() / library;
    handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
      const char* err = dlerror();
      handles.erase(library);
      throw UnsupportedError(what + " needs " + path.string() + ", which cannot be loaded (" +
                             (err ? err : "unknown dlopen error") + ")");
    }
  }
  dlerror();
  void* address = dlsym(handle, symbol);
  if (!address) throw UnsupportedError(what + " needs " + library + ", which lacks " + symbol);
  return address;
}

}  // namespace deform
