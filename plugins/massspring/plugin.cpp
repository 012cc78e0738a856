// The "massspring" plugin: its parameters, their config (MassSpringConfig) and the registration
// of MassSpringModel (massspring_model.h).
#include "massspring_model.h"

#include <deform/sdk/registry.h>

namespace deform::massspring {

std::vector<ParamSpec> paramSpecs() {
  return {
      ParamSpec::choice("integrator", "symplectic_euler",
                        {"explicit_euler", "symplectic_euler", "implicit_euler", "local_global"},
                        "time integration: explicit Euler (the papers' baseline), symplectic "
                        "Euler, implicit Euler with one Newton step (Baraff & Witkin 1998), or "
                        "implicit Euler by local/global iterations with a prefactored matrix "
                        "(Liu et al. 2013)"),
      common_params::network(
          "surface: springs on the organ's surface mesh (the papers' baselines); "
          "volume: on the tet edges of the surface tetrahedralised with about "
          "volume_elements tets (a mesh file with tets is used as given either "
          "way)"),
      common_params::volumeElements(),
      common_params::thickness(
          10.0, "surface input: membrane thickness t in the spring rule k = E t sum|T|/L^2"),
      ParamSpec::real("bending_ratio", "1", 0.1, 0.0, 100.0,
                      "bending spring stiffness relative to the spring on the hinge edge")
          .calibrate(0.001, 10, ParamScale::Log),
      ParamSpec::real("damping_ratio", "1", 0.1, 0.0, 100.0,
                      "damping ratio of each spring's axial dashpot, c = 2 zeta sqrt(k mu)")
          .calibrate(0.001, 10, ParamScale::Log),
      ParamSpec::real("mass_damping", "1/s", 1.0, 0.0, 1e4,
                      "mass-proportional damping: force -mass_damping * m * v on every node")
          .calibrate(0.01, 1000, ParamScale::Log),
      ParamSpec::real("cg_tolerance", "1", 1e-6, 1e-14, 1.0,
                      "implicit Euler: relative residual of the conjugate gradient solve"),
      ParamSpec::integer("cg_max_iterations", 200, 1, 100000,
                         "implicit Euler: conjugate gradient iteration cap"),
      ParamSpec::integer("substeps", 0, 0, kMaxSubsteps,
                         "explicit and symplectic Euler: substeps per time step; 0 = automatic, "
                         "enough to stay below the estimated stability limit; 1 = none (the "
                         "papers' experiments, which may diverge)"),
      ParamSpec::integer("local_global_iterations", 5, 1, 10000,
                         "local_global: local/global iterations per step"),
      ParamSpec::choice("local_global_acceleration", "chebyshev", {"chebyshev", "none"},
                        "local_global: Chebyshev semi-iterative acceleration of the iterations "
                        "(Wang 2015) or none (Liu et al. 2013's plain alternation)"),
      ParamSpec::real("local_global_rho", "1", 0.0, 0.0, 0.9999,
                      "local_global with chebyshev: spectral radius of the plain iteration; 0 = "
                      "estimated whenever the system matrix is factorised"),
      ParamSpec::flag("local_global_warm_start", true,
                      "local_global: start the iterations from the inertial prediction plus the "
                      "previous step's correction (false: from the inertial prediction)"),
  };
}

MassSpringConfig configFromParams(const ParamValues& p) {
  MassSpringConfig c;
  c.integrator =
      p.choiceAs<Integrator>("integrator", {{"explicit_euler", Integrator::ExplicitEuler},
                                            {"symplectic_euler", Integrator::SymplecticEuler},
                                            {"implicit_euler", Integrator::ImplicitEuler},
                                            {"local_global", Integrator::LocalGlobal}});
  c.volumeNetwork = p.choice("network") == "volume";
  c.volumeElements = p.integer("volume_elements");
  c.thickness = p.real("thickness");
  c.bendingRatio = p.real("bending_ratio");
  c.dampingRatio = p.real("damping_ratio");
  c.massDamping = p.real("mass_damping");
  c.cgTolerance = p.real("cg_tolerance");
  c.cgMaxIterations = static_cast<int>(p.integer("cg_max_iterations"));
  c.substeps = static_cast<int>(p.integer("substeps"));
  c.localGlobalIterations = static_cast<int>(p.integer("local_global_iterations"));
  c.localGlobalAcceleration = p.choiceAs<LocalGlobalAcceleration>(
      "local_global_acceleration",
      {{"chebyshev", LocalGlobalAcceleration::Chebyshev}, {"none", LocalGlobalAcceleration::None}});
  c.localGlobalRho = p.real("local_global_rho");
  c.localGlobalWarmStart = p.flag("local_global_warm_start");
  return c;
}

}  // namespace deform::massspring

DEFORM_PLUGIN(registry) {
  using C = deform::Capability;
  deform::ModelInfo info = deform::modelInfo<deform::massspring::MassSpringModel>(
      "massspring",
      "Mass-spring network on the organ surface (edge + bending springs, van Gelder stiffness) "
      "or on tet edges; explicit, symplectic or implicit Euler (Newton + CG, or prefactored "
      "local/global iterations)",
      "van Gelder 1998, Approximate simulation of elastic membranes by triangulated spring "
      "meshes, J. Graphics Tools 3(2); Baraff & Witkin 1998, "
      "Large steps in cloth simulation, SIGGRAPH '98, doi:10.1145/280814.280821; Liu, Bargteil, "
      "O'Brien & Kavan 2013, Fast simulation of mass-spring systems, ACM TOG 32(6) 214; Wang "
      "2015, A Chebyshev semi-iterative approach for accelerating projective and position-based "
      "dynamics, ACM TOG 34(6) 246",
      {C::Grasp, C::PointForce, C::Gravity, C::ReactionForce, C::TetInput, C::Contact,
       C::ContactReaction, C::Markers, C::Sliding},
      deform::massspring::paramSpecs());
  // What the harness's sweep, bench and stability run it with (registry.h).
  // On the organ's surface mesh (no resolution of its own); substeps 0 is the automatic
  // (stable) count, and fixed counts below it are swept too (they diverge, flagged invalid).
  info.effort = {"substeps", {0LL, 5LL, 10LL, 20LL, 50LL}, {0LL, 20LL, 50LL}};
  info.presets["bench"] = {{}};  // the defaults; the other integrators are timed on the 8k liver
  info.presets["bench_8k"] = {{},
                              {{"integrator", std::string("local_global")}},
                              {{"integrator", std::string("implicit_euler")}}};
  registry.add(std::move(info));
}
