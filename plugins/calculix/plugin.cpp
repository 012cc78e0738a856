// The calculix plugin: CalculiX's ccx as an independent reference on reference_fem's tet mesh.
// See README.md for the method, the parameters and the limits.
#include "calculix_model.h"

#include <deform/geometry/organ_tets.h>
#include <deform/sdk/registry.h>

namespace {

std::vector<deform::ParamSpec> calculixParams() {
  using deform::ParamSpec;
  std::vector<ParamSpec> specs = {
      ParamSpec::choice("material", "neo_hookean", {"linear", "neo_hookean"},
                        "neo_hookean: *HYPERELASTIC, NEO HOOKE (C10 = mu/2, D1 = 2/K) with NLGEOM; "
                        "linear: *ELASTIC, small strain"),
      ParamSpec::integer("element_order", 2, 1, 2,
                         "2: C3D10 (reference_fem's 10-node tets); 1: C3D4 (its 4-node tets)"),
      ParamSpec::real("initial_increment", "1", 0.25, 1e-6, 1.0,
                      "ccx's first load increment, as a fraction of each solve (NLGEOM)"),
      ParamSpec::real("max_increment", "1", 1.0, 1e-6, 1.0, "ccx's largest load increment"),
      ParamSpec::real("min_increment", "1", 1e-5, 1e-12, 1.0,
                      "ccx gives up (a failed run) below this increment"),
      ParamSpec::real("residual_tolerance", "1", 1e-5, 1e-12, 0.1,
                      "ccx's convergence test (*CONTROLS, FIELD): largest residual force <= this x "
                      "the average force, and largest displacement correction <= 10 x this x the "
                      "increment's displacement (ccx's own defaults: 0.005, 0.01)"),
      ParamSpec::integer("max_increments", 1000, 1, 1000000, "ccx's increments per solve"),
      ParamSpec::real("timeout", "s", 3600.0, 1.0, 604800.0,
                      "wall-clock limit of one ccx run (killed after it: a failed run)"),
      ParamSpec::real("max_memory", "B", 0.0, 0.0, 1e15,
                      "address-space limit of one ccx run (a run past it fails alone, not the "
                      "machine); 0: half of the machine's physical memory"),
  };
  // reference_fem's tet mesh parameters after "element_order" (organ_tets.h): the same values
  // mesh the same tets.
  return deform::withOrganTetParams(std::move(specs), 2);
}

}  // namespace

DEFORM_PLUGIN(registry) {
  using C = deform::Capability;
  deform::ModelInfo info = deform::modelInfo(
      "calculix",
      "Independent reference: CalculiX ccx (C3D10, Neo-Hookean, NLGEOM) on reference_fem's mesh",
      "CalculiX: G. Dhondt, The Finite Element Method for Three-Dimensional Thermomechanical "
      "Applications, Wiley 2004, doi:10.1002/0470021217; www.calculix.de",
      {C::Grasp, C::PointForce, C::Gravity, C::NeedsPrecompute, C::TetInput, C::QuasiStatic,
       C::RollerSupport, C::Markers, C::Sliding, C::ReactionForce},
      calculixParams(), deform::calculix::makeCalculixModel);
  // The conformance suite's scenes check (status and finiteness only): coarse linear tets, so
  // that four liver/gallbladder scenes stay within the suite's budget (P2 at 300 tets took
  // 1200 s on the loaded 2-core machine).
  info.presets["conformance"] = {{{"elements", 300LL}, {"element_order", 1LL}}};
  registry.add(std::move(info));
}
