// A CalculiX input deck (.inp) for one quasi-static solve of a tet mesh, and the displacements
// read back from the .dat file its *NODE PRINT writes.
//
// Elements: C3D4 (4-node) or C3D10 (10-node) tets. CalculiX orders a C3D10's midside nodes as
// the edges (1,2), (2,3), (3,1), (1,4), (2,4), (3,4) of its corners (CalculiX User's Manual,
// element C3D10), deformbench's 10-node rows as (0,1), (0,2), (0,3), (1,2), (1,3), (2,3)
// (deform/geometry/organ_tets.h): kCcxC3D10Order maps one onto the other. Corners 1-2-3 are
// counter- clockwise seen from corner 4, i.e. the tet's signed volume is positive. Materials:
// `*HYPERELASTIC, NEO HOOKE` with C10 = mu / 2, D1 = 2 / kappa, whose energy U = C10 (J^{-2/3} I1 -
// 3) + (J - 1)^2 / D1 is deform/kernels/fem_tet.h's NeoHookeanMaterial; or
// `*ELASTIC` (E, nu) solved without NLGEOM, the small-strain LinearMaterial.
#pragma once

#include <deform/sdk/types.h>

#include <array>
#include <string>
#include <utility>
#include <vector>

namespace deform::calculix {

/// Position in deformbench's 10-node row of each CalculiX C3D10 node 1..10.
inline constexpr int kCcxC3D10Order[10] = {0, 1, 2, 3, 4, 7, 5, 6, 8, 9};

enum class CcxMaterial { Linear, NeoHookean };

/// The part of a deck that stays the same from solve to solve.
struct CcxModel {
  MatX3 nodes;               ///< #N by 3 rest positions, m (CalculiX node i + 1)
  Eigen::MatrixXi elements;  ///< #T by 4 or 10 node rows (deformbench order, see above)
  CcxMaterial material = CcxMaterial::NeoHookean;
  Real young = 0, poisson = 0, density = 0;  ///< Pa, 1, kg/m^3
  /// Per node: which displacement components (x, y, z) are held at zero (the fixed region; a
  /// roller holds one or two).
  std::vector<std::array<bool, 3>> fixedDofs;
};

/// The loads of one solve, from the rest state.
struct CcxLoads {
  std::vector<std::pair<int, Vec3>> displacements;  ///< (node, prescribed displacement, m)
  /// ((node, axis 0..2), prescribed displacement along that axis, m): a sliding plate's normal
  /// component, the other two free. A node in `displacements` too is held there.
  std::vector<std::pair<std::pair<int, int>, Real>> dofDisplacements;
  std::vector<std::pair<int, Vec3>> forces;  ///< (node, force, N), summed per node
  Vec3 gravity = Vec3::Zero();               ///< m/s^2
};

struct CcxIncrements {
  Real initial = 0.25;  ///< first increment, as a fraction of the step
  Real minimum = 1e-5;  ///< smallest increment before ccx gives up
  Real maximum = 1.0;   ///< largest increment
  int maxIncrements = 1000;
  /// *CONTROLS, PARAMETERS=FIELD: R_n (largest residual over the average force) and C_n = 10 x
  /// it (largest displacement correction over the increment's displacement).
  Real residualTolerance = 1e-5;
};

/// The model part: *NODE, *ELEMENT, *MATERIAL, *SOLID SECTION and the fixed dofs.
std::string ccxModelDeck(const CcxModel& model);

/// One *STEP (NLGEOM for the Neo-Hookean material) with the loads, ramped from rest, and a
/// *NODE PRINT of every node's displacement and reaction force (RF) at the end of the step.
std::string ccxStepDeck(const CcxModel& model, const CcxLoads& loads, const CcxIncrements& inc);

/// The last "displacements (vx,vy,vz) ... and time T" table of a .dat file as #N by 3 (m);
/// `time` gets its T. Throws std::runtime_error when there is none or a node is missing.
MatX3 ccxLastDisplacements(const std::string& dat, int numNodes, double& time);

/// The last "forces (fx,fy,fz) ... and time T" table (RF: the force each node's constraints
/// exert on the tissue, N) as #N by 3, as ccxLastDisplacements.
MatX3 ccxLastReactionForces(const std::string& dat, int numNodes, double& time);

}  // namespace deform::calculix
