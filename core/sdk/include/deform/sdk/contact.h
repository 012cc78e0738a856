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
// phi_B the signed distance to B's surface (negative inside). A model describes its proxy once
// (ContactProxy: nodes, masses, shape, embedding) and picks how it answers: respondToContact()
// after its own solve (projection, penalty forces, or display-level projection), or
// solveWithContactConstraints() for models that solve for positions. Projection resolves
// contacts the same way for every model: c <- c + d n (the non-penetration projection of
// Mueller et al. 2007, "Position based dynamics", Sec. 3.5, Eq. (9)-(10) for a static collider),
// and, for models with a velocity state, the inward normal velocity is removed (an inelastic
// contact). The impulse the tissue received, m (dx / dt + dv), divided by dt, is the force on the
// node; its opposite is accumulated as the tissue's reaction on the instrument, which drives the
// instrument's rigid-body dynamics (see instruments.h) and the force felt by the hand.
#pragma once

#include <deform/sdk/model.h>
#include <deform/sdk/types.h>

#include <functional>
#include <memory>
#include <vector>

namespace deform {

/// How force-based models answer contact (scene key "contact.method").
///  - Projection: positions are projected out of the instruments (every model; the default).
///  - Penalty: force-based models (massspring, fem_hex dynamic) receive a penalty force on their
///    surface triangles instead, f = A (k_A d - c_A min(v_n, 0)) n (see ContactResponse::Penalty);
///    other models keep the projection.
enum class ContactMethod { Projection, Penalty };

/// Scene-level contact parameters, identical for every model (scene key "contact").
struct ContactParams {
  /// m: radius of the sphere around each node that is kept out of the instruments (the contact
  /// skin); models whose proxy is already a sphere set use their own radii instead.
  Real thickness = 1e-4;
  /// Projection passes per respondToContact() call: a node pushed out of one part of an
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
  /// ContactResponse::Project on a surface proxy (0: frictionless, the behaviour before it
  /// existed).
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

/// Row-major index and weight tables of an embedding (#S by K).
using EmbeddingIds = Eigen::Matrix<int, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using EmbeddingWeights = Eigen::Matrix<Real, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

/// Proxy points embedded in a model's nodes: point s = sum_k W(s,k) x_{I(s,k)}, K weights per
/// point (fem_hex's trilinear cells). Views the caller's row-major tables; build it with
/// embeddingOf().
struct ContactEmbedding {
  const int* ids = nullptr;       ///< #S by K, row-major
  const Real* weights = nullptr;  ///< #S by K, row-major
  Eigen::Index points = 0;        ///< S
  Eigen::Index perPoint = 0;      ///< K
};

/// A ContactEmbedding viewing two row-major Eigen tables of the same shape (kept alive by the
/// caller while the proxy is used).
template <class Ids, class Weights>
ContactEmbedding embeddingOf(const Eigen::DenseBase<Ids>& ids,
                             const Eigen::DenseBase<Weights>& weights) {
  static_assert(Ids::IsRowMajor && Weights::IsRowMajor, "embedding tables must be row-major");
  return {ids.derived().data(), weights.derived().data(), ids.rows(), ids.cols()};
}

/// A model's collision proxy: the points kept out of the instruments, and how they hang on the
/// nodes a contact response moves. One description for every model:
///
///  - shape: with `faces`, the proxy is a surface (triangles over the points, each kept the
///    contact thickness away from the instruments; finds a tool thinner than the point spacing);
///    without, the points are spheres of `radii` (or of the contact thickness);
///  - mapping: the points are the nodes themselves, or embedded in them (`embedding`), forces
///    going back through the transposed weights.
///
/// Every pointer views the model's own storage for the duration of the call.
struct ContactProxy {
  MatX3* nodes = nullptr;              ///< #N by 3 (m): the positions the response moves; required
  const VecX* invMass = nullptr;       ///< #N (1/kg, 0 = immovable); required to move nodes
  Real* velocity = nullptr;            ///< 3 #N node-major (m/s), or nullptr (no velocity state)
  const MatX3* atStepStart = nullptr;  ///< nodes at the step's start (friction), or nullptr
  const MatX3i* faces = nullptr;       ///< #F by 3 rows of the points: the surface shape
  const VecX* radii = nullptr;         ///< #P sphere radii (m), spheres only; nullptr: thickness
  ContactEmbedding embedding;          ///< empty (points == 0): the points are the nodes
};

/// How a model answers contact after its own solve (respondToContact()).
///  - Project: the penetrating points are moved out by the smallest (mass-weighted) motion of
///    their movable nodes, one contact after the other (Gauss-Seidel, contact.passes passes);
///    with a velocity the inward normal velocity is removed, with atStepStart and a friction
///    coefficient Coulomb friction acts as positions; the impulse given to the tissue, reversed,
///    is the instruments' reaction. Mueller et al. 2007, "Position based dynamics", Sec. 3.5,
///    Eq. (8)-(10); friction Macklin et al. 2014, Eq. (24)-(25).
///  - Penalty: every surface triangle within the thickness receives the force
///    f = max(0, A (k_A d - c_A min(v_n, 0))) n at its deepest point, added to `force` (3 #N
///    node-major, N) through the barycentric and embedding weights; -f is the reaction. A the
///    triangle's area, k_A = contact.stiffness, c_A = contact.damping, v_n the point's normal
///    speed relative to the instrument. Needs `faces`. Explicit: stable while k_A A dt^2 / m
///    stays below about 1 (m the vertex mass).
///  - Display: points the model derives from a proxy already in contact (a skinned or
///    interpolated surface) are moved onto the instruments' surface plus the thickness, with no
///    reaction and no velocity. Needs neither masses nor faces; no embedding.
enum class ContactResponse { Project, Penalty, Display };

/// What one respondToContact() call did.
struct ContactResolution {
  int contacts = 0;   ///< proxies (points or triangles) in contact in the first pass
  Real maxDepth = 0;  ///< m, deepest penetration found in the first pass
};

/// Keeps `proxy` out of the world's instruments by `response` over a step of dt (s). force: 3 #N
/// node-major (N), accumulated into, for Penalty only. Throws std::invalid_argument naming the
/// inconsistent field when the proxy does not describe what the response needs.
ContactResolution respondToContact(ContactWorld& world, const ContactProxy& proxy,
                                   ContactResponse response, Real dt, Real* force = nullptr);

/// How a model that solves for its positions (quasi-static or coupled solvers, whose step honours
/// StepInput::nodeConstraints as Dirichlet conditions) answers contact: as prescribed positions.
struct ContactConstraintSolver {
  /// Solves the step with the given input (the model's own step body); the proxy's nodes hold
  /// the result.
  std::function<StepStatus(const StepInput&)> solve;
  /// The forces the model's grasps and node constraints exert, as graspForces(); may be empty
  /// (no reaction reported).
  std::function<std::vector<Vec3>()> graspForces;
  /// The force (N) the solved tissue exerts at a node held by a node constraint on what holds it
  /// (minus its energy's gradient there), after solve(); may be empty. With it, a held node whose
  /// force pulls its instrument (a component along the contact normal, which points out of the
  /// instrument) is released before the next round: contact pushes, it never sticks. The
  /// instruments' reaction is then the held nodes' push along their normals, plus their
  /// tangential force up to the scene's friction coefficient times that push (frictionless:
  /// none), instead of graspForces().
  std::function<Vec3(int node)> nodeReaction;
  /// Nodes never held (sorted): the model's fixed nodes.
  std::vector<int> immovable;
  /// Rounds of detection and solve; stops earlier when a round adds no penetration.
  int maxRounds = 1;
  /// Quasi-static models, whose solves can be far apart along the instruments' path: the motion
  /// since the last settled poses is split into sub-steps of at most maxStepFraction of each
  /// instrument's thinnest radius, so that no node is swallowed whole between two solves (a node
  /// deeper than the radius would be pushed out of the wrong side); the poses are settled at the
  /// end and the reaction is that of the last sub-step.
  bool followInstrumentPath = false;
  Real maxStepFraction = 0.5;
};

/// Contact as prescribed positions: each round calls solver.solve(in') with in' = in plus one
/// NodeGrasp per instrument (tool = -1) in nodeConstraints, holding the proxy nodes that
/// penetrate it (with `faces`, also the free movable vertices of every triangle within the
/// thickness: x_a + b_a d n / sum_b b_b^2), their targets pushed out onto its surface plus the
/// thickness (nodes touching it, within twice the thickness, are held where they are). Round 0
/// tests the nodes at the step's start, each later round those of the previous solve; a node
/// once held stays (its target kept) and only new penetrations are added, except that with
/// solver.nodeReaction a node pulling its instrument is released when another round remains (and
/// held again only if it penetrates deeper than the thickness). The appended
/// constraints' graspForces() become the instruments' reaction (with nodeReaction: the nodes'
/// normal push and friction, see there). solver.immovable are never
/// held. The proxy's points are its nodes (no embedding, no radii; invMass and velocity unused).
/// Returns the last solve's status; throws std::invalid_argument for such a proxy or an
/// unsorted immovable list.
StepStatus solveWithContactConstraints(ContactWorld& world, const ContactProxy& proxy,
                                       const StepInput& in, const ContactConstraintSolver& solver);

/// "projection" or "penalty" (the scene's spelling).
const char* contactMethodName(ContactMethod m);

}  // namespace deform
