// particle_bem plugin: registers the surface-guided particle model (particle_bem_model.h).
#include "particle_bem_model.h"

DEFORM_PLUGIN(registry) {
  registry.add(deform::particle_bem::ParticleBemModel::info());
}
