#include <deform/sparse.h>

#include <dlfcn.h>

namespace deform {

namespace {

/// omp_get/set_max_active_levels of an already loaded libgomp (CHOLMOD pulls it in), looked up
/// at run time so that the core does not link an OpenMP runtime of its own.
struct OpenMpLevels {
  int (*get)() = nullptr;
  void (*set)(int) = nullptr;
};

const OpenMpLevels& openMpLevels() {
  static const OpenMpLevels levels = [] {
    OpenMpLevels l;
    void* gomp = dlopen("libgomp.so.1", RTLD_LAZY | RTLD_NOLOAD);
    if (!gomp) return l;
    l.get = reinterpret_cast<int (*)()>(dlsym(gomp, "omp_get_max_active_levels"));
    l.set = reinterpret_cast<void (*)(int)>(dlsym(gomp, "omp_set_max_active_levels"));
    if (!l.get || !l.set) l = OpenMpLevels{};
    return l;  // the handle stays open: libgomp is in use by CHOLMOD for the whole run
  }();
  return levels;
}

}  // namespace

SerialOpenMpScope::SerialOpenMpScope() {
  const OpenMpLevels& omp = openMpLevels();
  if (!omp.set) return;
  m_saved = omp.get();
  omp.set(0);
}

SerialOpenMpScope::~SerialOpenMpScope() {
  if (m_saved >= 0) openMpLevels().set(m_saved);
}

}  // namespace deform
