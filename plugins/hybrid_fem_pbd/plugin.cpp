// The "hybrid_fem_pbd" plugin: its parameters, their config (HybridConfig) and the registration
// of HybridModel (hybrid_model.h).
#include <deform/sdk/registry.h>

#include "hybrid_model.h"

namespace deform::hybrid_fem_pbd {

std::vector<ParamSpec> paramSpecs() {
  return {
      common_params::iterations(10, 10000, "Gauss-Seidel sweeps over the surface constraints"),
      common_params::unitStiffness("stretch_stiffness", 1.0, 0.01,
                                   "stretch constraint stiffness (classic PBD)"),
      common_params::unitStiffness("bending_stiffness", 0.5, 0.01,
                                   "bending constraint stiffness (classic PBD)"),
      common_params::bendingModel(
          "surface bending constraint: isometric (Bergou et al. 2006, a constant "
          "stencil per hinge) or the paper's dihedral angle (Eqs. (10)-(11))"),
      common_params::damping(20.0, 1e4, 0.1,
                             "surface velocity damping rate: v <- v exp(-damping dt) each step"),
      ParamSpec::flag("surface_load", true,
                      "the point force also moves its own fine node in the PBD prediction "
                      "(paper Sec. 6.3) besides loading the coarse FEM"),
      ParamSpec::integer(
          "simplification_levels", 1, 1, 4,
          "vertex-cover simplification passes building the coarse surface (paper: 1)"),
      ParamSpec::real("min_collapse_quality", "1", 0.1, 0.0, 0.9,
                      "reject vertex merges leaving a triangle of lower quality "
                      "4 sqrt(3) A / sum l^2"),
      ParamSpec::real("tet_edge_factor", "1", 1.0, 0.25, 8.0,
                      "interior tet edge length of the coarse volume mesh, relative to the coarse "
                      "surface's mean edge length"),
      ParamSpec::real("cut_snap", "1", 0.1, 0.0, 0.3,
                      "incision: intersection points within this barycentric distance of a "
                      "vertex or edge snap to it"),
      common_params::precision(
          "number type of the surface projection (isometric bending; positions "
          "relative to the organ's centre) and of the stored grasp response of "
          "the coarse FEM; state between steps and the FEM solve stay double"),
  };
}

HybridConfig configFromParams(const ParamValues& p) {
  HybridConfig c;
  c.iterations = static_cast<int>(p.integer("iterations"));
  c.stretchStiffness = p.real("stretch_stiffness");
  c.bendingStiffness = p.real("bending_stiffness");
  c.bending = p.choiceAs<HybridBending>("bending_model", {{"isometric", HybridBending::Isometric},
                                                          {"dihedral", HybridBending::Dihedral}});
  c.damping = p.real("damping");
  c.surfaceLoad = p.flag("surface_load");
  c.simplificationLevels = static_cast<int>(p.integer("simplification_levels"));
  c.minCollapseQuality = p.real("min_collapse_quality");
  c.tetEdgeFactor = p.real("tet_edge_factor");
  c.cutSnap = p.real("cut_snap");
  c.precision = p.choiceAs<HybridPrecision>(
      "precision", {{"float32", HybridPrecision::Float32}, {"float64", HybridPrecision::Float64}});
  return c;
}

}  // namespace deform::hybrid_fem_pbd

DEFORM_PLUGIN(registry) {
  using C = deform::Capability;
  deform::ModelInfo info = deform::modelInfo<deform::hybrid_fem_pbd::HybridModel>(
      "hybrid_fem_pbd",
      "Hybrid mesh: linear FEM on a coarse tet mesh (vertex-cover simplified surface) drives "
      "PBD stretch/bending on the fine surface; small incisions",
      "A Hybrid Model Method for Accurate Surface Deformation and Incision Based on FEM and PBD, "
      "Scientific Programming 2021, article 8343312 (hindawi.com/journals/sp/2021/8343312)",
      {C::Grasp, C::PointForce, C::Gravity, C::ReactionForce, C::Cut, C::NeedsPrecompute,
       C::Contact, C::Markers, C::Sliding},
      deform::hybrid_fem_pbd::paramSpecs());
  // What the harness's sweep, bench and stability run it with (registry.h).
  // The coarse FEM's resolution: fewer vertex-cover passes leave a finer coarse surface.
  info.resolution = {"simplification_levels", {4LL, 3LL, 2LL, 1LL}, {3LL, 2LL, 1LL}};
  info.effort = {"iterations", {2LL, 5LL, 10LL, 20LL, 40LL}, {5LL, 20LL}};
  info.presets["bench"] = {{}};
  info.presets["bench_8k"] = {{}};
  registry.add(std::move(info));
}
