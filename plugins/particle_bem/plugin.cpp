// particle_bem plugin: registers the surface-guided particle model (particle_bem_model.h) and
// its "static_accuracy" measure (static_accuracy.h), the paper's Table 2 without a model run.
#include "particle_bem_model.h"
#include "static_accuracy.h"

#include <deform/sdk/registry.h>

DEFORM_PLUGIN(registry) {
  deform::ModelInfo info = deform::particle_bem::ParticleBemModel::info();
  // What the harness's sweep, bench and stability run it with (registry.h).
  // The BEM surface's resolution; the particles follow it with no iterative solve (no effort).
  info.resolution = {"coarse_vertices", {150LL, 300LL, 600LL, 1200LL}, {150LL, 300LL, 600LL}};
  info.presets["bench"] = {{{"coarse_vertices", 300LL}}};
  info.presets["stability_quick"] = {{{"coarse_vertices", 200LL}, {"points", 150LL}}};
  info.measures["static_accuracy"] = deform::particle_bem::staticAccuracyMeasure;
  registry.add(std::move(info));
}
