// The "pbd" plugin: registers PbdModel (pbd_model.h) with the harness.
#include "pbd_model.h"

#include <deform/sdk/registry.h>

DEFORM_PLUGIN(registry) {
  deform::ModelInfo info;
  info.name = "pbd";
  info.description =
      "Position based dynamics on the organ surface (stretch, dihedral bending, global volume) "
      "or on a tet mesh (edges + tet volumes); classic or XPBD stiffness";
  info.citation =
      "Mueller, Heidelberger, Hennix, Ratcliff 2007, Position based dynamics, J. Vis. Commun. "
      "Image Represent. 18(2), doi:10.1016/j.jvcir.2007.01.005; Macklin, Mueller, Chentanez 2016, "
      "XPBD, MIG '16, doi:10.1145/2994258.2994272";
  info.version = "1.0";
  using C = deform::Capability;
  info.capabilities = {C::Grasp,    C::PointForce, C::Gravity,         C::ReactionForce,
                       C::TetInput, C::Contact,    C::ContactReaction, C::Markers};
  info.params = deform::pbd::paramSpecs();
  info.create = [] { return std::make_unique<deform::pbd::PbdModel>(); };
  // What the harness's sweep, bench and stability run it with (registry.h).
  info.knob = {"iterations", {1LL, 2LL, 5LL, 10LL, 20LL, 50LL}, {2LL, 10LL, 40LL}};
  info.presets["bench"] = {{}};
  info.presets["bench_8k"] = {{}, {{"bending", true}}};
  registry.add(std::move(info));
}
