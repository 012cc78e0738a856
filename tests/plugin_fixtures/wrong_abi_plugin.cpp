// Fixture: claims ABI version 7. Its deform_register must never be called.
#include <deform/registry.h>

#include <cstdlib>

DEFORM_PLUGIN_EXPORT int deform_abi_version() {
  return 7;
}
DEFORM_PLUGIN_EXPORT void deform_register(deform::Registry&) {
  std::abort();
}
