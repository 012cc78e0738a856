// Metaballs plugin entry point: registers the "metaballs" model (see metaballs_model.h).
#include "metaballs_model.h"

DEFORM_PLUGIN(registry) {
  registry.add(deform::metaballs::metaballsModelInfo());
}
