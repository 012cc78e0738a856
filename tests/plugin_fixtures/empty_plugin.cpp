// Fixture: a well-formed plugin that registers no model.
#include <deform/registry.h>

DEFORM_PLUGIN(registry) {
  (void)registry;
}
