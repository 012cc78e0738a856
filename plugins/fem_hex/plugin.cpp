// The "fem_hex" plugin: its parameters, their config (HexFemConfig) and the registration of
// HexFemModel (hex_fem_model.h gives the method, README.md every choice).
#include "hex_fem_model.h"

#include <deform/sdk/registry.h>

namespace deform::fem_hex {

std::vector<ParamSpec> paramSpecs() {
  return {
      ParamSpec::integer("elements", 967, 1, 2000000,
                         "target number of hexahedra (the cell size is bisected to match it); "
                         "used when cell_size is 0"),
      ParamSpec::real("cell_size", "m", 0.0, 0.0, 10.0,
                      "edge of the cubic hexahedra; 0 = choose it from elements"),
      ParamSpec::choice("formulation", "corotational", {"corotational", "linear"},
                        "corotational (rotation-invariant, R K0 R^T per element) or linear "
                        "small-strain elasticity"),
      ParamSpec::choice("element", "incompatible_modes", {"incompatible_modes", "trilinear"},
                        "element stiffness: incompatible_modes (Wilson's nine internal bending "
                        "modes, condensed: no shear locking) or the plain trilinear hexahedron"),
      ParamSpec::integer("fill_samples", 4, 0, 16,
                         "samples per axis of the volume fraction of the cells the surface "
                         "crosses; their stiffness and mass are scaled by it (at least 0.1), so "
                         "the voxel grid's overhang adds neither; 0: every cell counts whole"),
      ParamSpec::choice("corotational_solver", "pcg", {"pcg", "refactor"},
                        "pcg: CG warm-started (pcg_start), preconditioned by the "
                        "prefactored rest system; refactor: assemble and refactorise R K0 R^T "
                        "every step"),
      ParamSpec::real("rayleigh_mass", "1/s", 0.1, 0.0, 1e4,
                      "Rayleigh damping alpha (D = alpha M + beta K)"),
      ParamSpec::real("rayleigh_stiffness", "s", 0.01, 0.0, 10.0,
                      "Rayleigh damping beta (D = alpha M + beta K)"),
      ParamSpec::real("pcg_tolerance", "1", 1e-3, 1e-15, 1.0,
                      "CG stops when sqrt(r^T D^-1 r) falls below this fraction of the "
                      "right-hand side's scale: max(|M v + h f_ext|, |r0|) in the same norm (r "
                      "residual, r0 the warm start's, D diagonal of the rest system); at least "
                      "one iteration per step"),
      ParamSpec::choice("pcg_preconditioner", "rest", {"rest", "rest_grasped"},
                        "rest: Cholesky of the rest system with the held points' penalty, "
                        "refactorised when the grasped set changes; rest_grasped: the same (kept "
                        "for scenes that name it)"),
      ParamSpec::integer("pcg_max_iterations", 50, 1, 100000, "CG iteration cap per step"),
      ParamSpec::choice("pcg_start", "projected", {"projected", "last_velocity"},
                        "CG's start: projected: the last velocities corrected along the last "
                        "step's change of velocity by its energy-norm optimal step (a smooth "
                        "motion then needs one iteration where it needed two); last_velocity: "
                        "the last velocities"),
      ParamSpec::choice("preconditioner_precision", "float32", {"float16", "float32", "float64"},
                        "number type of the PCG preconditioner's two triangular solves (float32: "
                        "a float copy of a supernodal factor, half its memory traffic; float16: "
                        "a half copy, a quarter, faster but the grasped points and nearly "
                        "incompressible tissue solved less exactly; the CG itself and every "
                        "direct solve stay in double)"),
      ParamSpec::integer("rotation_iterations", 8, 1, 1000,
                         "cap of the warm-started Newton steps of the element rotation extraction "
                         "(1e-9 rad); past it the rotation comes from the SVD of F (numeric "
                         "rotation_svd_fallbacks)"),
      ParamSpec::choice("clamp", "points", {"points", "cells", "nodes"},
                        "points: pin the grid nodes inside the fixed region and hold the clamped "
                        "surface points at rest through the embedding (penalty hold_stiffness); "
                        "cells: also pin every node of the cells carrying a clamped surface "
                        "vertex (the clamp reaches up to a cell beyond the region); nodes: only "
                        "the grid nodes inside the region"),
      ParamSpec::real("hold_stiffness", "1", 1e8, 1.0, 1e10,
                      "penalty stiffness holding the grasped (and with clamp = points the "
                      "clamped) surface points on their targets through the embedding, as a "
                      "multiple of the largest diagonal entry of one hexahedron's stiffness"),
      ParamSpec::choice("cholesky", "auto", {"auto", "simplicial", "supernodal"},
                        "CHOLMOD factorisation kind (auto: CHOLMOD picks supernodal when the "
                        "factor is dense enough)"),
  };
}

HexFemConfig configFromParams(const ParamValues& p) {
  HexFemConfig c;
  c.elements = p.integer("elements");
  c.preconditionerPrecision = p.choiceAs<PreconditionerPrecision>(
      "preconditioner_precision", {{"float64", PreconditionerPrecision::Float64},
                                   {"float32", PreconditionerPrecision::Float32},
                                   {"float16", PreconditionerPrecision::Float16}});
  c.cellSize = p.real("cell_size");
  c.elastic = p.choiceAs<ElasticModel>("formulation", {{"corotational", ElasticModel::Corotational},
                                                       {"linear", ElasticModel::Linear}});
  c.element =
      p.choiceAs<HexElement>("element", {{"incompatible_modes", HexElement::IncompatibleModes},
                                         {"trilinear", HexElement::Trilinear}});
  c.fillSamples = static_cast<int>(p.integer("fill_samples"));
  c.solver = p.choiceAs<CorotationalSolver>(
      "corotational_solver",
      {{"pcg", CorotationalSolver::Pcg}, {"refactor", CorotationalSolver::Refactor}});
  c.rayleighMass = p.real("rayleigh_mass");
  c.rayleighStiffness = p.real("rayleigh_stiffness");
  c.pcgTolerance = p.real("pcg_tolerance");
  c.pcgPreconditioner = p.choiceAs<PcgPreconditioner>(
      "pcg_preconditioner",
      {{"rest", PcgPreconditioner::Rest}, {"rest_grasped", PcgPreconditioner::RestGrasped}});
  c.pcgMaxIterations = static_cast<int>(p.integer("pcg_max_iterations"));
  c.pcgProjectedStart = p.choice("pcg_start") == "projected";
  c.rotationIterations = static_cast<int>(p.integer("rotation_iterations"));
  c.clamp = p.choiceAs<Clamp>(
      "clamp", {{"points", Clamp::Points}, {"cells", Clamp::Cells}, {"nodes", Clamp::Nodes}});
  c.holdStiffness = p.real("hold_stiffness");
  c.cholesky = p.choiceAs<CholeskySolver::Kind>("cholesky",
                                                {{"auto", CholeskySolver::Kind::Auto},
                                                 {"simplicial", CholeskySolver::Kind::Simplicial},
                                                 {"supernodal", CholeskySolver::Kind::Supernodal}});
  return c;
}

}  // namespace deform::fem_hex

DEFORM_PLUGIN(registry) {
  using deform::Capability;
  deform::ModelInfo info = deform::modelInfo<deform::fem_hex::HexFemModel>(
      "fem_hex",
      "Hexahedral FEM on a voxel grid embedding the surface (linear or corotational, implicit "
      "Euler, CHOLMOD)",
      "FEM baseline of Table 2 in Pan et al. 2015, Metaballs-based physical modeling and "
      "deformation "
      "of organs for virtual surgery, The Visual Computer; "
      "corotational: Mueller & Gross 2004, Interactive virtual materials, Graphics Interface; "
      "Nesme et al. 2005, Efficient, physically plausible finite elements, Eurographics short",
      {Capability::Grasp, Capability::PointForce, Capability::Gravity, Capability::ReactionForce,
       Capability::Contact, Capability::ContactReaction, Capability::Markers, Capability::Sliding},
      deform::fem_hex::paramSpecs());
  // What the harness's sweep, bench and stability run it with (registry.h).
  info.resolution = {"elements", {100LL, 300LL, 967LL, 2500LL, 6000LL}, {300LL, 967LL, 2500LL}};
  info.effort = {"pcg_tolerance", {1e-1, 1e-2, 1e-3, 1e-5}, {1e-2, 1e-4}};
  info.presets["bench"] = {{}};
  info.presets["bench_8k"] = {{}};
  info.presets["stability_quick"] = {{{"elements", 300LL}}};
  registry.add(std::move(info));
}
