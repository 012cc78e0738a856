// The "bullet_softbody" plugin: its parameters, their config (SoftBodyConfig) and the
// registration of BulletSoftBodyModel (bullet_softbody_model.h).
#include "bullet_softbody_model.h"

#include <deform/sdk/registry.h>

namespace deform::bullet_softbody {

std::vector<ParamSpec> paramSpecs() {
  return {
      common_params::iterations(10, 100000,
                                "position solver sweeps per step (btSoftBody m_cfg.piterations)"),
      ParamSpec::choice("stiffness_mapping", "xpbd", {"xpbd", "fixed"},
                        "link stiffness kLST: xpbd = per link from E (one XPBD projection's "
                        "fraction, see README); fixed = link_stiffness for every link"),
      ParamSpec::real("link_stiffness", "1", 0.5, 1e-6, 1.0,
                      "kLST of every structural link when stiffness_mapping is fixed")
          .calibrate(0.001, 1, ParamScale::Log),
      common_params::thickness(1.0,
                               "shell thickness t of the xpbd mapping (alpha = L^2 / (E t A_e))"),
      ParamSpec::flag("bending", false,
                      "add Bullet's bending links between nodes two edges apart "
                      "(generateBendingConstraints(2))"),
      ParamSpec::real("bending_stiffness", "1", 0.1, 1e-6, 1.0, "kLST of the bending links")
          .calibrate(0.001, 1, ParamScale::Log),
      ParamSpec::flag("volume", true,
                      "Bullet's volume conservation force with kVC = volume_scale K / V0"),
      ParamSpec::real("volume_scale", "1", 1.0, 0.0, 1e6,
                      "multiplier on the physical volume coefficient K / V0")
          .calibrate(0.001, 1000.0, ParamScale::Log),
      common_params::damping(1.0, 1e4, 0.01,
                             "velocity damping rate c: Bullet kDP = 1 - exp(-c dt)"),
  };
}

SoftBodyConfig configFromParams(const ParamValues& p) {
  SoftBodyConfig c;
  c.iterations = static_cast<int>(p.integer("iterations"));
  c.mapping = p.choiceAs<StiffnessMapping>(
      "stiffness_mapping", {{"xpbd", StiffnessMapping::Xpbd}, {"fixed", StiffnessMapping::Fixed}});
  c.linkStiffness = p.real("link_stiffness");
  c.thickness = p.real("thickness");
  c.bending = p.flag("bending");
  c.bendingStiffness = p.real("bending_stiffness");
  c.volume = p.flag("volume");
  c.volumeScale = p.real("volume_scale");
  c.damping = p.real("damping");
  return c;
}

}  // namespace deform::bullet_softbody

DEFORM_PLUGIN(registry) {
  using C = deform::Capability;
  deform::ModelInfo info = deform::modelInfo<deform::bullet_softbody::BulletSoftBodyModel>(
      "bullet_softbody",
      "Peer baseline: Bullet 3.24's classic position-based btSoftBody on the organ surface "
      "(links from mesh edges, volume conservation force, kinematic grasps)",
      "Bullet Physics SDK 3.24, E. Coumans et al., https://github.com/bulletphysics/bullet3 "
      "(btSoftBody by N. Presson); method family: Mueller, Heidelberger, Hennix, Ratcliff 2007, "
      "Position based dynamics, doi:10.1016/j.jvcir.2007.01.005",
      {C::Grasp, C::PointForce, C::Gravity, C::Contact, C::ContactReaction, C::Sliding,
       C::ReactionForce},
      deform::bullet_softbody::paramSpecs());
  info.effort = {"iterations", {2LL, 5LL, 10LL, 20LL, 40LL}, {5LL, 20LL}};
  registry.add(std::move(info));
}
