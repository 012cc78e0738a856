// The "bullet_deformable" plugin: its parameters, their config (DeformableConfig) and the
// registration of BulletDeformableModel (bullet_deformable_model.h).
#include "bullet_deformable_model.h"

#include <deform/sdk/registry.h>

namespace deform::bullet_deformable {

std::vector<ParamSpec> paramSpecs() {
  return {
      ParamSpec::choice("force", "neo_hookean", {"neo_hookean", "linear_elasticity"},
                        "Bullet's elastic force: btDeformableNeoHookeanForce (stable Neo-Hookean) "
                        "or btDeformableLinearElasticityForce (small strain)"),
      ParamSpec::integer("tets", 6000, 10, 5000000,
                         "target tetrahedron count of the shared Gmsh mesher (organs without a "
                         "volume mesh)"),
      ParamSpec::real("damping_alpha", "1/s", 0.01, 0.0, 1e4,
                      "mass-proportional damping alpha M (linear_elasticity only; Bullet's "
                      "default)")
          .calibrate(0.0001, 100, ParamScale::Log),
      ParamSpec::real("damping_beta", "s", 0.01, 0.0, 10.0,
                      "stiffness-proportional damping beta K (Bullet's default for "
                      "linear_elasticity)")
          .calibrate(0.0001, 1, ParamScale::Log),
      ParamSpec::integer("newton_iterations", 1, 1, 1000,
                         "Newton iterations of Bullet's implicit solver per step (Bullet's "
                         "default 1: linearly implicit)"),
      ParamSpec::integer("krylov_iterations", 300, 1, 100000,
                         "iteration cap of Bullet's conjugate gradient solver per Newton "
                         "iteration (Bullet's default 300)"),
      ParamSpec::real("krylov_tolerance", "1", 1.1920928955078125e-07, 1e-30, 1.0,
                      "CG stops when r^T P^-1 r < tol min(1, b^T P^-1 b), P the preconditioner; "
                      "default FLT_EPSILON, the value of Bullet's single-precision build (its "
                      "double build uses DBL_EPSILON and then always runs to the cap)"),
      ParamSpec::choice("preconditioner", "rest_factor", {"rest_factor", "none"},
                        "preconditioner of Bullet's CG: the Cholesky factor of the implicit "
                        "step's matrix M + dt D + dt^2 K at rest, or none (the identity, what "
                        "Bullet applies in this solver form); the converged step is the same"),
  };
}

DeformableConfig configFromParams(const ParamValues& p) {
  DeformableConfig c;
  c.force =
      p.choiceAs<ElasticForce>("force", {{"neo_hookean", ElasticForce::NeoHookean},
                                         {"linear_elasticity", ElasticForce::LinearElasticity}});
  c.targetTets = p.integer("tets");
  c.dampingAlpha = p.real("damping_alpha");
  c.dampingBeta = p.real("damping_beta");
  c.newtonIterations = static_cast<int>(p.integer("newton_iterations"));
  c.krylovIterations = static_cast<int>(p.integer("krylov_iterations"));
  c.krylovTolerance = p.real("krylov_tolerance");
  c.preconditioner = p.choiceAs<CgPreconditioning>(
      "preconditioner",
      {{"rest_factor", CgPreconditioning::RestFactor}, {"none", CgPreconditioning::None}});
  return c;
}

}  // namespace deform::bullet_deformable

DEFORM_PLUGIN(registry) {
  using C = deform::Capability;
  deform::ModelInfo info = deform::modelInfo<deform::bullet_deformable::BulletDeformableModel>(
      "bullet_deformable",
      "Peer baseline: Bullet 3.24's implicit FEM deformable body (btDeformableMultiBodyDynamics"
      "World, Neo-Hookean or linear elasticity on a tet mesh, kinematic grasps)",
      "Bullet Physics SDK 3.24, E. Coumans et al., https://github.com/bulletphysics/bullet3 "
      "(deformable solver by Xuchen Han, 2019); stable Neo-Hookean: Smith, de Goes, Kim 2018, "
      "ACM TOG 37(2), doi:10.1145/3180491",
      {C::Grasp, C::PointForce, C::Gravity, C::TetInput, C::NeedsPrecompute, C::Contact,
       C::ContactReaction, C::Sliding, C::ReactionForce, C::Markers},
      deform::bullet_deformable::paramSpecs());
  // The conformance suite runs every shipped scene: 1500 tets instead of 6000 keep it to seconds.
  info.presets["conformance"] = {{{"tets", 1500LL}}};
  // The stability sweep's cases run 1 s of 1 ms steps in a 60 s limit (120 s without --quick).
  // At 6000 tets a case ran past it (Bullet's unpreconditioned CG at its cap); 1500 tets keep it
  // to seconds.
  info.presets["stability_quick"] = {{{"tets", 1500LL}}};
  info.presets["stability"] = {{{"tets", 1500LL}}};
  info.resolution = {"tets", {1000LL, 3000LL, 6000LL, 12000LL}, {1000LL, 3000LL, 6000LL}};
  info.effort = {"newton_iterations", {1LL, 2LL, 4LL}, {1LL, 4LL}};
  registry.add(std::move(info));
}
