// Metaballs plugin: the model class (state only; the maths is in the kernels). Pan, Zhao, Zhao,
// Hao, Qin 2015, "Metaballs-based physical modeling and deformation of organs for virtual
// surgery", The Visual Computer 31, doi:10.1007/s00371-015-1092-2.
//
// nodes() are the sphere centres; surface() is the organ's input surface skinned to the spheres
// (eqs. 13-16). Each step (Algorithm 3): explicit prediction of the centres under gravity and
// point loads, damping, then `iterations` Gauss-Seidel sweeps of the stretching constraints (eqs.
// 6-8) and the Laplacian coordinate constraints (eqs. 9-11); velocities from the position change;
// local volume preservation (eq. 12) on the spheres under interaction (grasped or loaded) and their
// linked spheres; skinning. Fixed and grasped spheres are kinematic (inverse mass 0).
//
// Surface mapping (SOFA's Mapping): the skinning, v = sum_i w_vi c_i + (sum r' / sum r) R_v disp_v,
// is linear in the centres c for given radii and rotations, with J = W (the skinning weights).
// Loads: every per-vertex share f_v of the harness's patch goes to the vertex's spheres as
// W^T f (w_vi f_v on sphere i). Grasps hold organ surface vertices: the spheres that carry them
// (every sphere with a non-zero weight in a grasped vertex's row of W, the carrying set C) are
// kinematic, moved by the damped least-squares correction (metaballs_model.cpp, dampedInverse)
//     dc_C = W_C^+ (t - v)
// twice per step: before the sweeps from the surface at the step's start (so the constraints see
// the grasp), and after the skinning from the skinned grasped vertices, whose change is then
// exactly W dc (the radii and rotations of the step kept), so the grasped vertices end on their
// targets whenever W_C's rows can reach them (they can when the targets move rigidly and the
// skinning offsets do not change within the jaws: the carrying spheres keep their rotations of
// the closing while held, as the jaws do not turn the tissue they hold; the radii still change,
// measured residual 0.1-0.4 mm on the liver lift).
// Sliding plates (GraspInput::slideNormal, along a coordinate axis a): a correction on coordinate
// a alone, one shift of all carrying spheres fitted to the gaps t_a - v_a (the plate moves
// rigidly; a minimum-norm W_C^+ pulled them apart), gives each carrying sphere a target;
// the spheres stay free (their inverse mass kept) and their coordinate a is put on it after the
// prediction and after every sweep, the other two left to the constraints; after the skinning the
// correction along a is applied again as for a grasp (their radii and rotations kept too: the
// plate holds the face it presses flat, so the tissue under it does not turn).
// Reaction force (graspForces): the constraints keep their accumulated multipliers over a step's
// sweeps (XPBD, and the same sums in classic mode), so the force each constraint exerts on a
// sphere is g lambda / dt^2 (g its gradient there: a link's unit direction, +-1; a Laplacian
// constraint's +1 on its centre, -1/n on each neighbour), exactly the momentum it gave the free
// spheres per step, over dt, with the sign of Newton's third law (as pbd's computeGraspForces).
// A grasp's force is the sum over its carrying spheres (a sphere carrying several grasps' vertices
// is shared by its skinning weights on them); a sliding plate's is the axis component over its
// carrying spheres (the plate holds that coordinate only).
#pragma once

#include "construction.h"
#include "skinning.h"
#include "solver_kernels.h"

#include <deform/sdk/model.h>
#include <deform/sdk/registry.h>

#include <vector>

namespace deform::metaballs {

enum class StiffnessMode { Classic, Xpbd };
enum class Frame { Rotated, Fixed };

std::vector<ParamSpec> metaballsParams();
/// Construction parameters from resolved plugin parameters.
ConstructionParams constructionParams(const ParamValues& p);

class MetaballsModel final : public Model {
 public:
  void init(const ModelSetup& setup) override;
  StepStatus step(const StepInput& in) override;
  const MatX3& nodes() const override { return m_x; }
  const MatX3& surface() const override { return m_surface; }
  void reset() override;
  Counts counts() const override;
  PhaseTimes phaseTimes() const override;
  NumericCounters numericCounters() const override;
  /// Markers through the spheres' skinning (eqs. 13-16, as the surface): each point attached to
  /// the spheres whose field reaches it, with its offset from their weighted centre.
  void bindMarkers(const MatX3& rest) override;
  MatX3 markers() const override;
  /// Per grasp of the last step: the constraint forces on its carrying spheres (header comment).
  std::vector<Vec3> graspForces() const override { return m_graspForces; }

  const Metaballs& metaballs() const { return m_mb; }
  const VecX& radii() const { return m_r; }
  const VecX& restRadii() const { return m_mb.spheres.radii; }
  const Skinning& skinning() const { return m_skin; }
  bool constructionCacheHit() const { return m_cacheHit; }

  /// Phase times of the last step (ms), without the map phaseTimes() builds.
  struct Phases {
    double pbd = 0, laplacian = 0, volume = 0, rotations = 0, skinning = 0;
  };
  const Phases& lastPhases() const { return m_phases; }
  /// Use the AVX-512 kernels when the CPU has them (default); results are identical either way.
  void setSimd(bool on) { m_simd = on; }

 private:
  void computeRotations();
  /// Grasped surface vertices of `in` -> m_graspVerts, m_graspTargets; rebuilds the carrying
  /// spheres and W_C^+ when the grasped set changes.
  void collectGrasps(const StepInput& in);
  /// dc_C = W_C^+ (t - v) for the current m_surface (into m_graspDc).
  void graspCorrection();
  /// The sliding plates of `in` -> m_sliding (vertices a bonded grasp holds stay bonded; spheres
  /// fixed or carrying a bonded grasp are left out); rebuilds a plate's carrying set and W_C^+
  /// when its vertices or the bonded set change. After collectGrasps().
  void collectSliding(const StepInput& in);
  /// The carrying spheres' shift along the axis of sliding set k for the current m_surface (one
  /// value for all of them, least squares over the vertices' gaps t_a - v_a).
  VecX slidingCorrection(size_t k) const;
  /// Puts the sliding spheres' axis coordinate in the padded rows P on their targets.
  void holdSliding(Real* P) const;
  /// The step's kinematic spheres: fixed ones at rest; the carrying spheres of the grasped
  /// vertices moved by dc_C = W_C^+ (t - v) from the surface at the step's start, into P; the
  /// sliding plates' carrying spheres given their axis targets (holdSliding).
  void placeHeldSpheres(const StepInput& in, Real* P);
  /// After the skinning: the radii and rotations of the step moved the held vertices off their
  /// targets, so the carrying spheres are corrected again (along each sliding plate's axis
  /// alone); with the radii and rotations kept, the skinned surface changes by exactly W dc.
  void correctHeldAfterSkinning(Real dt);
  /// The step's parts (step() calls them in this order): the loads as sphere forces W^T f
  /// (m_f; the spheres they touch in m_contacted); the constraints' per-step constants and
  /// Laplacian targets; after the sweeps, the radii of eq. (12).
  void applyLoads(const StepInput& in);
  void prepareConstraints(Real dt);
  void updateRadii();
  /// m_vertStart / m_vertOf / m_vertW: the vertices each sphere skins (the transpose of W).
  void buildSkinTranspose();
  /// m_graspForces from the multipliers of the step's sweeps (after them, at the new centres).
  void computeGraspForces(const StepInput& in, Real dt);

  Metaballs m_mb;
  Skinning m_skin;
  MatX3 m_restSurface;
  bool m_cacheHit = false;

  // parameters
  int m_iterations = 10;
  StiffnessMode m_mode = StiffnessMode::Xpbd;
  Real m_stiffness = 1.0;  // classic, corrected for the iteration count
  bool m_laplacian = true;
  Real m_lapStiffness = 0.5;
  Frame m_lapFrame = Frame::Rotated;
  Frame m_skinFrame = Frame::Rotated;
  bool m_volume = true;
  Real m_damping = 5.0;

  // rest data
  MatX3 m_x0;
  VecX m_invMass;  // 1 / m_i
  std::vector<uint8_t> m_fixed;
  std::vector<int> m_fixedList;
  std::vector<Real> m_linkRest, m_linkAlpha;  // per link: d (eq. 6), XPBD compliance (m/N)
  std::vector<int> m_adjStart, m_adj;         // CSR adjacency of the links
  MatX3 m_lapRest;                            // L_m (eq. 10), #S by 3
  VecX m_lapAlpha;                            // XPBD compliance of each Laplacian constraint
  VecX m_restSumD;                            // sum d(c_m) over linked spheres (eq. 12)

  StretchBatches m_batches;     // links by colour (solver_kernels.h)
  std::vector<Real> m_restOff;  // #adj*3: x0_i - x0_m for each adjacency entry (rotations)

  // state
  MatX3 m_x, m_v, m_f;
  MatX3 m_p;               // contact only: the padded predicted positions as rows (see step())
  std::vector<Real> m_p4;  // (#S+1)*4 predicted positions, row #S the padding dummy
  VecX m_r;
  RotationBatch m_rotBatch;  // per-sphere A and warm-started quaternions
  std::vector<Real> m_rot;   // #S*9 row-major rotations
  std::vector<uint8_t> m_kin;
  std::vector<Real> m_wEff;  // #S+1 inverse masses this step (0: kinematic, dummy)
  StretchStepData m_sdata;
  LaplacianStepData m_ldata;
  Real m_alphaDt = -1;         // dt the alpha~ arrays were computed for
  std::vector<Real> m_frames;  // #S*16 sphere records for the skinning
  Real m_skinThreshold = 0.2;
  int m_skinMaxSpheres = 4;
  Skinning m_markerSkin;  // bindMarkers(): the markers' skinning
  std::vector<Real> m_volFactorSum;
  std::vector<int> m_volCount, m_contacted;
  MatX3 m_surface;
  std::vector<int> m_vertStart, m_vertOf;  // CSR sphere -> skinned vertices
  std::vector<Real> m_vertW;               // and the vertex's weight on the sphere

  // grasps through the skinning (per step, allocated on change only)
  std::vector<int> m_graspVerts;  // grasped surface vertices, first grasp first
  MatX3 m_graspTargets;           // their targets
  std::vector<int> m_mapVerts;    // the grasped set m_carry / m_WcPinv were built for
  std::vector<int> m_carry;       // carrying spheres (sorted, not fixed)
  MatX m_WcPinv;                  // #carrying x #grasped vertices
  std::vector<Real> m_carryRot;   // #carrying*9: their rotations when the grasp closed
  std::vector<Real> m_carryR;     // #carrying: their radii when the grasp closed
  MatX3 m_graspGap, m_graspDc;
  std::vector<GraspInput> m_bondedScratch;  // the bonded grasps of a step with sliding ones
  bool m_bondedChanged = false;             // the bonded grasped set changed this step
  /// A sliding plate (one grasp): its vertices, the axis of its normal and their targets along
  /// it; the carrying spheres, W_C^+ and their radii at the closing (rebuilt on change); this
  /// step's target coordinate of each carrying sphere.
  struct SlidingSet {
    std::vector<int> verts;
    int axis = -1;
    VecX targets;
    std::vector<int> carry;
    VecX share;                    // #verts: each vertex's total weight on the carrying spheres
    std::vector<Real> radii, rot;  // radii, rotations (9 each) at the closing
    VecX carryTarget;
  };
  std::vector<SlidingSet> m_sliding;
  std::vector<Vec3> m_graspForces;  // N, per grasp of the last step
  MatX3 m_heldForce;                // #S by 3 scratch: constraint force on each held sphere
  std::vector<int> m_heldList;      // the carrying spheres of this step (bonded, then sliding)
  Phases m_phases;
  long long m_degenerate = 0;
  bool m_simd = true;
};

}  // namespace deform::metaballs
