// Fixture: claims ABI version 99 (never a real one). Its deform_register must never be called.
#include <deform/sdk/registry.h>

#include <cstdlib>

DEFORM_PLUGIN_EXPORT int deform_abi_version() {
  return 99;
}
DEFORM_PLUGIN_EXPORT void deform_register(deform::Registry&) {
  std::abort();
}
