// Fixture: exports deform_abi_version but not deform_register.
#include <deform/sdk/registry.h>

DEFORM_PLUGIN_EXPORT int deform_abi_version() {
  return DEFORM_ABI_VERSION;
}
