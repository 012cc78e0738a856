// The "massspring" plugin: registers MassSpringModel (massspring_model.h) with the harness.
#include "massspring_model.h"

#include <deform/sdk/registry.h>

DEFORM_PLUGIN(registry) {
  deform::ModelInfo info;
  info.name = "massspring";
  info.description =
      "Mass-spring network on the organ surface (edge + bending springs, van Gelder stiffness) "
      "or on tet edges; explicit, symplectic or implicit Euler (Newton + CG, or prefactored "
      "local/global iterations)";
  info.citation =
      "van Gelder 1998, Approximate simulation of elastic membranes by triangulated spring "
      "meshes, J. Graphics Tools 3(2); Baraff & Witkin 1998, "
      "Large steps in cloth simulation, SIGGRAPH '98, doi:10.1145/280814.280821; Liu, Bargteil, "
      "O'Brien & Kavan 2013, Fast simulation of mass-spring systems, ACM TOG 32(6) 214; Wang "
      "2015, A Chebyshev semi-iterative approach for accelerating projective and position-based "
      "dynamics, ACM TOG 34(6) 246";
  info.version = "1.0";
  using C = deform::Capability;
  info.capabilities = {C::Grasp,    C::PointForce, C::Gravity,         C::ReactionForce,
                       C::TetInput, C::Contact,    C::ContactReaction, C::Markers};
  info.params = deform::massspring::paramSpecs();
  info.create = [] { return std::make_unique<deform::massspring::MassSpringModel>(); };
  // What the harness's sweep, bench and stability run it with (registry.h).
  info.knob = {"integrator",
               {std::string("explicit_euler"), std::string("symplectic_euler"),
                std::string("implicit_euler")},
               {std::string("symplectic_euler"), std::string("implicit_euler")}};
  info.presets["bench"] = {{{"integrator", std::string("implicit_euler")}}};
  info.presets["bench_8k"] = {{},
                              {{"integrator", std::string("local_global")}},
                              {{"integrator", std::string("implicit_euler")}}};
  registry.add(std::move(info));
}
