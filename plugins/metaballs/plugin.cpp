// The "metaballs" plugin: its parameters, their config (constructionParams; the solver's are
// read in MetaballsModel::init) and the registration of MetaballsModel (metaballs_model.h).
#include "metaballs_model.h"

#include <deform/sdk/registry.h>

namespace deform::metaballs {

std::vector<ParamSpec> metaballsParams() {
  return {
      ParamSpec::integer("spheres", 900, 8, 20000,
                         "sphere budget of the medial-axis packing (stage 1); the final count "
                         "changes by filling and merging"),
      ParamSpec::integer("voxel_resolution", 48, 8, 256,
                         "voxels along the organ's longest side (packing samples, Algorithm 2)"),
      ParamSpec::integer("fill_neighbours", 6, 1, 32, "k nearest neighbours of Algorithm 1"),
      ParamSpec::real("fill_min_radius", "1", 0.5, 0.0, 1.0,
                      "smallest filling sphere, as a fraction of the median radius"),
      ParamSpec::real("attraction_range", "1", 2.0, 0.5, 10.0,
                      "Algorithm 2: reach of a hollow voxel beyond a sphere's surface, in voxels"),
      ParamSpec::integer("optimisation_max_moves", 20000, 0, 10000000,
                         "Algorithm 2: most accepted one-voxel moves"),
      ParamSpec::integer("topology_neighbours", 9, 1, 64, "N of eq. (5)"),
      common_params::iterations(10, 1000, "PBD solver iterations per step"),
      ParamSpec::choice("stiffness_mode", "xpbd", {"xpbd", "classic"},
                        "xpbd: compliance from Young's modulus; classic: stiffness coefficient"),
      common_params::unitStiffness("stiffness", 1.0, 0.01, "classic PBD stretching stiffness"),
      ParamSpec::flag("laplacian", true, "Laplacian coordinate constraints (eqs. 9-11)"),
      common_params::unitStiffness(
          "laplacian_stiffness", 0.5, 0.01,
          "classic: coefficient; xpbd: fraction of E r_m used as stiffness (N/m)"),
      ParamSpec::choice("laplacian_frame", "rotated", {"rotated", "fixed"},
                        "rotated: L_m follows the local rotation; fixed: the paper's world frame"),
      ParamSpec::flag("volume_preservation", true, "local volume preservation by radii (eq. 12)"),
      ParamSpec::choice("skinning_frame", "rotated", {"rotated", "fixed"},
                        "rotated: disp follows the blended sphere rotations; fixed: eq. (16)"),
      ParamSpec::real("skin_threshold", "1", 0.2, 1e-6, 1.0,
                      "T: a sphere is attached when f(d, r) >= T (eq. 13, c = 1)"),
      ParamSpec::integer("skin_max_spheres", 6, 1, 16, "most attached spheres per vertex"),
      common_params::damping(5.0, 1000.0, 0.1, "velocity damping rate"),
  };
}

ConstructionParams constructionParams(const ParamValues& p) {
  ConstructionParams c;
  c.targetSpheres = int(p.integer("spheres"));
  c.voxelResolution = int(p.integer("voxel_resolution"));
  c.fillNeighbours = int(p.integer("fill_neighbours"));
  c.fillMinRadiusRatio = p.real("fill_min_radius");
  c.attractionRangeVoxels = p.real("attraction_range");
  c.maxOptimisationMoves = int(p.integer("optimisation_max_moves"));
  c.topologyNeighbours = int(p.integer("topology_neighbours"));
  return c;
}

}  // namespace deform::metaballs

DEFORM_PLUGIN(registry) {
  deform::ModelInfo info = deform::modelInfo<deform::metaballs::MetaballsModel>(
      "metaballs",
      "Metaballs (overlapping spheres) + PBD with Laplacian and local volume constraints, "
      "skinned surface",
      "Pan, Zhao, Zhao, Hao, Qin 2015, Metaballs-based physical modeling and deformation of "
      "organs for virtual surgery, The Visual Computer 31, doi:10.1007/s00371-015-1092-2",
      {deform::Capability::Grasp, deform::Capability::PointForce, deform::Capability::Gravity,
       deform::Capability::NeedsPrecompute, deform::Capability::Contact,
       deform::Capability::ContactReaction, deform::Capability::Markers,
       deform::Capability::Sliding, deform::Capability::ReactionForce},
      deform::metaballs::metaballsParams());
  // What the harness's sweep, bench and stability run it with (registry.h).
  info.resolution = {"spheres", {100LL, 250LL, 500LL, 900LL, 1600LL}, {100LL, 300LL, 900LL}};
  info.effort = {"iterations", {2LL, 5LL, 10LL, 20LL, 40LL}, {5LL, 20LL}};
  info.presets["bench"] = {{{"spheres", 300LL}}};
  info.presets["stability_quick"] = {{{"spheres", 150LL}}};
  registry.add(std::move(info));
}
