// bullet_softbody: Bullet's classic soft body (btSoftBody, Bullet Physics SDK, E. Coumans; the
// soft body by N. Presson) on the organ surface, as a peer baseline for our PBD. It is a position
// based solver in the family of Mueller et al. 2007 (PBD, doi:10.1016/j.jvcir.2007.01.005):
//
//   predict    v += dt (g + f / m),  x* = x + dt v                (btSoftBody::predictMotion)
//   project    `iterations` Gauss-Seidel sweeps over the links:   (btSoftBody::PSolve_Links)
//                k = kLST (L0^2 - |d|^2) / ((w_a + w_b) (L0^2 + |d|^2)),  d = x_b - x_a
//                x_a -= k w_a d,  x_b += k w_b d
//   velocity   v = (1 - kDP) (x* - x_n) / dt                       (btSoftBody::solveConstraints)
//
// plus Bullet's volume conservation force, applied before the prediction (btSoftBody::applyForces):
//   f_i = kVC (V0 - V) A_i n_i     (V enclosed volume, A_i, n_i Bullet's node area and normal).
//
// Mapping from our physical parameters (README.md, "Parameters"):
//   - mass: density x enclosed rest volume, distributed over the nodes by adjacent surface area;
//   - kVC = K / V0 with the bulk modulus K = E / (3 (1 - 2 nu)): the force is then the pressure
//     p = K (V0 - V) / V0 of a linear compressible fill acting on the node's area;
//   - kLST per link ("xpbd" mapping): the fraction of the constraint error one XPBD projection
//     (Macklin et al. 2016, doi:10.1145/2994258.2994272, Eq. 18 with lambda = 0) removes,
//     kLST = (w_a + w_b) / (w_a + w_b + alpha / dt^2),  alpha = L0^2 / (E t A_e)
//     (A_e area of the triangles sharing the edge, t a shell thickness). Bullet does not carry the
//     multiplier across iterations, so the effective stiffness still grows with `iterations`
//     (as in classic PBD): it is a defensible starting point, not a physical stiffness;
//   - kDP = 1 - exp(-c dt) for a velocity damping rate c (1/s), as our PBD's damping.
// Fixed nodes have inverse mass 0; grasped nodes get inverse mass 0 and the velocity that moves
// them onto their targets in the step (kinematic), their mass is restored on release. Contact
// with instruments: the SDK's shared response on the nodes after Bullet's step
// (bullet_common/bullet_peer_step.h; README.md, "Contact with instruments").
//
// Reaction force (graspForces, "xpbd" mapping only): what Bullet's step transmits between the
// tool and the tissue. A bonded grasp's kinematic nodes push their free neighbours only through
// the links: one projection of link (a, c) gives a the momentum -kappa d (d = x_c - x_a, kappa =
// kLST (L0^2 - |d|^2) / ((w_a + w_c) (L0^2 + |d|^2)), whatever w_a), so near a steady state the
// `iterations` sweeps of a step give the held end the force -N kappa d / dt^2, summed over its
// links at the end of the step (links inside one grasp cancel; bending links too, as Bullet
// projects them).
// Bullet applies no volume force to kinematic nodes, so none is added. A sliding plate's nodes
// keep their mass and are put back on the plate after the step: its force is the normal momentum
// it takes back, m (v . n - v_plate) / dt per node. Under the "fixed" mapping the links have no
// physical stiffness and graspForces() is empty.
#pragma once

#include <bullet_peer_step.h>
#include <deform/sdk/model.h>
#include <deform/sdk/params.h>

#include <memory>
#include <vector>

namespace deform::bullet_softbody {

enum class StiffnessMapping { Xpbd, Fixed };

/// Resolved parameters (see paramSpecs() for units, ranges and meaning).
struct SoftBodyConfig {
  int iterations = 10;  ///< m_cfg.piterations
  StiffnessMapping mapping = StiffnessMapping::Xpbd;
  Real linkStiffness = 0.5;     ///< kLST of every structural link when mapping == Fixed
  Real thickness = 0.01;        ///< m, shell thickness of the xpbd mapping
  bool bending = false;         ///< generateBendingConstraints(2)
  Real bendingStiffness = 0.1;  ///< kLST of the bending links
  bool volume = true;           ///< volume conservation force
  Real volumeScale = 1.0;       ///< kVC = volumeScale K / V0
  Real damping = 1.0;           ///< 1/s, kDP = 1 - exp(-damping dt)
};

std::vector<ParamSpec> paramSpecs();
/// Reads validated parameters; throws InputError on an unknown choice.
SoftBodyConfig configFromParams(const ParamValues& params);

/// kLST of one link from the XPBD compliance of an edge (see the header comment). wa, wb inverse
/// masses (1/kg), restLength (m), adjacentArea (m^2) the area of the faces sharing the edge.
/// Returns a value in (0, 1]; 1 when both ends are immovable or the compliance vanishes.
Real xpbdLinkStiffness(Real young, Real thickness, Real restLength, Real adjacentArea, Real wa,
                       Real wb, Real dt);
/// Bullet's volume coefficient kVC = K / V0 (N/m^5), K = E / (3 (1 - 2 nu)).
Real volumeCoefficient(const Material& m, Real restVolume);
/// Bullet's per-step damping coefficient kDP = 1 - exp(-rate dt), in [0, 1).
Real dampingCoefficient(Real rate, Real dt);

class BulletSoftBodyModel final : public Model {
 public:
  BulletSoftBodyModel();
  ~BulletSoftBodyModel() override;

  void init(const ModelSetup& setup) override;
  /// init() without the parameter layer (tests and benchmarks). fixedNodes: pinned vertices.
  void init(const Organ& organ, const SoftBodyConfig& config, Real dt,
            const std::vector<int>& fixedNodes);

  StepStatus step(const StepInput& in) override;
  const MatX3& nodes() const override { return m_x; }
  const MatX3& surface() const override { return m_x; }
  void reset() override;
  Counts counts() const override;
  PhaseTimes phaseTimes() const override { return m_phase; }
  /// Per grasp, see the header comment; empty under the "fixed" mapping. Computed when first
  /// asked after a step (a pass over the links, kept off the step for runs that never ask).
  std::vector<Vec3> graspForces() const override;

  const SoftBodyConfig& config() const { return m_config; }
  /// Node masses (kg) before pinning.
  const VecX& masses() const { return m_mass; }
  /// kLST of each structural link (input edge order), then of each bending link.
  std::vector<Real> linkStiffnesses() const;
  /// Bullet's kVC and kDP as configured.
  Real volumeCoefficientUsed() const;
  Real dampingCoefficientUsed() const;

 private:
  struct World;  // the Bullet objects, rebuilt by reset()
  void build();
  void computeGraspForces(std::size_t numGrasps, Real dt) const;

  SoftBodyConfig m_config;
  Real m_dt = 0;
  Material m_material;
  MatX3 m_rest;  // #V by 3
  MatX3i m_faces;
  MatX2i m_edges;
  VecX m_edgeArea;  // #E, area of the faces sharing each edge
  VecX m_mass;      // #V
  std::vector<int> m_fixed;
  Real m_restVolume = 0;

  std::unique_ptr<World> m_world;
  bullet_common::PeerStepState m_tail;  // grasped set, divergence box, contact scratch
  MatX3 m_x;
  PhaseTimes m_phase;
  mutable std::vector<Vec3> m_graspForces;  // N, per grasp of the last step (xpbd mapping)
  mutable bool m_graspForcesStale = false;  // the last step's are not computed yet
  std::size_t m_stepGrasps = 0;             // the last step's number of grasps
  Real m_stepDt = 0;                        // and its time step, s
  std::vector<Vec3> m_slidingForces;        // N, per grasp: the sliding plates' normal impulse / dt
  mutable std::vector<int> m_holder;        // #V, bonded grasp holding each kinematic node, or -1
};

}  // namespace deform::bullet_softbody
