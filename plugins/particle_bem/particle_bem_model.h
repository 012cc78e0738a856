// particle_bem: the model class. Zhu, Gu & Zhou 2010, "Particle-Based Deformable Modeling with
// Pre-computed Surface Data in Real-Time Surgical Simulation".
//
// guidance = true (the paper's surface-guided organ, §5): nodes() are the particles: first the
// surface particles (the vertices of the coarse BEM surface), then the interior physics points.
// Each step: sparse traction vector -> U = M P (eq. 6) -> damped virtual springs pull every
// particle to its target (surface particles: X + U; interior particles: X + inverse-distance
// weighted U of their 8 nearest coarse nodes) -> the fine organ surface follows the coarse
// surface particles (barycentric interpolation, by default enriched with the one-ring recovered
// displacement gradients: guided_particles.h, SurfaceTransfer). See guided_particles.h,
// bem_assembly.h.
//
// guidance = false (the paper's pure particle model for small tissues, §4): nodes() are the
// interior physics points, moved by MLS point-based elasticity (sph_elasticity.h) with gravity,
// symplectic Euler; the fine surface is skinned to the particles to first order,
// x_v = sum_j w_vj (x_j + F_j (X_v - X_j)) / sum_j w_vj over the 8 nearest particles.
//
// Surface mapping (SOFA's Mapping), interaction as the harness defines it on the organ surface:
// the fine surface is x_s = X_s + J u with J the transfer's matrix (guided: transferRow, linear in
// the coarse displacements; pure: the skinning weights w_vj, with the F_j of the step kept).
//  - Loads: the harness's per-vertex forces f_v reach the model as J^T f: nodal forces on the
//    coarse surface, turned into tractions by patch_traction and applied through their
//    precomputed displacement response (guided); forces on the particles (pure).
//  - Grasps: the particles carrying the grasped fine vertices (every node with a non-zero entry in
//    their rows of J, the carrying set C) are prescribed at x_C + J_C^+ (t - x_s) (the
//    minimum-norm correction, least squares with more vertices than nodes), so the grasped
//    vertices land on their targets; in the guided model the BEM solve then finds the tractions
//    that hold C there. The pure model corrects C again after its skinning (F_j changed in the
//    step), with the surface moved by exactly J dx.
//  - Sliding plates (GraspInput::slideNormal, along a coordinate axis a): the same correction on
//    coordinate a alone, dx_C,a = J_C^+ (t_a - x_s,a), prescribes the carrying nodes' coordinate
//    a only. Guided: the traction solve holds that one component of U (a normal traction, no
//    tangential one: a frictionless plate), the nodes follow the solved U in full. Pure: the
//    nodes' coordinate a is set after the integration and corrected after the skinning, the
//    other two integrate freely.
#pragma once

#include "bem_assembly.h"
#include "distance_field.h"
#include "guided_particles.h"
#include "spatial_hash.h"
#include "sph_elasticity.h"

#include <deform/sdk/model.h>
#include <deform/sdk/registry.h>

#include <array>
#include <functional>
#include <map>
#include <memory>

namespace deform::particle_bem {

/// The plugin's parameters (plugin.cpp): units, ranges and meaning.
std::vector<ParamSpec> paramSpecs();

class ParticleBemModel final : public Model {
 public:
  void init(const ModelSetup& setup) override;
  StepStatus step(const StepInput& in) override;
  const MatX3& nodes() const override { return m_x; }
  const MatX3& surface() const override { return m_surface; }
  void reset() override;
  Counts counts() const override;
  PhaseTimes phaseTimes() const override { return m_times; }
  NumericCounters numericCounters() const override { return m_numeric; }
  /// The force on each grasp's tool (see collectGraspForces); empty after a step whose grasp
  /// traction system was singular.
  std::vector<Vec3> graspForces() const override { return m_graspForces; }
  /// Markers: each follows the inverse-distance (Shepard) weighted displacement of its 8
  /// nearest particles at rest, the rule the guided model's interior particles follow.
  void bindMarkers(const MatX3& rest) override;
  MatX3 markers() const override;

  // For tests, benchmarks and tables.
  bool guided() const { return m_guided; }
  const SurfaceMesh& coarseSurface() const { return m_coarse; }
  const DeformationMatrix& deformationMatrix() const { return m_bem; }
  int surfaceParticles() const { return m_guided ? m_coarse.numVertices() : 0; }
  const std::vector<int>& fixedNodes() const { return m_fixed; }
  Real particleSpacing() const { return m_spacing; }
  /// The particles prescribed by the grasps of the last step (those carrying the grasped
  /// vertices), sorted.
  const std::vector<int>& graspedNodes() const { return m_carry; }

 private:
  void initGuided(const ModelSetup& setup, const SignedDistanceField& sdf, Real volume);
  void initParticles(const ModelSetup& setup, const SignedDistanceField& sdf, Real volume);
  StepStatus stepGuided(const StepInput& in);
  StepStatus stepParticles(const StepInput& in);
  void applyGrasps(const StepInput& in);
  /// Row v of J (see above): (node, weight) pairs.
  std::vector<std::pair<int, Real>> surfaceRow(int v) const;
  /// Grasped fine vertices of `in` -> m_graspVerts / m_graspTargets; rebuilds the carrying set
  /// and J_C^+ when the grasped set changes; prescribes C at x_C + J_C^+ (t - x_s) (m_carryTarget).
  void prescribeGrasps(const StepInput& in);
  /// The sliding plates of `in` -> m_sliding (vertices a bonded grasp holds stay bonded; carrying
  /// nodes a bonded grasp prescribes are left to it); prescribes the carrying nodes' coordinate
  /// along the plate's axis (SlidingSet::carryTarget). After prescribeGrasps().
  void prescribeSliding(const StepInput& in);
  /// The nodes under sliding plates after the integration (guided: onto the solved target; pure:
  /// their axis coordinate onto carryTarget).
  void applySliding(const StepInput& in);
  /// m_graspForces, in the order of in.grasps: per grasp, the sum of nodeForce (the force the
  /// tissue exerts on the tool through that node, N) over the nodes it carries (a node carried by
  /// two bonded grasps counts for the first); a sliding plate's along its axis only (frictionless).
  /// After prescribeGrasps() and prescribeSliding().
  void collectGraspForces(const StepInput& in, const std::function<Vec3(int)>& nodeForce);
  /// The displacement response (3N x 3, m/N) of a load's J^T-mapped forces, cached per spread.
  const MatX& loadResponse(const PointLoad& load);
  /// Contact (deform/sdk/contact.h) on every particle, after the correction.
  void resolveParticleContacts(const StepInput& in);
  /// Display level: the surface follows particles already out of the instruments (no force).
  void projectSurfaceOut(const StepInput& in);

  bool m_guided = true;
  std::string m_source;
  MatX3 m_fineRest;
  Real m_dt = 1e-3;
  Material m_material;
  MatX3 m_rest, m_x, m_v, m_target, m_surface;
  MatX3 m_markerRest;                             ///< bindMarkers()
  std::vector<std::array<int, 8>> m_markerNodes;  ///< their 8 nearest particles at rest
  std::vector<std::array<Real, 8>> m_markerWeights;
  std::vector<int> m_fixed;
  std::vector<char> m_fixedMask, m_kinematic;
  Real m_spacing = 0;
  PhaseTimes m_times;
  NumericCounters m_numeric;

  // guided
  SurfaceMesh m_coarse;
  DeformationMatrix m_bem;
  VecX m_nodalArea;
  SurfaceMap m_map;
  SurfaceTransfer m_transfer = SurfaceTransfer::Gradient;
  GradientTransfer m_gradient;
  std::vector<std::array<int, 8>> m_interiorNodes;
  std::vector<std::array<Real, 8>> m_interiorWeights;
  Real m_springK = 0, m_springC = 0;
  bool m_repulsion = true, m_bemGravity = true;
  Real m_repulsionDistance = 0, m_repulsionStiffness = 0;
  MatX3 m_restCoarse;
  SpatialHash m_hash;
  std::vector<std::pair<int, int>> m_pairs;
  std::vector<std::pair<int, int>> m_verlet;
  MatX3 m_verletRef;
  bool m_verletValid = false;
  SparseTraction m_P;
  PatchTraction m_patchTraction = PatchTraction::Consistent;
  PatchProjection m_patchProjection;
  /// A load's spread (the harness's patch vertices and weights) -> displacement of the coarse
  /// nodes per unit force (3N x 3, m/N): sum_k q_k M(:, 3k..3k+2) with q the tractions of the
  /// nodal shares J^T w (PatchTraction), computed on first use, so a step costs one 3N x 3
  /// product per load.
  struct LoadResponse {
    std::vector<int> vertices;
    std::vector<Real> weights;
    MatX W;
  };
  std::vector<LoadResponse> m_loadResponses;
  VecX m_U, m_patchU, m_graspRhs, m_graspP;
  // grasps through the surface mapping (rebuilt when the grasped set changes)
  std::vector<int> m_graspVerts, m_mapVerts;  // grasped fine vertices; the set J_C was built for
  MatX3 m_graspTargets;
  std::vector<int> m_carry;     // carrying nodes (coarse particles / particles), sorted
  std::vector<int> m_carryCol;  // node -> column in m_carry or -1
  MatX m_JcPinv;                // #carry x #grasped vertices
  MatX3 m_carryTarget, m_graspGap, m_graspDx;
  GraspSolver m_graspSolver;
  std::vector<GraspInput> m_bondedScratch;  // the bonded grasps of a step with sliding ones
  bool m_bondedChanged = false;             // the bonded grasped set changed this step
  /// A sliding plate (one grasp) through the surface mapping: its fine vertices (those no bonded
  /// grasp holds), the axis of its normal, their target coordinates along it; the carrying nodes
  /// and J_C^+ (rebuilt when the vertices or the bonded set change); this step's prescribed
  /// coordinate of each carrying node and its value at the step's start.
  struct SlidingSet {
    std::vector<int> verts;
    int axis = -1;
    VecX targets;
    std::vector<int> carry;  // sorted
    std::vector<int> col;    // node -> column in carry or -1
    MatX pinv;               // #carry x #verts
    VecX carryTarget, carryStart;
  };
  std::vector<SlidingSet> m_sliding;
  std::vector<Vec3> m_graspForces;  ///< N, per grasp of the last step
  /// The nodes m_sliding carries (as of the last step): the repulsion leaves them to the plate.
  /// Pushed along it, the free tangential displacement of a carrying node fed the next step's
  /// repulsion through U (a static response) and the particles never settled (the Truth Cube at
  /// 12.5%: the repulsion list rebuilt on 2156 of 3000 steps).
  std::vector<char> m_slidingMask;
  MatX3 m_coarseDisp;

  // pure particles
  MlsElasticity m_mls;
  VecX m_mass;
  Real m_particleDamping = 0;
  std::vector<Mat3> m_F;
  MatX3 m_forces;
  std::vector<std::array<int, 8>> m_skinNodes;
  std::vector<std::array<Real, 8>> m_skinWeights;
};

}  // namespace deform::particle_bem
