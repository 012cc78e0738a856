// Metaballs plugin entry point: registers the "metaballs" model (see metaballs_model.h).
#include "metaballs_model.h"

DEFORM_PLUGIN(registry) {
  deform::ModelInfo info = deform::metaballs::metaballsModelInfo();
  // What the harness's sweep, bench and stability run it with (registry.h).
  info.knob = {"spheres", {100LL, 250LL, 500LL, 900LL}, {100LL, 300LL}};
  info.presets["bench"] = {{{"spheres", 300LL}}};
  info.presets["stability_quick"] = {{{"spheres", 150LL}}};
  registry.add(std::move(info));
}
