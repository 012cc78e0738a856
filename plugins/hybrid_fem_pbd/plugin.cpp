// The "hybrid_fem_pbd" plugin: registers HybridModel (hybrid_model.h) with the harness.
#include <deform/sdk/registry.h>

#include "hybrid_model.h"

DEFORM_PLUGIN(registry) {
  deform::ModelInfo info;
  info.name = "hybrid_fem_pbd";
  info.description =
      "Hybrid mesh: linear FEM on a coarse tet mesh (vertex-cover simplified surface) drives "
      "PBD stretch/bending on the fine surface; small incisions";
  info.citation =
      "A Hybrid Model Method for Accurate Surface Deformation and Incision Based on FEM and PBD, "
      "Scientific Programming 2021, article 8343312 (hindawi.com/journals/sp/2021/8343312)";
  info.version = "1.0";
  using C = deform::Capability;
  info.capabilities = {C::Grasp, C::PointForce,      C::Gravity, C::ReactionForce,
                       C::Cut,   C::NeedsPrecompute, C::Contact, C::Markers};
  info.params = deform::hybrid::paramSpecs();
  info.create = [] { return std::make_unique<deform::hybrid::HybridModel>(); };
  // What the harness's sweep, bench and stability run it with (registry.h).
  info.knob = {"iterations", {2LL, 5LL, 10LL, 20LL, 40LL}, {2LL, 10LL, 40LL}};
  info.presets["bench"] = {{}};
  info.presets["bench_8k"] = {{}};
  registry.add(std::move(info));
}
