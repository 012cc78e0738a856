// deformbench harness: `verify SCENE`: the scene's reference solved twice on one mesh, by
// reference_fem and by the calculix plugin (CalculiX's ccx, an independent nonlinear FEM), and
// the two compared at every compared instant.
//
// Both solvers get the mesh parameters of the scene's reference (elements, edge_length,
// refine_surface, conform_fixed, element_order, material), so they solve on the same tets
// (deform/geometry/organ_tets.h, one cache entry), with the same fixed nodes, grasped nodes and
// per-vertex forces. At each compared instant, over the compared vertices V (every surface vertex
// no grasp holds: the held ones are prescribed alike in both),
//     rms_relative = sqrt(mean_V |x_ccx - x_ref|^2) / sqrt(mean_V |x_ref - X|^2),
//     max_relative = max_V |x_ccx - x_ref|          / sqrt(mean_V |x_ref - X|^2),
// x_ref reference_fem's positions, X the rest surface. The goal is rms_relative <= 1%.
//
// Nearly incompressible tissue (nu >= 0.45, neo_hookean P2): reference_fem's default volumetric
// term is then constant per element (mean dilatation, free of locking), which CalculiX's plain
// C3D10 does not have (Debian's ccx has no hybrid elements). So that the comparison checks the
// solver rather than the formulation, reference_fem is compared with volumetric = displacement
// (C3D10's, per quadrature point), and the scene's own formulation is solved as well: its
// difference from that run, formulation_rms_relative / formulation_max_relative, is reported
// beside each instant (not part of the 1% goal).
// Times: wall and CPU (this process and its children: user + system, getrusage) of each solve.
#pragma once

#include <deform/engine/plugin_loader.h>

#include <cmath>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace deform::harness {

struct VerifyOptions {
  std::filesystem::path outDir;
  std::optional<std::filesystem::path> cacheDir;  ///< nullopt: default; empty: no cache
  int maxSteps = -1;
  /// Skip CalculiX's own solve (it does not finish some scenes in hours): the equilibrium check
  /// alone (VerifyEquilibrium).
  bool equilibriumOnly = false;
};

struct VerifySolverTimes {
  double wallS = 0, cpuS = 0;
};

struct VerifyInstant {
  int step = 0;
  double time = 0;
  int vertices = 0;
  double referenceRms = 0;  ///< m, RMS displacement of reference_fem over the vertices
  double rmsDifference = 0, maxDifference = 0;  ///< m
  double rmsRelative = 0, maxRelative = 0;
  VerifySolverTimes reference, calculix;  ///< the solve of this instant
  /// Nearly incompressible scenes: the scene's formulation (mean dilatation) against the
  /// compared reference_fem run (volumetric = displacement), relative as above; NaN otherwise.
  double formulationRmsRelative = NAN, formulationMaxRelative = NAN;
};

/// The equilibrium check of a compared instant: CalculiX's C3D10 (or C3D4) elements evaluated at
/// reference_fem's answer, every node but the fixed ones prescribed there, so ccx solves nothing
/// and needs no Newton iteration (it checks the scenes whose loads ccx's own solve does not
/// reach). The residual is the internal minus the external force at the nodes reference_fem
/// left free (a roller's held axes excluded), relative to the force scale: the largest of the
/// loads' total, the organ's weight and the grasps' forces.
struct VerifyEquilibrium {
  int step = 0;
  double time = 0;
  std::string status;  ///< "ok", or why there is no figure
  int freeNodes = 0;
  double forceScale = 0;          ///< N
  double residualRelative = NAN;  ///< 2-norm of the free nodes' residual forces / forceScale
  double maxRelative = NAN;       ///< the largest node's residual force / forceScale
  /// The largest |grasp force by CalculiX's elements - reference_fem's| / forceScale (NaN
  /// without a grasp).
  double graspForceRelative = NAN;
  VerifySolverTimes calculix;
};

struct VerifySolver {
  std::string plugin;
  nlohmann::ordered_json params;
  std::string status, message;
  std::vector<std::string> notes;
  nlohmann::ordered_json counts;
  double precomputeS = 0;
  VerifySolverTimes total;  ///< every solve of the run (the compared instants and grasp closings)
};

struct VerifyResult {
  std::string sceneFile, sceneName;
  VerifySolver reference, calculix;
  /// Nearly incompressible scenes: the scene's own formulation of reference_fem (status
  /// "not run" otherwise).
  VerifySolver formulation;
  std::vector<VerifyInstant> instants;
  bool agrees = false;  ///< both ran and every instant's rms_relative <= kVerifyGoal
  /// One per reference_fem compared instant (empty when reference_fem did not run).
  std::vector<VerifyEquilibrium> equilibrium;
  /// Every equilibrium check ran and its residual_relative <= kEquilibriumGoal.
  bool equilibriumAgrees = false;
  std::string message;  ///< why there is no comparison, if there is none
  std::vector<std::string> notes;
  std::filesystem::path jsonPath;
};

inline constexpr double kVerifyGoal = 0.01;
inline constexpr double kEquilibriumGoal = 1e-4;

/// Runs both solvers and writes OUT/verify.json (format deformbench-verify/1). Throws
/// InputError for bad input (the scene, a reference that is neither reference_fem nor calculix,
/// a material calculix has no counterpart of); a solver that fails is recorded, not thrown.
VerifyResult runVerify(const std::string& sceneFile, PluginLoader& loader,
                       const VerifyOptions& options);

}  // namespace deform::harness
