// Fixture: deform_register throws (after registering one model, which must be discarded).
#include <deform/sdk/registry.h>

#include <stdexcept>

#include "toy_model.h"

DEFORM_PLUGIN(registry) {
  registry.add(deform::fixture::toyInfo("throws"));
  throw std::runtime_error("fixture failure on purpose");
}
