// Fixture: a well-formed plugin that registers no model.
#include <deform/sdk/registry.h>

DEFORM_PLUGIN(registry) {
  (void)registry;
}
