// The contact responses every model shares (contact.h): the proxy description's two entry points,
// respondToContact() (projection of spheres, embedded spheres and surfaces, penalty forces,
// display-level projection) and solveWithContactConstraints() (prescribed positions). The world
// itself is in contact_world.cpp.
#include <deform/sdk/contact.h>
#include <deform/sdk/enum_names.h>
#include <deform/sdk/error.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <stdexcept>
#include <string>

namespace deform {

RigidShape probeShape(Real tipRadius, Real shaftLength, Real shaftRadius, const Vec3& axis) {
  RigidShape s;
  ShapePrimitive tip;
  tip.kind = ShapePrimitive::Kind::Sphere;
  tip.radius = tipRadius;
  s.parts.push_back(tip);
  if (shaftLength > 0 && shaftRadius > 0) {
    ShapePrimitive shaft;
    shaft.kind = ShapePrimitive::Kind::Capsule;
    shaft.axis = axis.normalized();
    shaft.radius = shaftRadius;
    shaft.length = shaftLength;
    shaft.centre = 0.5 * shaftLength * shaft.axis;
    s.parts.push_back(shaft);
  }
  return s;
}

namespace {

/// The two-body share of a contact correction (mass splitting by inverse masses): a tissue point
/// of generalized inverse mass W against a body of inverse mass w_b moves by W / (W + w_b) of the
/// depth, the body takes the rest through the reaction (its next rigid-body step moves it by
/// w_b dt times minus the impulse given to the tissue). The bodies' motion predicted that way is
/// kept while the contacts are resolved in sequence (Gauss-Seidel), so a later contact with the
/// same body sees the depth its earlier ones left: depth' = depth + delta_b . n.
class BodyExchange {
 public:
  explicit BodyExchange(const ContactWorld& world)
      : m_world(world), m_moved(size_t(world.numBodies()), Vec3::Zero()) {}

  /// The tissue's share of a correction against `body`, W the tissue point's inverse mass.
  Real tissueShare(int body, Real W) const {
    const Real wb = m_world.inverseMass(body);
    return wb > 0 ? W / (W + wb) : Real(1);
  }
  /// Depth left once the body's predicted motion is taken into account.
  Real depth(int body, Real depth, const Vec3& normal) const {
    return depth + m_moved[size_t(body)].dot(normal);
  }
  /// The body receives -impulse (N s): it will move by -w_b dt impulse.
  void push(int body, const Vec3& impulse, Real dt) {
    m_moved[size_t(body)] -= m_world.inverseMass(body) * dt * impulse;
  }

 private:
  const ContactWorld& m_world;
  std::vector<Vec3> m_moved;
};

/// Moves node `node` of x by dx (its share of a correction along the contact normal n), removes
/// the same share of its velocity into the body (vel: 3 #N node-major or nullptr), and gives the
/// impulse it took (mass 1 / w) to the body: its predicted motion and the world's reaction.
void correctNode(ContactWorld& world, BodyExchange& bodies, int body, const Vec3& n, Real share,
                 Real w, Real dt, const Vec3& dx, MatX3& x, Eigen::Index node, Real* vel) {
  x.row(node) += dx.transpose();
  Vec3 impulsePerMass = dx / dt;
  if (vel) {
    Eigen::Map<Vec3> v(vel + 3 * node);
    const Real vn = v.dot(n);
    if (vn < 0) {
      v -= share * vn * n;
      impulsePerMass -= share * vn * n;
    }
  }
  const Vec3 impulse = impulsePerMass / w;
  bodies.push(body, impulse, dt);
  world.addReaction(body, -impulse / dt, x.row(node).transpose());
}

/// Proxy spheres that are the nodes themselves (ContactResponse::Project without faces or
/// embedding). vel: 3 #N node-major or nullptr.
ContactResolution projectSpheres(ContactWorld& world, MatX3& x, const VecX& invMass, Real dt,
                                 Real* vel, const VecX* radii) {
  ContactResolution res;
  BodyExchange bodies(world);
  const int passes = std::max(world.params().passes, 1);
  for (int pass = 0; pass < passes; ++pass) {
    const std::vector<Contact> contacts = world.query(x, radii);
    if (pass == 0) res.contacts = static_cast<int>(contacts.size());
    if (contacts.empty()) break;
    for (const Contact& c : contacts) {
      const Real w = invMass[c.proxy];
      if (!(w > 0)) continue;
      if (pass == 0) res.maxDepth = std::max(res.maxDepth, c.depth);
      const Real depth = bodies.depth(c.body, c.depth, c.normal);
      if (!(depth > 0)) continue;
      const Real share = bodies.tissueShare(c.body, w);
      const Vec3 dx = share * depth * c.normal;
      correctNode(world, bodies, c.body, c.normal, share, w, dt, dx, x, c.proxy, vel);
    }
  }
  return res;
}

/// Proxy spheres (of the contact thickness) embedded in the nodes: each correction d n is spread
/// over the point's movable nodes as dx_a = W(s,a) d n / sum_b W(s,b)^2, Gauss-Seidel over the
/// contacts for up to 4 x passes passes.
ContactResolution projectEmbeddedSpheres(ContactWorld& world, MatX3& nodes,
                                         const Eigen::Ref<const EmbeddingIds>& ids,
                                         const Eigen::Ref<const EmbeddingWeights>& weights,
                                         const VecX& invMass, Real dt, Real* nodeVelocity) {
  ContactResolution res;
  const Eigen::Index S = ids.rows(), K = ids.cols();
  MatX3 points(S, 3);
  const auto pointOf = [&](Eigen::Index s) {
    Vec3 p = Vec3::Zero();
    for (Eigen::Index k = 0; k < K; ++k) p += weights(s, k) * nodes.row(ids(s, k)).transpose();
    return p;
  };
  BodyExchange bodies(world);
  const int passes = 4 * std::max(world.params().passes, 1);
  for (int pass = 0; pass < passes; ++pass) {
    for (Eigen::Index s = 0; s < S; ++s) points.row(s) = pointOf(s).transpose();
    const std::vector<Contact> contacts = world.query(points);
    if (pass == 0) res.contacts = static_cast<int>(contacts.size());
    if (contacts.empty()) break;
    for (const Contact& c : contacts) {
      if (pass == 0) res.maxDepth = std::max(res.maxDepth, c.depth);
      // Depth left after the corrections of the contacts before this one.
      const Vec3 now = pointOf(c.proxy);
      const Real depth = bodies.depth(
          c.body, c.depth - (now - points.row(c.proxy).transpose()).dot(c.normal), c.normal);
      if (!(depth > 0)) continue;
      Real sumW2 = 0, W = 0;
      for (Eigen::Index k = 0; k < K; ++k) {
        const Real w = invMass[ids(c.proxy, k)], c2 = weights(c.proxy, k) * weights(c.proxy, k);
        if (w > 0) {
          sumW2 += c2;
          W += w * c2;
        }
      }
      if (!(sumW2 > 0)) continue;
      // The point's generalized inverse mass for the split: sum_k w_k c_k^2 (the correction
      // itself keeps its equal-weight rule, c_k / sum c^2).
      const Real share = bodies.tissueShare(c.body, W);
      for (Eigen::Index k = 0; k < K; ++k) {
        const int a = ids(c.proxy, k);
        const Real w = invMass[a];
        if (!(w > 0) || weights(c.proxy, k) == 0) continue;
        const Vec3 dx = (share * weights(c.proxy, k) * depth / sumW2) * c.normal;
        correctNode(world, bodies, c.body, c.normal, share, w, dt, dx, nodes, a, nodeVelocity);
      }
    }
  }
  return res;
}

/// Below this barycentric share of movable nodes a triangle contact is left to its other
/// triangles (and the fixed or grasped nodes that hold it).
constexpr Real kMinMovableShare = 0.25;

/// Surface vertex a = sum_k W(a,k) x_{I(a,k)}, or x_a itself when there is no embedding.
struct SurfaceMap {
  const Eigen::Ref<const EmbeddingIds>* ids = nullptr;
  const Eigen::Ref<const EmbeddingWeights>* weights = nullptr;

  /// The surface vertices: x itself, or evaluated into `buffer`.
  const MatX3& surface(const MatX3& x, MatX3& buffer) const {
    if (!ids) return x;
    const Eigen::Index S = ids->rows(), K = ids->cols();
    buffer.setZero(S, 3);
    for (Eigen::Index a = 0; a < S; ++a)
      for (Eigen::Index k = 0; k < K; ++k) buffer.row(a) += (*weights)(a, k) * x.row((*ids)(a, k));
    return buffer;
  }
  template <class Fn>
  void forEachNode(int a, Fn fn) const {
    if (!ids) {
      fn(a, Real(1));
      return;
    }
    for (Eigen::Index k = 0; k < ids->cols(); ++k)
      if ((*weights)(a, k) != 0) fn((*ids)(a, k), (*weights)(a, k));
  }
};

/// A triangle contact point as a weighted sum of nodes, p = sum_j c_j x_{n_j} (nodes merged).
struct Stencil {
  std::vector<std::pair<int, Real>> terms;

  void build(const SurfaceMap& map, const MatX3i& F, const TriangleContact& c) {
    terms.clear();
    for (int a = 0; a < 3; ++a) {
      if (c.bary[a] == 0) continue;
      map.forEachNode(F(c.triangle, a), [&](int n, Real w) {
        for (auto& t : terms)
          if (t.first == n) {
            t.second += c.bary[a] * w;
            return;
          }
        terms.emplace_back(n, c.bary[a] * w);
      });
    }
  }
  Vec3 apply(const Real* rows) const {
    Vec3 p = Vec3::Zero();
    for (const auto& [n, cw] : terms) p += cw * Eigen::Map<const Vec3>(rows + 3 * n);
    return p;
  }
  /// sum_j c_j over the movable nodes (1 when every node can move).
  Real movableShare(const VecX& invMass) const {
    Real s = 0;
    for (const auto& [n, cw] : terms)
      if (invMass[n] > 0) s += std::abs(cw);
    return s;
  }
  /// sum_j w_j c_j^2 over the movable nodes.
  Real generalizedInverseMass(const VecX& invMass) const {
    Real s = 0;
    for (const auto& [n, cw] : terms)
      if (invMass[n] > 0) s += invMass[n] * cw * cw;
    return s;
  }
};

/// Coulomb friction as positions at a triangle contact point p (Macklin et al. 2014, "Unified
/// particle physics for real-time applications", Eq. (24)-(25)): p's tangential motion relative
/// to the instrument over the step is undone when shorter than muDepth (static), otherwise
/// shortened by muDepth (kinetic); with a velocity state the same share of p's tangential velocity
/// relative to the instrument is removed. Moves p (pNow) with the nodes and adds the impulse given
/// to the nodes (N s) to `impulse`.
void frictionCorrection(const ContactWorld& world, const Stencil& st, const TriangleContact& c,
                        const VecX& invMass, Real W, Real muDepth, Real dt, MatX3& x, Real* vel,
                        const MatX3& x0, Vec3& pNow, Vec3& impulse) {
  const Vec3 rel = (pNow - st.apply(x0.data())) - world.bodyDisplacement(c.body, pNow);
  const Vec3 tang = rel - rel.dot(c.normal) * c.normal;
  const Real len = tang.norm();
  if (!(len > 0)) return;
  const Real keep = len < muDepth ? 1 : muDepth / len;  // static: all of it
  const Vec3 undo = -keep * tang;
  Vec3 dvp = Vec3::Zero();
  if (vel) {
    const Vec3 vr = st.apply(vel) - world.bodyDisplacement(c.body, pNow) / dt;
    dvp = -keep * (vr - vr.dot(c.normal) * c.normal);
  }
  for (const auto& [n, cw] : st.terms) {
    const Real w = invMass[n];
    if (!(w > 0)) continue;
    const Vec3 dx = (w * cw / W) * undo;
    x.row(n) += dx.transpose();
    Vec3 dv = Vec3::Zero();
    if (vel) {
      dv = (w * cw / W) * dvp;
      Eigen::Map<Vec3>(vel + 3 * n) += dv;
    }
    impulse += (dx / dt + dv) / w;
  }
  pNow += undo;
}

ContactResolution resolveTriangleContacts(ContactWorld& world, MatX3& x, const SurfaceMap& map,
                                          const MatX3i& F, const VecX& invMass, Real dt, Real* vel,
                                          const MatX3* x0) {
  ContactResolution res;
  const Real mu = world.params().friction;
  const bool friction = x0 && mu > 0;
  const int passes = 4 * std::max(world.params().passes, 1);
  MatX3 buffer;
  Stencil st;
  BodyExchange bodies(world);
  for (int pass = 0; pass < passes; ++pass) {
    const MatX3& S = map.surface(x, buffer);
    const std::vector<TriangleContact> contacts = world.queryTriangles(S, F);
    if (pass == 0) res.contacts = static_cast<int>(contacts.size());
    if (contacts.empty()) break;
    // The surface at the query (x changes below): each depth is updated by the motion since.
    MatX3 copy;
    if (!map.ids) copy = x;
    const MatX3& atQuery = map.ids ? S : copy;
    for (const TriangleContact& c : contacts) {
      if (pass == 0) res.maxDepth = std::max(res.maxDepth, c.depth);
      st.build(map, F, c);
      const Real W = st.generalizedInverseMass(invMass);
      // A point held mostly by immovable nodes (a fixed or grasped vertex) cannot be moved by
      // the rest: the minimum-norm motion of a node with a small weight c grows like d / c.
      if (!(W > 0) || st.movableShare(invMass) < kMinMovableShare) continue;
      Vec3 pNow = st.apply(x.data());
      Vec3 pThen = Vec3::Zero();
      for (int a = 0; a < 3; ++a) pThen += c.bary[a] * atQuery.row(F(c.triangle, a)).transpose();
      const Real left = bodies.depth(c.body, c.depth - (pNow - pThen).dot(c.normal), c.normal);
      if (!(left > 0)) continue;
      // The tissue's share of the correction (all of it against a body the hand drives).
      const Real share = bodies.tissueShare(c.body, W);
      const Real depth = share * left;
      Vec3 impulse = Vec3::Zero();  // given to the nodes, N s
      // Normal: move p by depth n, remove (its share of) p's inward normal velocity.
      Real vn = 0;
      if (vel) vn = share * std::min(st.apply(vel).dot(c.normal), Real(0));
      for (const auto& [n, cw] : st.terms) {
        const Real w = invMass[n];
        if (!(w > 0)) continue;
        const Vec3 dx = (w * cw * depth / W) * c.normal;
        x.row(n) += dx.transpose();
        Vec3 dv = Vec3::Zero();
        if (vel) {
          dv = (-w * cw * vn / W) * c.normal;
          Eigen::Map<Vec3>(vel + 3 * n) += dv;
        }
        impulse += (dx / dt + dv) / w;
      }
      pNow += depth * c.normal;
      if (friction)
        frictionCorrection(world, st, c, invMass, W, mu * depth, dt, x, vel, *x0, pNow, impulse);
      bodies.push(c.body, impulse, dt);
      world.addReaction(c.body, -impulse / dt, pNow);
    }
  }
  return res;
}

ContactResolution penaltyTriangleForces(ContactWorld& world, const MatX3& x, const SurfaceMap& map,
                                        const MatX3i& F, const Real* vel, Real dt, Real* force) {
  ContactResolution res;
  const ContactParams& prm = world.params();
  MatX3 buffer;
  const MatX3& S = map.surface(x, buffer);
  const std::vector<TriangleContact> contacts = world.queryTriangles(S, F);
  res.contacts = static_cast<int>(contacts.size());
  Stencil st;
  for (const TriangleContact& c : contacts) {
    res.maxDepth = std::max(res.maxDepth, c.depth);
    const Vec3 a = S.row(F(c.triangle, 0)), b = S.row(F(c.triangle, 1)),
               e = S.row(F(c.triangle, 2));
    const Real area = 0.5 * (b - a).cross(e - a).norm();
    const Vec3 p = c.bary[0] * a + c.bary[1] * b + c.bary[2] * e;
    st.build(map, F, c);
    Real vn = 0;
    if (vel && dt > 0) vn = (st.apply(vel) - world.bodyDisplacement(c.body, p) / dt).dot(c.normal);
    const Real fn = area * (prm.stiffness * c.depth - prm.damping * std::min(vn, Real(0)));
    if (!(fn > 0)) continue;
    const Vec3 f = fn * c.normal;
    for (const auto& [n, cw] : st.terms) Eigen::Map<Vec3>(force + 3 * n) += cw * f;
    world.addReaction(c.body, -f, p);
  }
  return res;
}

/// Display-level projection: each point inside an instrument goes onto its surface plus the
/// thickness, with no reaction.
ContactResolution projectPointsOut(ContactWorld& world, MatX3& points) {
  ContactResolution res;
  const std::vector<Contact> contacts = world.query(points);
  res.contacts = static_cast<int>(contacts.size());
  for (const Contact& c : contacts) {
    res.maxDepth = std::max(res.maxDepth, c.depth);
    points.row(c.proxy) += (c.depth * c.normal).transpose();
  }
  return res;
}

const char* responseName(ContactResponse r) {
  static constexpr EnumName<ContactResponse> kNames[] = {{ContactResponse::Project, "Project"},
                                                         {ContactResponse::Penalty, "Penalty"},
                                                         {ContactResponse::Display, "Display"}};
  return enumName(kNames, r, "?");
}

/// A plugin's proxy that does not describe what its response needs is a programmer error; it is
/// reported in one line naming the field rather than read out of bounds.
void checkProxy(const ContactProxy& p, ContactResponse r, Real dt, const Real* force) {
  const auto fail = [r](const std::string& what) {
    throw std::invalid_argument(std::string("respondToContact(") + responseName(r) + "): " + what);
  };
  if (!p.nodes) fail("proxy.nodes is null");
  const Eigen::Index n = p.nodes->rows();
  const ContactEmbedding& e = p.embedding;
  if (e.points > 0 && (!e.ids || !e.weights || e.perPoint < 1))
    fail("proxy.embedding has points but no ids, weights or columns");
  const Eigen::Index points = e.points > 0 ? e.points : n;
  if (p.radii && (p.faces || e.points > 0 || p.radii->size() != points))
    fail("proxy.radii are for sphere proxies that are the nodes, one per node");
  if (r == ContactResponse::Display) {
    if (e.points > 0) fail("display-level projection moves points, not embedded nodes");
    return;
  }
  if (!(dt > 0)) fail("dt must be positive");
  if (r == ContactResponse::Penalty) {
    if (!p.faces) fail("penalty forces act on surface triangles: proxy.faces is null");
    if (!force) fail("penalty forces need a force array");
    return;
  }
  if (!p.invMass || p.invMass->size() != n) fail("proxy.invMass must hold one value per node");
  if (p.atStepStart && p.atStepStart->rows() != n) fail("proxy.atStepStart has not #nodes rows");
}

}  // namespace

ContactResolution respondToContact(ContactWorld& world, const ContactProxy& proxy,
                                   ContactResponse response, Real dt, Real* force) {
  checkProxy(proxy, response, dt, force);
  const ContactEmbedding& e = proxy.embedding;
  const bool embedded = e.points > 0;
  const Eigen::Map<const EmbeddingIds> idsMap(e.ids, e.points, e.perPoint);
  const Eigen::Map<const EmbeddingWeights> weightsMap(e.weights, e.points, e.perPoint);
  const Eigen::Ref<const EmbeddingIds> ids(idsMap);
  const Eigen::Ref<const EmbeddingWeights> weights(weightsMap);
  const SurfaceMap map = embedded ? SurfaceMap{&ids, &weights} : SurfaceMap{};
  MatX3& x = *proxy.nodes;
  switch (response) {
    case ContactResponse::Display:
      return projectPointsOut(world, x);
    case ContactResponse::Penalty:
      return penaltyTriangleForces(world, x, map, *proxy.faces, proxy.velocity, dt, force);
    case ContactResponse::Project:
      break;
  }
  if (proxy.faces)
    return resolveTriangleContacts(world, x, map, *proxy.faces, *proxy.invMass, dt, proxy.velocity,
                                   proxy.atStepStart);
  if (embedded)
    return projectEmbeddedSpheres(world, x, ids, weights, *proxy.invMass, dt, proxy.velocity);
  return projectSpheres(world, x, *proxy.invMass, dt, proxy.velocity, proxy.radii);
}

const char* contactMethodName(ContactMethod m) {
  return m == ContactMethod::Penalty ? "penalty" : "projection";
}

namespace {

/// The prescribed positions one solveWithContactConstraints() step has collected so far: per
/// instrument, the nodes it holds and their targets. A node once held stays with its target.
class HeldNodes {
 public:
  HeldNodes(const ContactWorld& world, const std::vector<int>& immovable)
      : m_immovable(immovable),
        m_nodes(size_t(world.numBodies())),
        m_targets(size_t(world.numBodies())),
        m_normals(size_t(world.numBodies())) {}

  bool free(int node) const {
    return m_owner[size_t(node)] < 0 &&
           !std::binary_search(m_immovable.begin(), m_immovable.end(), node);
  }
  /// free(), and a node released for pulling its instrument only when it penetrates deeper than
  /// the thickness (a released node still touching the skin is not held again).
  bool mayHold(int node, Real depth, Real thickness) const {
    return free(node) && (!m_released[size_t(node)] || depth > thickness);
  }
  void hold(int node, int body, const Vec3& target, const Vec3& normal) {
    m_owner[size_t(node)] = body;
    m_nodes[size_t(body)].push_back(node);
    m_targets[size_t(body)].push_back(target);
    m_normals[size_t(body)].push_back(normal);
  }
  void resize(Eigen::Index nodes) {
    m_owner.resize(size_t(nodes), -1);
    m_released.resize(size_t(nodes), 0);
  }

  /// The force of the held nodes on `body` with their forces `reaction`: the push along each
  /// node's contact normal, and of the rest (the held position also holds the node tangentially)
  /// at most mu times that push (Coulomb; frictionless: none).
  Vec3 contactForce(int body, const std::function<Vec3(int)>& reaction, Real mu) const {
    Vec3 total = Vec3::Zero();
    for (size_t k = 0; k < m_nodes[size_t(body)].size(); ++k) {
      const Vec3 f = reaction(m_nodes[size_t(body)][k]);
      const Vec3& n = m_normals[size_t(body)][k];
      const Real push = std::min(f.dot(n), Real(0));  // along -n: into the instrument
      total += push * n;
      const Vec3 tangential = f - f.dot(n) * n;
      const Real cap = mu * -push, len = tangential.norm();
      if (len > 0 && cap > 0) total += std::min(Real(1), cap / len) * tangential;
    }
    return total;
  }

  /// Frictionless contact pushes: every held node whose force on its instrument (`reaction`)
  /// has a component along the contact normal (out of the instrument, i.e. the tissue pulls it)
  /// is released. Returns how many were.
  int releaseAdhesive(const std::function<Vec3(int)>& reaction) {
    int released = 0;
    for (size_t b = 0; b < m_nodes.size(); ++b) {
      size_t keep = 0;
      for (size_t k = 0; k < m_nodes[b].size(); ++k) {
        const int node = m_nodes[b][k];
        if (reaction(node).dot(m_normals[b][k]) > 0) {
          m_owner[size_t(node)] = -1;
          m_released[size_t(node)] = 1;
          ++released;
          continue;
        }
        m_nodes[b][keep] = node;
        m_targets[b][keep] = m_targets[b][k];
        m_normals[b][keep] = m_normals[b][k];
        ++keep;
      }
      m_nodes[b].resize(keep);
      m_targets[b].resize(keep);
      m_normals[b].resize(keep);
    }
    return released;
  }

  /// Nodes within twice the thickness count as touching and stay prescribed where they are (a
  /// node set exactly on the skin would otherwise be free in the next step, be pulled back in by
  /// the tissue and slide off the instrument); deeper ones go onto the skin. True when a node
  /// deeper than the thickness was added.
  bool addPenetratingNodes(ContactWorld& world, const MatX3& x) {
    const Real t = world.params().thickness;
    const VecX radii = VecX::Constant(x.rows(), 2 * t);
    bool added = false;
    for (const Contact& c : world.query(x, &radii)) {
      if (!mayHold(c.proxy, c.depth, t)) continue;
      hold(c.proxy, c.body, x.row(c.proxy).transpose() + std::max(c.depth - t, Real(0)) * c.normal,
           c.normal);
      added = c.depth > t || added;
    }
    return added;
  }

  /// Every triangle within the thickness prescribes its free, movable vertices: the smallest
  /// motion that moves its deepest point by d n. True when a triangle inside an instrument (depth
  /// over the thickness) added vertices.
  bool addTriangleVertices(ContactWorld& world, const MatX3& x, const MatX3i& faces) {
    const Real t = world.params().thickness;
    bool added = false;
    for (const TriangleContact& c : world.queryTriangles(x, faces)) {
      Real sum2 = 0, share = 0;
      for (int a = 0; a < 3; ++a)
        if (mayHold(faces(c.triangle, a), c.depth, t)) {
          sum2 += c.bary[a] * c.bary[a];
          share += c.bary[a];
        }
      if (!(sum2 > 0) || share < kMinMovableShare) continue;
      for (int a = 0; a < 3; ++a) {
        const int v = faces(c.triangle, a);
        if (!mayHold(v, c.depth, t)) continue;
        hold(v, c.body, x.row(v).transpose() + (c.bary[a] * c.depth / sum2) * c.normal, c.normal);
      }
      added = c.depth > t || added;
    }
    return added;
  }

  /// A vertex moved along the normal at a triangle's deepest point can still be inside a curved
  /// instrument: its target goes onto the skin like a penetrating node's.
  void pushTargetsOut(ContactWorld& world) {
    for (std::vector<Vec3>& targets : m_targets) {
      if (targets.empty()) continue;
      MatX3 at(static_cast<Eigen::Index>(targets.size()), 3);
      for (size_t k = 0; k < targets.size(); ++k) at.row(Eigen::Index(k)) = targets[k].transpose();
      for (const Contact& c : world.query(at)) targets[size_t(c.proxy)] += c.depth * c.normal;
    }
  }

  /// `in` with one NodeGrasp per instrument that holds nodes appended; `bodies` gets their order.
  StepInput constrained(const StepInput& in, std::vector<int>& bodies) const {
    StepInput aug = in;
    bodies.clear();
    for (size_t b = 0; b < m_nodes.size(); ++b) {
      if (m_nodes[b].empty()) continue;
      NodeGrasp g;
      g.tool = -1;
      g.nodes = m_nodes[b];
      g.targets.resize(static_cast<Eigen::Index>(m_nodes[b].size()), 3);
      for (size_t k = 0; k < m_nodes[b].size(); ++k)
        g.targets.row(Eigen::Index(k)) = m_targets[b][k].transpose();
      aug.nodeConstraints.push_back(std::move(g));
      bodies.push_back(int(b));
    }
    return aug;
  }

 private:
  const std::vector<int>& m_immovable;
  std::vector<int> m_owner;      // body holding each node, -1 if free
  std::vector<char> m_released;  // released this step for pulling its instrument
  std::vector<std::vector<int>> m_nodes;
  std::vector<std::vector<Vec3>> m_targets;
  std::vector<std::vector<Vec3>> m_normals;  // contact normal (out of the instrument) per node
};

/// The rounds of detection and solve at the instruments' current poses.
StepStatus solveWithConstraints(ContactWorld& world, const ContactProxy& proxy, const StepInput& in,
                                const ContactConstraintSolver& solver) {
  HeldNodes held(world, solver.immovable);
  std::vector<int> lastBodies;
  StepStatus status = StepStatus::Ok;
  const int rounds = std::max(solver.maxRounds, 1);
  bool released = false;
  for (int round = 0; round < rounds; ++round) {
    const MatX3& x = *proxy.nodes;
    held.resize(x.rows());
    bool added = held.addPenetratingNodes(world, x);
    if (proxy.faces) {
      added = held.addTriangleVertices(world, x, *proxy.faces) || added;
      held.pushTargetsOut(world);
    }
    if (!added && !released && round > 0) break;
    status = solver.solve(held.constrained(in, lastBodies));
    if (status != StepStatus::Ok) return status;
    // Nodes that pull their instrument let go, and the next round solves without them (never
    // after the last round: the state reported is always a solve of the held set).
    released =
        solver.nodeReaction && round + 1 < rounds && held.releaseAdhesive(solver.nodeReaction) > 0;
  }
  if (solver.nodeReaction) {
    // From the nodes' own forces: the push, and friction only as far as the scene's coefficient
    // allows (the held positions hold the nodes tangentially as well).
    for (int b : lastBodies)
      world.addReaction(b, held.contactForce(b, solver.nodeReaction, world.params().friction),
                        world.position(b));
  } else if (solver.graspForces) {
    const std::vector<Vec3> f = solver.graspForces();
    for (size_t k = 0; k < lastBodies.size(); ++k) {
      const size_t idx = in.grasps.size() + k;
      if (idx < f.size()) world.addReaction(lastBodies[k], f[idx], world.position(lastBodies[k]));
    }
  }
  return status;
}

/// solveWithConstraints() in sub-steps along the instruments' path since the settled poses.
StepStatus alongInstrumentPath(ContactWorld& world, const ContactProxy& proxy, const StepInput& in,
                               const ContactConstraintSolver& solver) {
  const int nb = world.numBodies();
  std::vector<Vec3> from(nb), to(nb);
  std::vector<Mat3> rot(nb);
  int steps = 1;
  for (int b = 0; b < nb; ++b) {
    from[b] = world.settledPosition(b);
    to[b] = world.position(b);
    rot[b] = world.rotation(b);
    const Real len = solver.maxStepFraction * world.thinnestRadius(b);
    if (len > 0 && std::isfinite(len))
      steps = std::max(steps, static_cast<int>(std::ceil((to[b] - from[b]).norm() / len)));
  }
  steps = std::min(steps, 1000);
  StepStatus status = StepStatus::Ok;
  for (int s = 1; s <= steps; ++s) {
    const Real a = Real(s) / steps;
    for (int b = 0; b < nb; ++b) world.setPose(b, (1 - a) * from[b] + a * to[b], rot[b]);
    world.clearReactions();
    status = solveWithConstraints(world, proxy, in, solver);
    if (status != StepStatus::Ok) break;
  }
  for (int b = 0; b < nb; ++b) world.setPose(b, to[b], rot[b]);
  world.settle();
  return status;
}

}  // namespace

StepStatus solveWithContactConstraints(ContactWorld& world, const ContactProxy& proxy,
                                       const StepInput& in, const ContactConstraintSolver& solver) {
  if (!proxy.nodes || !solver.solve)
    throw std::invalid_argument("solveWithContactConstraints: proxy.nodes or solver.solve is null");
  if (proxy.embedding.points > 0 || proxy.radii)
    throw std::invalid_argument(
        "solveWithContactConstraints: the proxy's points must be its nodes (no embedding, radii)");
  if (!std::is_sorted(solver.immovable.begin(), solver.immovable.end()))
    throw std::invalid_argument("solveWithContactConstraints: solver.immovable must be sorted");
  return solver.followInstrumentPath ? alongInstrumentPath(world, proxy, in, solver)
                                     : solveWithConstraints(world, proxy, in, solver);
}

}  // namespace deform
