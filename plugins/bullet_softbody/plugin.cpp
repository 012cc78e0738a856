// The "bullet_softbody" plugin: registers BulletSoftBodyModel (bullet_softbody_model.h).
#include "bullet_softbody_model.h"

#include <deform/sdk/registry.h>

DEFORM_PLUGIN(registry) {
  deform::ModelInfo info;
  info.name = "bullet_softbody";
  info.description =
      "Peer baseline: Bullet 3.24's classic position-based btSoftBody on the organ surface "
      "(links from mesh edges, volume conservation force, kinematic grasps)";
  info.citation =
      "Bullet Physics SDK 3.24, E. Coumans et al., https://github.com/bulletphysics/bullet3 "
      "(btSoftBody by N. Presson); method family: Mueller, Heidelberger, Hennix, Ratcliff 2007, "
      "Position based dynamics, doi:10.1016/j.jvcir.2007.01.005";
  info.version = "1.0";
  using C = deform::Capability;
  info.capabilities = {C::Grasp, C::PointForce, C::Gravity, C::Contact, C::ContactReaction};
  info.params = deform::bullet_softbody::paramSpecs();
  info.create = [] { return std::make_unique<deform::bullet_softbody::BulletSoftBodyModel>(); };
  registry.add(std::move(info));
}
