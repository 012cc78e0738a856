// deformbench SDK: contact between rigid instruments and a model's own collision proxy, through
// Bullet's collision world (btCollisionWorld: a btDbvtBroadphase finds the proxy/instrument pairs
// whose bounding boxes overlap, Bullet's narrowphase computes their signed distance and normal).
//
// The harness owns one ContactWorld per run, and only when the scene has something to collide
// with (a probe tool or a rigid object); it sets the instruments' poses before each step and hands
// the world to the model through StepInput::contact. A model passes its own proxy (sphere centres
// and radii: metaball spheres, BEM particles, or its nodes as spheres of the contact thickness)
// and gets the penetrating ones back, each with the depth d > 0 and the unit normal n pointing
// out of the instrument:
//
//   a proxy sphere (c, r) penetrates instrument B when  phi_B(c) < r,  d = r - phi_B(c),
//
// phi_B the signed distance to B's surface (negative inside). The shared helper projectContacts()
// resolves them the same way for every model: c <- c + d n (the non-penetration projection of
// Mueller et al. 2007, "Position based dynamics", Sec. 3.5, Eq. (9)-(10) for a static collider),
// and, for models with a velocity state, the inward normal velocity is removed (an inelastic
// contact). The impulse the tissue received, m (dx / dt + dv), divided by dt, is the force on the
// node; its opposite is accumulated as the tissue's reaction on the instrument, which drives the
// instrument's rigid-body dynamics (see instruments.h) and the force felt by the hand.
#pragma once

#include <deform/model.h>
#include <deform/types.h>

#include <functional>
#include <memory>
#include <vector>

namespace deform {

/// Scene-level contact parameters, identical for every model (scene key "contact").
struct ContactParams {
  /// m: radius of the sphere around each node that is kept out of the instruments (the contact
  /// skin); models whose proxy is already a sphere set use their own radii instead.
  Real thickness = 1e-4;
  /// Projection passes per resolveContacts() call: a node pushed out of one part of an
  /// instrument into another is fixed by the next pass.
  int passes = 2;
};

/// One primitive of a rigid instrument, in the instrument's body frame (m).
struct ShapePrimitive {
  enum class Kind { Sphere, Capsule, Box };
  Kind kind = Kind::Sphere;
  Vec3 centre = Vec3::Zero();       ///< sphere centre, capsule segment midpoint, box centre
  Vec3 axis = Vec3::UnitZ();        ///< capsule: unit direction of the segment
  Real radius = 0;                  ///< sphere and capsule radius
  Real length = 0;                  ///< capsule: segment length (the caps add 2 radius)
  Vec3 halfExtents = Vec3::Zero();  ///< box, along the body frame's axes
};

/// A rigid instrument or object: the union of its primitives.
struct RigidShape {
  std::vector<ShapePrimitive> parts;
};

/// A probe: a spherical tip of radius tipRadius centred at the body origin and a cylindrical shaft
/// (a capsule of radius shaftRadius) from the tip centre along `axis` for shaftLength (0: tip
/// only).
RigidShape probeShape(Real tipRadius, Real shaftLength, Real shaftRadius, const Vec3& axis);

/// A penetrating proxy sphere: push it by depth along normal to touch the instrument.
struct Contact {
  int proxy = -1;               ///< index into the centres given to query()
  int body = -1;                ///< instrument (addBody() order)
  Real depth = 0;               ///< m, > 0
  Vec3 normal = Vec3::UnitZ();  ///< unit, out of the instrument
};

class ContactWorld {
 public:
  explicit ContactWorld(const ContactParams& params = {});
  ~ContactWorld();
  ContactWorld(const ContactWorld&) = delete;
  ContactWorld& operator=(const ContactWorld&) = delete;

  /// Adds a rigid instrument at the identity pose; returns its index.
  int addBody(const RigidShape& shape);
  /// Pose of the instrument for the coming queries: x_world = pos + rot * x_body.
  void setPose(int body, const Vec3& pos, const Mat3& rot = Mat3::Identity());
  Vec3 position(int body) const;
  Mat3 rotation(int body) const;
  int numBodies() const;
  /// Radius of the body's thinnest part (sphere or capsule radius, half the box's smallest side).
  Real thinnestRadius(int body) const;
  /// Where the body was when a quasi-static model last resolved contact (settle()); its first
  /// pose until then.
  Vec3 settledPosition(int body) const;
  void settle();
  const ContactParams& params() const { return m_params; }

  /// Penetrating proxy spheres, at most one contact per proxy (the deepest over all instruments),
  /// sorted by proxy index. centres: #P by 3 (m); radii: #P (m), or nullptr for the contact
  /// thickness. Proxies inside the instruments' bounding box are inserted into Bullet's world as
  /// spheres for the query (broadphase pairs, narrowphase depth) and taken out after it.
  std::vector<Contact> query(const MatX3& centres, const VecX* radii = nullptr);

  /// Reaction of the tissue on an instrument (N), applied at `at` (m, world); accumulated until
  /// clearReactions() (the harness clears before every step).
  void addReaction(int body, const Vec3& force, const Vec3& at);
  Vec3 reactionForce(int body) const;
  /// Torque of the reactions about the body's position (N m).
  Vec3 reactionTorque(int body) const;
  void clearReactions();

  /// Statistics since construction: broadphase pairs passed to the narrowphase, contacts found.
  long long pairsTested() const { return m_pairsTested; }
  long long contactsFound() const { return m_contactsFound; }

 private:
  struct Impl;
  ContactParams m_params;
  std::unique_ptr<Impl> m_impl;
  std::vector<Vec3> m_force, m_torque;
  std::vector<Vec3> m_settled;
  std::vector<char> m_settledSet;
  std::vector<Real> m_thinnest;
  long long m_pairsTested = 0, m_contactsFound = 0;
};

/// What one resolveContacts() call did.
struct ContactResolution {
  int contacts = 0;   ///< proxies found penetrating in the first pass
  Real maxDepth = 0;  ///< m, deepest penetration found in the first pass
};

/// The shared contact response for every model whose proxy is its own nodes (or spheres it moves
/// like nodes): each penetrating proxy i with 0 < invMass[i] is moved out, x_i += d n; when v is
/// given its inward normal velocity is removed (v_i -= min(v_i . n, 0) n) and its position change
/// is not added to v (a model that derives v from positions, like PBD, passes v = nullptr). The
/// opposite of m_i (dx_i / dt + dv_i) / dt is added to the instrument's reaction. Repeats for
/// world.params().passes passes. x: #P by 3 (m); invMass: #P (1/kg, 0 = immovable); radii as in
/// ContactWorld::query(); v: #P by 3 (m/s) or nullptr.
ContactResolution resolveContacts(ContactWorld& world, MatX3& x, const VecX& invMass, Real dt,
                                  MatX3* v = nullptr, const VecX* radii = nullptr);

/// Display-level projection of points the model derives from its proxy (a skinned or
/// interpolated surface): each point inside an instrument is moved onto its surface (plus the
/// contact thickness). No reaction: the proxy's contact already carried the force. Returns the
/// number of points moved.
int projectPointsOut(ContactWorld& world, MatX3& points);

/// Contact as prescribed positions, for models whose solver honours GraspInput as Dirichlet
/// conditions (quasi-static and coupled solvers): each round calls solve(in') with in' = in plus
/// one GraspInput per instrument (tool = -1) holding the nodes that penetrate it, with targets
/// pushed out onto its surface (plus the thickness; nodes touching it, within twice the
/// thickness, are held where they are). Round 0 tests the nodes at the step's start, each later
/// round the nodes the previous solve produced; a node once in the set stays (its target kept) and
/// only new penetrations are added; rounds stop when none is added or after maxRounds. The appended
/// inputs' graspForces() (the tissue's force on them) become the instruments' reaction. Nodes in
/// `immovable` (sorted) are never added. Returns the last solve's status.
struct ContactModelHooks {
  std::function<StepStatus(const StepInput&)> solve;
  std::function<const MatX3&()> nodes;
  std::function<std::vector<Vec3>()> graspForces;  ///< may be empty: no reaction reported
};
StepStatus solveWithContactConstraints(ContactWorld& world, const StepInput& in,
                                       const ContactModelHooks& model,
                                       const std::vector<int>& immovable, int maxRounds);

/// The same for quasi-static models, whose solves can be far apart along the instruments' path:
/// the motion since the last settled poses is split into sub-steps of at most maxStepFraction of
/// each instrument's thinnest radius, so that no node is swallowed whole between two solves (a
/// node deeper than the radius would be pushed out of the wrong side); each sub-step runs
/// solveWithContactConstraints() with the instruments there. The reaction is that of the last
/// sub-step; the poses are settled at the end.
StepStatus solveAlongInstrumentPath(ContactWorld& world, const StepInput& in,
                                    const ContactModelHooks& model,
                                    const std::vector<int>& immovable, int maxRounds,
                                    Real maxStepFraction = 0.5);

/// Row-major index and weight tables of an embedding (#S by K).
using EmbeddingIds = Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using EmbeddingWeights = Eigen::Matrix<Real, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

/// The same response for models whose collision proxy (their surface) is embedded in their nodes:
/// surface point s = sum_k W(s,k) x_{I(s,k)}. Each penetrating point's correction d n is spread
/// over its movable nodes as dx_a = W(s,a) d n / sum_b W(s,b)^2 (the smallest node motion that
/// moves the point by d n), one contact after the other with the depth updated to the motion so
/// far (Gauss-Seidel), for up to 4 x passes passes. Moved nodes lose their inward normal velocity
/// when nodeVelocity (3 #N, node-major, m/s) is given. Reaction as in resolveContacts(). Proxy
/// spheres have the contact thickness as radius.
ContactResolution resolveEmbeddedContacts(ContactWorld& world, MatX3& nodes,
                                          const Eigen::Ref<const EmbeddingIds>& ids,
                                          const Eigen::Ref<const EmbeddingWeights>& weights,
                                          const VecX& invMass, Real dt,
                                          Real* nodeVelocity = nullptr);

}  // namespace deform
