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

/// How force-based models answer contact (scene key "contact.method").
///  - Projection: positions are projected out of the instruments (every model; the default).
///  - Penalty: force-based models (massspring, fem_hex dynamic) receive a penalty force on their
///    surface triangles instead, f = A (k_A d - c_A min(v_n, 0)) n (see addPenaltyContactForces);
///    other models keep the projection.
enum class ContactMethod { Projection, Penalty };

/// Scene-level contact parameters, identical for every model (scene key "contact").
struct ContactParams {
  /// m: radius of the sphere around each node that is kept out of the instruments (the contact
  /// skin); models whose proxy is already a sphere set use their own radii instead.
  Real thickness = 1e-4;
  /// Projection passes per resolveContacts() call: a node pushed out of one part of an
  /// instrument into another is fixed by the next pass.
  int passes = 2;
  ContactMethod method = ContactMethod::Projection;
  /// Pa/m (N/m^3), penalty only: pressure per metre of penetration; a triangle of area A
  /// penetrated by d carries the force k_A A d, so the total force does not depend on the
  /// model's mesh resolution (a per-proxy N/m stiffness would grow with the proxy count).
  Real stiffness = 1e6;
  /// Pa s/m (N s/m^3), penalty only: pressure per unit approach speed, c_A A max(-v_n, 0).
  Real damping = 1e3;
  /// Coulomb friction coefficient mu (static = kinetic) of the projection response of
  /// resolveSurfaceContacts() (0: frictionless, the behaviour before it existed).
  Real friction = 0;
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

/// A model surface triangle that comes within the contact thickness of an instrument: its points
/// closer than the thickness are pushed out when the triangle's deepest point moves by
/// depth along normal.
///
///   depth = thickness - dist_B(T),  dist_B(T) = min over the triangle T of phi_B (< 0: overlap),
///
/// computed by Bullet's narrowphase on a btTriangleShape (sphere-triangle exactly, capsules and
/// boxes by GJK/EPA).
struct TriangleContact {
  int triangle = -1;            ///< row of the faces given to queryTriangles()
  int body = -1;                ///< instrument (addBody() order)
  Real depth = 0;               ///< m, > 0
  Vec3 normal = Vec3::UnitZ();  ///< unit, out of the instrument
  Vec3 bary = Vec3::Zero();     ///< barycentric weights of the triangle's deepest point
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

  /// Surface triangles that come within the contact thickness of an instrument, at most one
  /// contact per triangle (the deepest over all instruments), sorted by triangle index. V: #V by
  /// 3 (m); F: #F by 3 rows of V. Triangles whose (thickened) bounding box meets the instruments'
  /// box enter Bullet's world as btTriangleShapes for the query and leave it after it (so a tool
  /// thinner than the vertex spacing is found where vertex spheres would let it pass).
  std::vector<TriangleContact> queryTriangles(const MatX3& V, const MatX3i& F);

  /// Displacement (m) since the body's previous pose (the one before the last setPose()) of the
  /// body's material point that is now at p: the instrument's motion over the step, which a
  /// friction or damping law measures relative motion against.
  Vec3 bodyDisplacement(int body, const Vec3& p) const;

  /// Reaction of the tissue on an instrument (N), applied at `at` (m, world); accumulated until
  /// clearReactions() (the harness clears before every step).
  void addReaction(int body, const Vec3& force, const Vec3& at);
  Vec3 reactionForce(int body) const;
  /// Torque of the reactions about the body's position (N m).
  Vec3 reactionTorque(int body) const;
  void clearReactions();

  /// Inverse mass (1/kg) of a body that the tissue's reaction moves (a free object, a tool with
  /// dynamics): the contact responses then share each correction between the tissue and the body
  /// in proportion to their inverse masses (a two-body exchange), so a light object is not
  /// thrown off by heavy tissue pushed out of it. 0 (the default): the body is driven by the hand
  /// and the tissue alone moves out of it.
  void setInverseMass(int body, Real invMass);
  Real inverseMass(int body) const;

  /// Statistics since construction: broadphase pairs passed to the narrowphase, contacts found.
  long long pairsTested() const { return m_pairsTested; }
  long long contactsFound() const { return m_contactsFound; }

 private:
  struct Impl;
  ContactParams m_params;
  std::unique_ptr<Impl> m_impl;
  std::vector<Vec3> m_force, m_torque;
  std::vector<Vec3> m_settled;
  std::vector<Vec3> m_prevPos;
  std::vector<Mat3> m_prevRot;
  std::vector<char> m_settledSet;
  std::vector<Real> m_thinnest;
  std::vector<Real> m_invMass;
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

/// The same two with the model's surface triangles as proxy too (issue F8): faces is #F by 3 rows
/// of model.nodes(). Besides the penetrating nodes, every triangle within the thickness of an
/// instrument (ContactWorld::queryTriangles(), which finds a tool thinner than the vertex
/// spacing) prescribes its not yet prescribed, movable vertices: x_a + b_a d n / sum_b b_b^2
/// (the smallest motion of the vertices that moves the triangle's deepest point by d n).
StepStatus solveWithSurfaceContactConstraints(ContactWorld& world, const StepInput& in,
                                              const ContactModelHooks& model, const MatX3i& faces,
                                              const std::vector<int>& immovable, int maxRounds);
StepStatus solveSurfaceAlongInstrumentPath(ContactWorld& world, const StepInput& in,
                                           const ContactModelHooks& model, const MatX3i& faces,
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

/// The response on surface triangles, for models whose collision proxy is their surface
/// (issue F8: "the surface triangles"): each triangle within the thickness of an instrument is
/// pushed out at its deepest point p = sum_a b_a x_a (b its barycentric weights) by d n, the
/// correction spread over its movable vertices as the smallest mass-weighted motion that moves
/// p by d n (the PBD distribution of Mueller et al. 2007, Eq. (8), for the constraint
/// C = n . (p - p0) - d with grad_{x_a} C = b_a n):
///
///   dx_a = w_a b_a d n / sum_b w_b b_b^2,   w the inverse masses,
///
/// contact after contact with the depth updated to the motion so far (Gauss-Seidel), for up to
/// 4 x passes passes. A contact whose movable vertices hold less than a quarter of the
/// barycentric weight is skipped (fixed or grasped vertices hold that point; the minimum-norm
/// motion of a vertex of weight b grows like d / b). Points closer than the thickness include the
/// vertices, so this replaces
/// resolveContacts() on the surface vertices. With v, p's inward normal velocity is removed the
/// same way (v_p . n -> 0) and dx is not added to v. With x0 (the positions at the step's start)
/// and contact.friction mu > 0, Coulomb friction as positions (Macklin et al. 2014, "Unified
/// particle physics for real-time applications", Sec. 6.1, Eq. (24)-(25)): the tangential
/// motion of p relative to the instrument over the step, dt_p = [(p - p(x0)) -
/// bodyDisplacement(p)]_tangent, is undone when |dt_p| < mu d (static), else shortened by
/// mu d (kinetic); with v the same share of p's tangential velocity relative to the
/// instrument is removed. The reaction on
/// the instrument is minus the impulse given to the vertices, normal and tangential parts:
/// -sum_a m_a (dx_a / dt + dv_a) / dt at p. x: #N by 3 (m); F: #F by 3 rows of x; invMass: #N
/// (1/kg, 0 = immovable); v: #N by 3 (m/s) or nullptr; x0: #N by 3 (m) or nullptr (no friction).
ContactResolution resolveSurfaceContacts(ContactWorld& world, MatX3& x, const MatX3i& F,
                                         const VecX& invMass, Real dt, MatX3* v = nullptr,
                                         const MatX3* x0 = nullptr);

/// The same for a surface embedded in the nodes (fem_hex): surface vertex s = sum_k W(s,k)
/// x_{I(s,k)} (ids, weights as in resolveEmbeddedContacts()); F: #F by 3 rows of the embedded
/// surface. A triangle's deepest point is sum_a b_a sum_k W(a,k) x_{I(a,k)}, its correction
/// spread over those nodes by the same minimum-norm rule. nodeVelocity: 3 #N (node-major, m/s)
/// or nullptr; nodes0: the nodes at the step's start (friction) or nullptr.
ContactResolution resolveEmbeddedSurfaceContacts(ContactWorld& world, MatX3& nodes,
                                                 const Eigen::Ref<const EmbeddingIds>& ids,
                                                 const Eigen::Ref<const EmbeddingWeights>& weights,
                                                 const MatX3i& F, const VecX& invMass, Real dt,
                                                 Real* nodeVelocity = nullptr,
                                                 const MatX3* nodes0 = nullptr);

/// Penalty contact (contact.method = penalty) for force-based models: every surface triangle
/// within the thickness of an instrument receives, at its deepest point p, the force
///
///   f = max(0, A (k_A d - c_A min(v_n, 0))) n,   v_n = (v_p - bodyDisplacement(p) / dt) . n,
///
/// A the triangle's area, k_A = contact.stiffness (Pa/m), c_A = contact.damping (Pa s/m),
/// distributed to the vertices as f_a = b_a f (the consistent load of a point force); -f is the
/// instrument's reaction. The model adds `force` (N, #N by 3, accumulated into) to its external
/// forces for the coming step. v: #N by 3 (m/s) or nullptr (no damping). Explicit: stable while
/// k_A A dt^2 / m stays below about 1 (m the vertex mass).
ContactResolution addPenaltyContactForces(ContactWorld& world, const MatX3& x, const MatX3i& F,
                                          const MatX3* v, Real dt, MatX3& force);

/// The same on an embedded surface: f_a is spread to the nodes as W(a,k) f_a. nodeVelocity,
/// nodeForce: 3 #N, node-major (nodeVelocity may be nullptr).
ContactResolution addEmbeddedPenaltyContactForces(ContactWorld& world, const MatX3& nodes,
                                                  const Eigen::Ref<const EmbeddingIds>& ids,
                                                  const Eigen::Ref<const EmbeddingWeights>& weights,
                                                  const MatX3i& F, const Real* nodeVelocity,
                                                  Real dt, Real* nodeForce);

/// "projection" or "penalty" (the scene's spelling).
const char* contactMethodName(ContactMethod m);

}  // namespace deform
