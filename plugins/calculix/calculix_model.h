// The calculix model: the organ on the same tet mesh as reference_fem
// (deform/geometry/organ_tets.h), solved by CalculiX's ccx in a child process at each step the
// harness asks for, as a quasi-static solve from rest to the step's loads (ccx_deck.h,
// ccx_process.h).
#pragma once

#include "ccx_deck.h"

#include <deform/sdk/model.h>

#include <memory>

namespace deform::calculix {

std::unique_ptr<Model> makeCalculixModel();

}  // namespace deform::calculix
