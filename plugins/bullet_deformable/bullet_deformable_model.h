// bullet_deformable: Bullet's implicit FEM deformable body (btSoftBody with tetrahedra in a
// btDeformableMultiBodyDynamicsWorld driven by btDeformableBodySolver; Bullet Physics SDK 3.24,
// E. Coumans et al.; the deformable solver by Xuchen Han, 2019) as a peer baseline for our FEM
// models. Each step is backward Euler, linearised about the start of the step:
//
//   (M - dt D - dt^2 K) dv = dt (f(x_n + dt v_n) + D v_n + f_ext),  v+ = v_n + dv,  x+ = x_n + dt
//   v+
//
// solved by Bullet's conjugate gradient in its projection form (fixed and kinematic nodes' dv
// projected to 0; up to `krylov_iterations`, relative tolerance `krylov_tolerance`; preconditioned
// by the factor of that matrix at rest, or not at all as in Bullet: `preconditioner`), repeated
// for `newton_iterations` Newton steps (Bullet's default 1). Elasticity per tetrahedron with
// constant deformation gradient F = Ds Dm^-1, either
//   linear_elasticity (btDeformableLinearElasticityForce): P = 2 mu eps + lambda tr(eps) I,
//                      eps = (F + F^T)/2 - I (small strain, not rotation invariant), damping
//                      D = alpha M + beta K (Rayleigh form);
//   neo_hookean       (btDeformableNeoHookeanForce): Bullet's stable Neo-Hookean (Smith, de Goes,
//                      Kim 2018, doi:10.1145/3180491), damping D = beta K only.
// mu = E / (2 (1 + nu)), lambda = E nu / ((1 + nu)(1 - 2 nu)). Node masses are lumped:
// density x tet volume / 4 per node. Gravity is btDeformableGravityForce.
//
// Fixed nodes have inverse mass 0 (Bullet then keeps their velocity; it is 0). Grasped nodes get
// inverse mass 0 and the velocity (target - x) / dt before the step (kinematic), their mass is
// restored on release. Point loads enter as the velocity impulse dt f / m before the step, which
// equals a constant external force in the backward Euler step above. Contact with instruments:
// the SDK's shared response on the tet nodes after Bullet's step (bullet_common/bullet_peer_step.h;
// README.md, "Contact with instruments").
//
// Reaction force (graspForces): the force the tissue exerts on a grasp or plate is the force its
// elements exert on the held nodes, f_i = -dPsi/dx_i - D v_i, summed over the grasp's nodes, with
// Bullet's own force objects (addScaledForces at scale 1) evaluated at the end-of-step positions
// (the deformation gradients refreshed for it and Bullet's copies restored, so the dynamics do not
// change). A sliding plate's nodes keep their mass and are put back on the plate after the step,
// so the elastic force there is not what the body transmits; its force is the normal momentum the
// plate takes back from them, m (v . n - v_plate) / dt per node, along the normal (frictionless).
#pragma once

#include <bullet_peer_step.h>
#include <deform/geometry/tet_embedding.h>
#include <deform/sdk/model.h>
#include <deform/sdk/params.h>

#include <memory>
#include <vector>

namespace deform::bullet_deformable {

enum class ElasticForce { LinearElasticity, NeoHookean };
/// The preconditioner of Bullet's CG (model .cpp, CgPreconditioner).
enum class CgPreconditioning { RestFactor, None };

/// Resolved parameters (see paramSpecs() for units, ranges and meaning).
struct DeformableConfig {
  ElasticForce force = ElasticForce::NeoHookean;
  long long targetTets = 6000;  ///< tets of the shared Gmsh mesher when the organ has no volume
  Real dampingAlpha = 0.01;     ///< 1/s, mass-proportional (linear_elasticity only)
  Real dampingBeta = 0.01;      ///< s, stiffness-proportional
  int newtonIterations = 1;
  int krylovIterations = 300;
  Real krylovTolerance = 1.1920928955078125e-07;  ///< FLT_EPSILON, see paramSpecs()
  CgPreconditioning preconditioner = CgPreconditioning::RestFactor;
};

std::vector<ParamSpec> paramSpecs();
DeformableConfig configFromParams(const ParamValues& params);

/// Lame parameters (mu, lambda) in Pa of an isotropic material.
std::pair<Real, Real> lameParameters(const Material& m);
/// Lumped node masses rho V_t / 4 (kg), #nodes.
VecX lumpedMasses(const TetMesh& mesh, Real density);

class BulletDeformableModel final : public Model {
 public:
  BulletDeformableModel();
  ~BulletDeformableModel() override;

  void init(const ModelSetup& setup) override;
  /// init() from a ready tet mesh (tests and benchmarks). surfaceNode[i]: node of surface
  /// vertex i. fixedNodes: pinned nodes.
  void init(const TetMesh& mesh, std::vector<int> surfaceNode, const Material& material,
            const DeformableConfig& config, Real dt, const std::vector<int>& fixedNodes);

  StepStatus step(const StepInput& in) override;
  const MatX3& nodes() const override { return m_x; }
  const MatX3& surface() const override { return m_surface; }
  void reset() override;
  Counts counts() const override;
  PhaseTimes phaseTimes() const override { return m_phase; }
  /// Bullet's CG since init or reset: solves, iterations, solves that reached the cap.
  NumericCounters numericCounters() const override;
  /// Per grasp: the elastic and damping forces Bullet's force object computes at the held nodes
  /// (positions at the end of the step), summed; a sliding plate: the normal momentum it takes
  /// back per step / dt (header comment). Computed when first asked after a step (one more
  /// evaluation of Bullet's forces, kept off the step for runs that never ask).
  std::vector<Vec3> graspForces() const override;
  /// Markers: barycentric coordinates in the rest tet that contains each point, following that
  /// tet's nodes (deform/geometry/tet_embedding.h, as pbd's and massspring's volume networks).
  void bindMarkers(const MatX3& rest) override {
    m_markerEmbedding = embedInTets(m_mesh.V, m_mesh.T, rest);
  }
  MatX3 markers() const override { return embeddedPositions(m_markerEmbedding, m_x, m_mesh.T); }

  const TetMesh& mesh() const { return m_mesh; }
  const VecX& masses() const { return m_mass; }

 private:
  struct World;
  void build();
  void computeGraspForces(std::size_t numGrasps) const;

  DeformableConfig m_config;
  Real m_dt = 0;
  Material m_material;
  TetMesh m_mesh;
  MatX2i m_edges;
  MatX3i m_boundary;
  std::vector<int> m_surfaceNode;
  VecX m_mass;
  std::vector<int> m_fixed;

  std::unique_ptr<World> m_world;
  bullet_common::PeerStepState m_tail;  // grasped set, divergence box, contact scratch
  MatX3 m_x;
  MatX3 m_surface;
  PhaseTimes m_phase;
  mutable std::vector<Vec3> m_graspForces;  ///< N, per grasp of the last step
  mutable bool m_graspForcesStale = false;  ///< the last step's are not computed yet
  std::size_t m_stepGrasps = 0;             ///< the last step's number of grasps
  std::vector<Vec3> m_slidingForces;  ///< N, per grasp: the sliding plates' normal impulse / dt
  TetEmbedding m_markerEmbedding;     ///< bindMarkers()
};

}  // namespace deform::bullet_deformable
