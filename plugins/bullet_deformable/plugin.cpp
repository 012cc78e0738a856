// The "bullet_deformable" plugin: registers BulletDeformableModel (bullet_deformable_model.h).
#include "bullet_deformable_model.h"

#include <deform/sdk/registry.h>

DEFORM_PLUGIN(registry) {
  deform::ModelInfo info;
  info.name = "bullet_deformable";
  info.description =
      "Peer baseline: Bullet 3.24's implicit FEM deformable body (btDeformableMultiBodyDynamics"
      "World, Neo-Hookean or linear elasticity on a tet mesh, kinematic grasps)";
  info.citation =
      "Bullet Physics SDK 3.24, E. Coumans et al., https://github.com/bulletphysics/bullet3 "
      "(deformable solver by Xuchen Han, 2019); stable Neo-Hookean: Smith, de Goes, Kim 2018, "
      "ACM TOG 37(2), doi:10.1145/3180491";
  info.version = "1.0";
  using C = deform::Capability;
  info.capabilities = {C::Grasp,           C::PointForce, C::Gravity,        C::TetInput,
                       C::NeedsPrecompute, C::Contact,    C::ContactReaction};
  info.params = deform::bullet_deformable::paramSpecs();
  info.create = [] { return std::make_unique<deform::bullet_deformable::BulletDeformableModel>(); };
  // The conformance suite runs every shipped scene: 1500 tets instead of 6000 keep it to seconds.
  info.presets["conformance"] = {{{"tets", 1500LL}}};
  // The stability sweep's cases run 1 s of 1 ms steps in a 60 s limit (120 s without --quick).
  // At 6000 tets a case ran past it; the stiff gravity cantilever (2378 tets at any target: the
  // beam's fine surface) ran Bullet's CG to its 300-iteration cap, 195 ms a step. 30 iterations
  // take 22 ms; its tip sag after 1 s is 1.08 mm, 1.12 mm with 300 (beam theory 1.49 mm).
  info.presets["stability_quick"] = {{{"tets", 1500LL}, {"krylov_iterations", 30LL}}};
  info.presets["stability"] = {{{"tets", 1500LL}, {"krylov_iterations", 30LL}}};
  registry.add(std::move(info));
}
