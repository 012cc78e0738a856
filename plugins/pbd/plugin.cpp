// The "pbd" plugin: its parameters, their config (PbdConfig) and the registration of PbdModel
// (pbd_model.h).
#include "pbd_model.h"

#include <deform/sdk/registry.h>

namespace deform::pbd {

std::vector<ParamSpec> paramSpecs() {
  return {
      common_params::iterations(10, 10000, "Gauss-Seidel sweeps over all constraints"),
      common_params::network("surface: constraints on the organ's surface mesh (the papers' "
                             "baselines); volume: on the tets of the surface tetrahedralised with "
                             "about volume_elements tets (a mesh file with tets is used as given "
                             "either way)"),
      common_params::volumeElements(),
      ParamSpec::choice("stiffness_mode", "xpbd", {"classic", "xpbd"},
                        "classic: [0,1] stiffness with k' = 1-(1-k)^(1/n); xpbd: compliances "
                        "from E, nu, thickness"),
      common_params::unitStiffness("stretch_stiffness", 1.0, 0.01,
                                   "classic mode: distance constraint stiffness"),
      common_params::unitStiffness("bending_stiffness", 0.1, 0.001,
                                   "classic mode: dihedral bending constraint stiffness"),
      common_params::unitStiffness("volume_stiffness", 1.0, 0.01,
                                   "classic mode: volume constraint stiffness (global or per tet)"),
      ParamSpec::flag("bending", false, "bending constraints on interior surface edges"),
      common_params::bendingModel(
          "bending constraint: isometric (Bergou et al. 2006, a constant stencil "
          "per hinge) or dihedral angle (Mueller et al. 2007)"),
      ParamSpec::flag("volume", true, "global volume constraint on a closed surface"),
      ParamSpec::flag("volume_every_sweep", false,
                      "project the global volume constraint in every sweep (default: last sweep "
                      "only; it costs a pass over all triangles)"),
      common_params::thickness(
          10.0, "xpbd mode, surface input: shell thickness for stretch/bending compliance"),
      common_params::damping(1.0, 1e4, 0.01,
                             "velocity damping rate: v <- v exp(-damping dt) each step"),
      common_params::precision(
          "number type of the distance, isometric bending, tet volume and global volume "
          "projections (positions relative to the organ's centre); state between steps stays "
          "double"),
  };
}

PbdConfig configFromParams(const ParamValues& p) {
  PbdConfig c;
  c.iterations = static_cast<int>(p.integer("iterations"));
  c.volumeNetwork = p.choice("network") == "volume";
  c.volumeElements = p.integer("volume_elements");
  c.mode = p.choiceAs<StiffnessMode>(
      "stiffness_mode", {{"classic", StiffnessMode::Classic}, {"xpbd", StiffnessMode::Xpbd}});
  c.stretchStiffness = p.real("stretch_stiffness");
  c.bendingStiffness = p.real("bending_stiffness");
  c.volumeStiffness = p.real("volume_stiffness");
  c.bending = p.flag("bending");
  c.bendingModel = p.choiceAs<BendingModel>(
      "bending_model",
      {{"isometric", BendingModel::Isometric}, {"dihedral", BendingModel::Dihedral}});
  c.volume = p.flag("volume");
  c.volumeEverySweep = p.flag("volume_every_sweep");
  c.thickness = p.real("thickness");
  c.damping = p.real("damping");
  c.precision = p.choiceAs<Precision>(
      "precision", {{"float32", Precision::Float32}, {"float64", Precision::Float64}});
  return c;
}

}  // namespace deform::pbd

DEFORM_PLUGIN(registry) {
  using C = deform::Capability;
  deform::ModelInfo info = deform::modelInfo<deform::pbd::PbdModel>(
      "pbd",
      "Position based dynamics on the organ surface (stretch, dihedral bending, global volume) "
      "or on a tet mesh (edges + tet volumes); classic or XPBD stiffness",
      "Mueller, Heidelberger, Hennix, Ratcliff 2007, Position based dynamics, J. Vis. Commun. "
      "Image Represent. 18(2), doi:10.1016/j.jvcir.2007.01.005; Macklin, Mueller, Chentanez 2016, "
      "XPBD, MIG '16, doi:10.1145/2994258.2994272",
      {C::Grasp, C::PointForce, C::Gravity, C::ReactionForce, C::TetInput, C::Contact,
       C::ContactReaction, C::Markers, C::Sliding},
      deform::pbd::paramSpecs());
  // What the harness's sweep, bench and stability run it with (registry.h).
  // On the organ's surface mesh (no resolution of its own): the solver's sweeps only.
  info.effort = {"iterations", {1LL, 2LL, 5LL, 10LL, 20LL, 50LL}, {2LL, 10LL, 40LL}};
  info.presets["bench"] = {{}};
  info.presets["bench_8k"] = {{}, {{"bending", true}}};
  registry.add(std::move(info));
}
