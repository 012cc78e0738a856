// The "particle_bem" plugin: its parameters and the registration of ParticleBemModel
// (particle_bem_model.h) with its "static_accuracy" measure (static_accuracy.h), the paper's
// Table 2 without a model run. The model reads its parameters itself (ParamValues in init()).
#include "particle_bem_model.h"
#include "static_accuracy.h"

#include <deform/sdk/registry.h>

namespace deform::particle_bem {

std::vector<ParamSpec> paramSpecs() {
  return {
      ParamSpec::flag("guidance", true,
                      "true: BEM surface-guided particles (organs); false: pure MLS particle "
                      "elasticity (small tissues)"),
      ParamSpec::integer("points", 400, 8, 200000,
                         "interior physics points (lattice inside the organ)"),
      ParamSpec::integer("coarse_vertices", 600, 12, 20000,
                         "vertices of the coarse BEM surface = surface particles"),
      ParamSpec::choice("patch_traction", "consistent", {"consistent", "lumped"},
                        "how the harness's per-vertex load forces, mapped to the coarse nodes by "
                        "J^T, become nodal tractions of the linear traction space: consistent = "
                        "L2 projection (consistent mass matrix, the nodal loads kept), lumped = "
                        "force / lumped nodal area (spreads a patch wider on coarse elements)"),
      ParamSpec::real("spring_stiffness", "1/s^2", 2500.0, 1e-3, 1e9,
                      "virtual spring stiffness per unit mass pulling particles to BEM targets")
          .calibrate(1, 10000000.0, ParamScale::Log),
      ParamSpec::real("spring_damping", "1/s", 100.0, 0.0, 1e7,
                      "virtual spring damping per unit mass (viscosity / creep)")
          .calibrate(0.1, 100000.0, ParamScale::Log),
      ParamSpec::real("particle_damping", "1/s", 2.0, 0.0, 1e6,
                      "mass-proportional damping of the pure particle model")
          .calibrate(0.01, 10000.0, ParamScale::Log),
      ParamSpec::real("kernel_radius", "1", 2.0, 1.2, 4.0,
                      "MLS kernel support h in lattice spacings (pure particle model)"),
      ParamSpec::flag("repulsion", true,
                      "surface-particle repulsion forces enter the traction vector"),
      ParamSpec::flag("bem_gravity", true,
                      "gravity in the guided model through a precomputed particular solution "
                      "(the paper ignores gravity)"),
      ParamSpec::flag("conforming_support", true,
                      "cut the coarse surface along the fixed boxes' faces before decimation "
                      "and keep that boundary, and let the clamp's reaction act on the support "
                      "faces only (false: decimate the organ as is, nodal clamps)"),
      ParamSpec::flag("singular_support", true,
                      "with conforming_support: the clamp's reaction on the support faces along "
                      "its edge carries the edge singularity s^(-1/2) (false: linear reaction "
                      "elements throughout, which converge to the same solution more slowly)"),
      ParamSpec::choice("surface_transfer", "gradient", {"gradient", "linear"},
                        "how the fine surface follows the coarse surface particles: gradient = "
                        "half-gradient Hermite blend with one-ring recovered gradients, linear = "
                        "barycentric interpolation on the closest coarse triangle"),
      ParamSpec::integer("duffy_order", 6, 2, 16,
                         "Gauss-Legendre order of the Duffy rule on singular triangles"),
  };
}

}  // namespace deform::particle_bem

DEFORM_PLUGIN(registry) {
  using C = deform::Capability;
  deform::ModelInfo info = deform::modelInfo<deform::particle_bem::ParticleBemModel>(
      "particle_bem",
      "particles guided by a precomputed BEM deformation matrix (pure MLS particles when "
      "guidance=false)",
      "Zhu B., Gu L., Zhou Z.: Particle-Based Deformable Modeling with Pre-computed Surface Data "
      "in Real-Time Surgical Simulation (Image Guided Surgery and Therapy Lab, Shanghai Jiao Tong "
      "University; no DOI given in the paper)",
      {C::Grasp, C::PointForce, C::Gravity, C::NeedsPrecompute, C::Contact, C::Markers, C::Sliding,
       C::ReactionForce},
      deform::particle_bem::paramSpecs());
  // What the harness's sweep, bench and stability run it with (registry.h).
  // The BEM surface's resolution; the particles follow it with no iterative solve (no effort).
  info.resolution = {
      "coarse_vertices", {150LL, 300LL, 600LL, 1200LL, 2400LL}, {150LL, 300LL, 600LL}};
  info.presets["bench"] = {{{"coarse_vertices", 300LL}}};
  info.presets["stability_quick"] = {{{"coarse_vertices", 200LL}, {"points", 150LL}}};
  info.measures["static_accuracy"] = deform::particle_bem::staticAccuracyMeasure;
  registry.add(std::move(info));
}
