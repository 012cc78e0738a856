// Fixture: a working plugin with two models ("toy" and "toy_rigid"), or, built with
// TOY_PREFIXED, one model "prefixed" (file libdeform_prefixed.so).
#include <deform/sdk/registry.h>

#include "toy_model.h"

DEFORM_PLUGIN(registry) {
#ifdef TOY_PREFIXED
  registry.add(deform::fixture::toyInfo("prefixed"));
#else
  registry.add(deform::fixture::toyInfo("toy"));
  registry.add(deform::fixture::toyInfo("toy_rigid"));
#endif
}
