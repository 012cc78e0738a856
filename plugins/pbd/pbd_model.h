// Position based dynamics model of an organ: the thin stateful layer over the kernels in
// pbd_constraints.h. Simulation nodes are the organ's surface vertices (distance constraints on
// edges, dihedral bending constraints on interior edges, one global volume constraint), or, when
// the organ comes with a tetrahedral mesh, the tet nodes (distance constraints on tet edges and
// one volume constraint per tet). One step follows Mueller et al. 2007, Algorithm 1 (XPBD:
// Macklin et al. 2016, Algorithm 1): predict with external forces, Gauss-Seidel projection of all
// constraints in a fixed order for `iterations` sweeps, velocity from the position change, then
// velocity damping. See README.md for every modelling choice.
#pragma once

#include "pbd_constraints.h"

#include <deform/geometry/tet_embedding.h>
#include <deform/kernels/isometric_bending.h>
#include <deform/kernels/tet_volume_batch.h>
#include <deform/sdk/model.h>
#include <deform/sdk/params.h>

#include <vector>

namespace deform::pbd {

enum class StiffnessMode { Classic, Xpbd };
/// Number type of the solver state of the distance, isometric bending, tet volume and global
/// volume constraints (see README.md, "Precision"); the interface, the state between steps and the
/// dihedral constraints stay double.
enum class Precision { Float32, Float64 };

/// Calls run(begin, end) on each run of constraints that may be projected together, in colour
/// order: colours[c] .. colours[c + 1] is colour c (see orderByColour in pbd_model.cpp), whose
/// constraints share no movable particle, except colour 63, which collects every constraint once
/// 63 colours are used and so goes one constraint at a time.
template <class Run>
void forEachIndependentRun(const std::vector<size_t>& colours, Run&& run) {
  for (size_t c = 0; c + 1 < colours.size(); ++c) {
    const size_t begin = colours[c], end = colours[c + 1];
    if (c == 63)
      for (size_t i = begin; i < end; ++i) run(i, i + 1);
    else
      run(begin, end);
  }
}

/// The bending constraint of `bending = true`: the isometric (Bergou et al. 2006) hinge of
/// deform/kernels/isometric_bending.h, or the dihedral angle of deform/kernels/pbd_kernels.h.
enum class BendingModel { Isometric, Dihedral };

/// Resolved parameters (see paramSpecs() for units, ranges and meaning).
struct PbdConfig {
  int iterations = 10;
  bool volumeNetwork = false;       ///< tetrahedralise a surface organ (network = volume)
  long long volumeElements = 4000;  ///< target tets of that volume
  StiffnessMode mode = StiffnessMode::Xpbd;
  Real stretchStiffness = 1.0;  ///< classic, [0, 1]
  Real bendingStiffness = 0.1;  ///< classic, [0, 1]
  Real volumeStiffness = 1.0;   ///< classic, [0, 1]
  bool bending = false;         ///< bending constraints on interior edges (surface input)
  BendingModel bendingModel = BendingModel::Isometric;
  bool volume = true;             ///< global volume constraint (closed surface input)
  bool volumeEverySweep = false;  ///< project the global volume in every sweep, not only the last
  Real thickness = 0.01;          ///< m, shell thickness for XPBD compliances (surface input)
  Real damping = 1.0;             ///< 1/s, velocity damping rate
  Precision precision = Precision::Float32;
};

/// The parameter declarations of the "pbd" plugin.
std::vector<ParamSpec> paramSpecs();
/// Reads validated parameters; throws InputError on an unknown stiffness_mode.
PbdConfig configFromParams(const ParamValues& params);

/// XPBD compliances derived from the material (see README.md, "Stiffness").
/// Edge of a triangle surface: alpha = L^2 / (E t sum_{T ni e} A_T)  (m/N).
Real surfaceEdgeCompliance(Real young, Real thickness, Real restLength, Real adjacentArea);
/// Dihedral hinge: alpha = (A1 + A2) / (3 D |e|^2), D = E t^3 / (12 (1 - nu^2))  (1/(N m)).
Real hingeCompliance(const Material& m, Real thickness, Real edgeLength, Real adjacentArea);
/// Isometric hinge: alpha = (A1 + A2) / (3 D) (m/N), see deform/kernels/isometric_bending.h.
/// Bulk modulus K = E / (3 (1 - 2 nu)), Pa (infinite for nu = 0.5).
Real bulkModulus(const Material& m);

class PbdModel final : public Model {
 public:
  void init(const ModelSetup& setup) override;
  /// init() without the parameter layer (tests and benchmarks).
  void init(const Organ& organ, const PbdConfig& config);

  StepStatus step(const StepInput& in) override;
  const MatX3& nodes() const override { return m_x; }
  const MatX3& surface() const override { return m_surfaceIdentity ? m_x : m_surface; }
  void reset() override;
  Counts counts() const override;
  PhaseTimes phaseTimes() const override { return m_phase; }
  NumericCounters numericCounters() const override;
  std::vector<Vec3> graspForces() const override { return m_graspForces; }
  /// Markers: barycentric coordinates in the containing tet of the volume network
  /// (deform/geometry/tet_embedding.h); a surface network has no interior.
  void bindMarkers(const MatX3& rest) override {
    if (m_tets.rows() == 0)
      throw UnsupportedError("no interior: surface network (network = volume maps markers)");
    m_markerEmbedding = embedInTets(m_rest, m_tets, rest);
  }
  MatX3 markers() const override { return embeddedPositions(m_markerEmbedding, m_x, m_tets); }

  const PbdConfig& config() const { return m_config; }
  const VecX& masses() const { return m_mass; }
  const std::vector<DistanceConstraint>& distanceConstraints() const { return m_distance; }
  const std::vector<DihedralConstraint>& dihedralConstraints() const { return m_dihedral; }
  const std::vector<IsometricHinge>& isometricHinges() const { return m_iso; }
  const std::vector<TetVolumeConstraint>& tetConstraints() const { return m_tet; }
  bool hasVolumeConstraint() const { return m_hasVolume; }

 private:
  void buildSurface(const Organ& organ);
  void buildTets(const Organ& organ);
  void refreshHotData(Real dt);
  void projectAll(Real dt);
  void listGraspConstraints();
  void packPositions();
  void unpackPositions();
  void projectVolume(Real dt);
  // Isometric bending (pbd_isometric.cpp): hot data, the per-sweep projection on the packed
  // positions, and the multipliers' forces on grasped nodes.
  void initIsometric();
  void refreshIsometricHotData(Real dt);
  void projectIsometric();
  void addIsometricGraspForces(Real invDt2, MatX3& nodeForce);
  // Tet volume constraints (pbd_tets.cpp): the batches, their hot data and one sweep.
  void initTets();
  void refreshTetHotData(Real dt);
  void projectTets();
  Real lambdaTet(size_t i) const {
    return m_f32 ? static_cast<Real>(m_lambdaTetF[i]) : m_lambdaTet[i];
  }
  Real lambdaDist(size_t i) const {
    return m_f32 ? static_cast<Real>(m_lambdaDistF[i]) : m_lambdaDist[i];
  }
  Vec3 volumeGradient(int node) const;
  void computeGraspForces(const StepInput& in, Real dt);

  PbdConfig m_config;
  Real m_kStretch = 1, m_kBend = 1, m_kVolume = 1;  // per-iteration stiffness (classic) or 1

  MatX3 m_rest;  // #N by 3 rest positions
  MatX3 m_x;     // #N by 3 positions
  MatX3 m_v;     // #N by 3 velocities
  MatX3 m_p;     // #N by 3 predicted / projected positions
  VecX m_mass;   // #N masses, kg
  VecX m_w0;     // #N inverse masses with fixed nodes 0
  VecX m_w;      // #N inverse masses of this step (grasped nodes 0)
  std::vector<int> m_fixed;

  bool m_surfaceIdentity = true;
  std::vector<int> m_surfaceRows;  // surface vertex -> node when not the identity
  MatX3 m_surface;
  MatX3i m_surfaceF;  // triangles (node indices) for the global volume constraint
  MatX3i m_contactF;  // surface triangles (node indices): the collision proxy

  std::vector<DistanceConstraint> m_distance;
  std::vector<DihedralConstraint> m_dihedral;
  std::vector<IsometricHinge> m_iso;
  // Isometric hinges in colour order as structure of arrays (double and float forms), like the
  // distance data: m_isoColours the start of each colour, plus the end.
  std::vector<size_t> m_isoColours;
  std::vector<int> m_isoP[4];  // 4 * particle index
  std::vector<Real> m_isoK[4], m_isoWK[4], m_isoRest, m_isoAlphaTilde, m_isoScale, m_lambdaIso;
  std::vector<float> m_isoKF[4], m_isoWKF[4], m_isoRestF, m_isoAlphaTildeF, m_isoScaleF,
      m_lambdaIsoF;
  std::vector<int> m_graspIso;
  std::vector<TetVolumeConstraint> m_tet;
  // Tet volume constraints in colour order as structure of arrays (pbd_tets.cpp), projected on
  // the packed positions like the hinges: m_tetColours the start of each colour, plus the end;
  // per-step inverse masses and alpha / dt^2 refreshed with the hot data. The float form's rest
  // volumes are measured in float from the packed rest positions (C = 0 exactly at rest).
  std::vector<size_t> m_tetColours;
  std::vector<int> m_tetP[4];  // 4 * particle index
  std::vector<Real> m_tetW[4], m_tetRest, m_tetFloor, m_tetAlphaTilde;
  std::vector<float> m_tetWF[4], m_tetRestF, m_tetFloorF, m_tetAlphaTildeF, m_lambdaTetF;
  MatX4i m_tets;  // tet input: the tets (for inverted_tets)
  TetEmbedding m_markerEmbedding;
  bool m_hasVolume = false;
  Real m_restVolume = 0, m_volumeCompliance = 0;
  long long m_elements = 0;

  // Distance constraints in colour order as structure of arrays; per-step alphaTilde = alpha/dt^2
  // and multiplier scale k / (w_a + w_b + alphaTilde), refreshed only when dt or the immovable
  // set changes. m_distColours: start of each colour, plus the end.
  std::vector<int> m_distA, m_distB;
  std::vector<Real> m_distRest, m_distAlphaTilde, m_distScale, m_distWa, m_distWb;
  // Positions padded to (x, y, z, 0) for the distance kernel, starting m_p4Offset entries into
  // m_p4Storage (32-byte aligned).
  std::vector<Real> m_p4Storage;
  size_t m_p4Offset = 0;
  Real* p4() { return m_p4Storage.data() + m_p4Offset; }
  std::vector<size_t> m_distColours;
  std::vector<Real> m_lambdaDist, m_lambdaBend, m_lambdaTet;
  Real m_lambdaVolume = 0;
  std::vector<Real> m_volumeGrad4;  // padded like the positions

  // Single-precision state (precision = float32): positions relative to m_boxCenter padded to
  // (x, y, z, 0) floats, 16-byte aligned from m_p4fOffset; the distance data in float; the rest
  // lengths and the rest volume recomputed in float from the rounded rest positions, so that the
  // rest state is exactly at rest.
  bool m_f32 = false;
  std::vector<float> m_p4fStorage;
  size_t m_p4fOffset = 0;
  float* p4f() { return m_p4fStorage.data() + m_p4fOffset; }
  std::vector<int> m_distA4, m_distB4;  // 4 * particle index (row offsets in p4f())
  std::vector<float> m_distRestF, m_distAlphaTildeF, m_distScaleF, m_distWaF, m_distWbF;
  std::vector<float> m_lambdaDistF, m_volumeGrad4F;
  Real m_restVolumeF = 0;
  Real m_hotDt = -1;
  std::vector<int> m_hotGrasped;  // grasped nodes the hot data was built for
  std::vector<unsigned char> m_graspMask;
  Vec3 m_boxCenter = Vec3::Zero();
  Real m_boxHalf = 0;

  long long m_degenerate = 0;        // skipped projections since init/reset
  long long m_degenerateAtInit = 0;  // hinges dropped at init (degenerate rest triangles)
  std::vector<int> m_graspedScratch;
  std::vector<NodeGrasp> m_nodeGrasps;  // this step's grasps on particles
  /// This step's particles under a sliding plate (not also held by a bonded grasp): free
  /// particles projected onto the plate's plane n . p = offset after every solver iteration.
  struct SlidingHold {
    int node;
    Vec3 normal;
    Real offset;
  };
  std::vector<SlidingHold> m_sliding;
  std::vector<int> m_slidingScratch;
  std::vector<int> m_hotSliding;  // sliding particles the hot data was built for
  /// Projects the sliding particles onto their planes, in the packed (p4) positions when
  /// `packed`, else in m_p.
  void holdSliding(bool packed);
  std::vector<std::pair<int, Vec3>> m_nodeForces;  // this step's load shares on particles
  MatX3 m_nodeForce;
  // Constraints touching a grasped node (rebuilt with the hot data when the grasped set changes).
  std::vector<int> m_graspDist, m_graspBend, m_graspTet;
  std::vector<Vec3> m_graspForces;
  PhaseTimes m_phase;
};

}  // namespace deform::pbd
