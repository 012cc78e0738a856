// Contact between rigid instruments and model proxies through Bullet's collision world.
#include <deform/contact.h>
#include <deform/error.h>

#include <algorithm>
#include <cmath>
#include <limits>

#ifdef DEFORM_HAVE_BULLET
#include <LinearMath/btAabbUtil2.h>
#include <btBulletCollisionCommon.h>
#endif

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

#ifdef DEFORM_HAVE_BULLET

namespace {

// Collision filter groups: proxies only meet instruments, never each other (overlapping proxy
// spheres would otherwise fill the broadphase's pair cache).
constexpr int kProxyGroup = 0x40;
constexpr int kBodyGroup = 0x80;
// Bullet's shapes default to a 4 cm collision margin (a game-world size); ours are millimetres.
constexpr btScalar kMargin = 1e-6;

btVector3 bt(const Vec3& v) {
  return btVector3(v.x(), v.y(), v.z());
}
Vec3 eig(const btVector3& v) {
  return Vec3(v.x(), v.y(), v.z());
}

/// Rotation taking the y axis (Bullet's capsule axis) to the unit vector a.
btMatrix3x3 yTo(const Vec3& a) {
  const Eigen::Quaternion<Real> q = Eigen::Quaternion<Real>::FromTwoVectors(Vec3::UnitY(), a);
  const Mat3 R = q.toRotationMatrix();
  return btMatrix3x3(R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0), R(2, 1),
                     R(2, 2));
}

/// Keeps the deepest contact per proxy.
struct DeepestCallback : btCollisionWorld::ContactResultCallback {
  const btCollisionObject* proxy = nullptr;
  Real deepest = 0;  // most negative distance seen
  Vec3 normal = Vec3::UnitZ();
  bool found = false;

  btScalar addSingleResult(btManifoldPoint& cp, const btCollisionObjectWrapper* w0, int, int,
                           const btCollisionObjectWrapper*, int, int) override {
    const Real dist = cp.getDistance();
    if (dist >= 0 || (found && dist >= deepest)) return 0;
    // normalWorldOnB points from B to A; A is the first wrapper.
    Vec3 n = eig(cp.m_normalWorldOnB);
    if (w0->getCollisionObject() != proxy) n = -n;
    const Real len = n.norm();
    if (!(len > 0.5)) return 0;
    deepest = dist;
    normal = n / len;
    found = true;
    return 0;
  }
};

}  // namespace

struct ContactWorld::Impl {
  btDefaultCollisionConfiguration config;
  btCollisionDispatcher dispatcher{&config};
  btDbvtBroadphase broadphase;
  btCollisionWorld world{&dispatcher, &broadphase, &config};

  struct Body {
    std::vector<std::unique_ptr<btCollisionShape>> children;
    std::unique_ptr<btCompoundShape> compound;
    std::unique_ptr<btCollisionObject> object;
  };
  std::vector<Body> bodies;

  // A pool of proxy spheres: a query inserts only the proxies near an instrument and takes them
  // out again, so the broadphase never holds thousands of densely packed leaves.
  std::vector<std::unique_ptr<btSphereShape>> proxyShapes;
  std::vector<std::unique_ptr<btCollisionObject>> proxies;
  int inWorld = 0;

  ~Impl() {
    removeProxies();
    for (auto& b : bodies) world.removeCollisionObject(b.object.get());
  }

  // Tight AABBs set directly: btCollisionWorld::updateAabbs() would inflate every box by the
  // global contact breaking threshold (2 cm), turning millimetre contacts into thousands of pairs.
  void setAabb(btCollisionObject* o) {
    btVector3 lo, hi;
    o->getCollisionShape()->getAabb(o->getWorldTransform(), lo, hi);
    broadphase.setAabb(o->getBroadphaseHandle(), lo, hi, &dispatcher);
  }

  void addProxy(int index, const btVector3& centre, btScalar radius) {
    if (inWorld == static_cast<int>(proxies.size())) {
      proxyShapes.push_back(std::make_unique<btSphereShape>(radius));
      proxies.push_back(std::make_unique<btCollisionObject>());
      proxies.back()->setCollisionShape(proxyShapes.back().get());
    }
    btSphereShape* s = proxyShapes[inWorld].get();
    if (s->getRadius() != radius) s->setUnscaledRadius(radius);
    btCollisionObject* o = proxies[inWorld].get();
    btTransform t;
    t.setIdentity();
    t.setOrigin(centre);
    o->setWorldTransform(t);
    o->setUserIndex(index);
    world.addCollisionObject(o, kProxyGroup, kBodyGroup);
    ++inWorld;
  }

  void removeProxies() {
    for (int k = inWorld - 1; k >= 0; --k) world.removeCollisionObject(proxies[k].get());
    inWorld = 0;
  }
};

ContactWorld::ContactWorld(const ContactParams& params)
    : m_params(params), m_impl(std::make_unique<Impl>()) {}

ContactWorld::~ContactWorld() = default;

int ContactWorld::addBody(const RigidShape& shape) {
  Impl::Body b;
  b.compound = std::make_unique<btCompoundShape>(true, static_cast<int>(shape.parts.size()));
  for (const ShapePrimitive& p : shape.parts) {
    std::unique_ptr<btCollisionShape> child;
    btTransform t;
    t.setIdentity();
    t.setOrigin(bt(p.centre));
    switch (p.kind) {
      case ShapePrimitive::Kind::Sphere:
        child = std::make_unique<btSphereShape>(p.radius);
        break;
      case ShapePrimitive::Kind::Capsule:
        child = std::make_unique<btCapsuleShape>(p.radius, p.length);
        t.setBasis(yTo(p.axis.normalized()));
        break;
      case ShapePrimitive::Kind::Box: {
        auto box = std::make_unique<btBoxShape>(bt(p.halfExtents));
        box->setMargin(kMargin);
        child = std::move(box);
        break;
      }
    }
    b.compound->addChildShape(t, child.get());
    b.children.push_back(std::move(child));
  }
  b.object = std::make_unique<btCollisionObject>();
  b.object->setCollisionShape(b.compound.get());
  b.object->setUserIndex(-1 - static_cast<int>(m_impl->bodies.size()));
  m_impl->world.addCollisionObject(b.object.get(), kBodyGroup, kProxyGroup);
  m_impl->setAabb(b.object.get());
  m_impl->bodies.push_back(std::move(b));
  m_force.push_back(Vec3::Zero());
  m_torque.push_back(Vec3::Zero());
  Real thin = std::numeric_limits<Real>::infinity();
  for (const ShapePrimitive& p : shape.parts)
    thin =
        std::min(thin, p.kind == ShapePrimitive::Kind::Box ? p.halfExtents.minCoeff() : p.radius);
  m_thinnest.push_back(thin);
  m_settled.push_back(Vec3::Zero());
  m_settledSet.push_back(0);
  return numBodies() - 1;
}

void ContactWorld::setPose(int body, const Vec3& pos, const Mat3& R) {
  btTransform t;
  t.setOrigin(bt(pos));
  t.setBasis(
      btMatrix3x3(R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0), R(2, 1), R(2, 2)));
  btCollisionObject* o = m_impl->bodies.at(body).object.get();
  o->setWorldTransform(t);
  m_impl->setAabb(o);
  if (!m_settledSet[body]) {
    m_settled[body] = pos;
    m_settledSet[body] = 1;
  }
}

Mat3 ContactWorld::rotation(int body) const {
  const btMatrix3x3& b = m_impl->bodies.at(body).object->getWorldTransform().getBasis();
  Mat3 R;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) R(i, j) = b[i][j];
  return R;
}

Vec3 ContactWorld::position(int body) const {
  return eig(m_impl->bodies.at(body).object->getWorldTransform().getOrigin());
}

int ContactWorld::numBodies() const {
  return static_cast<int>(m_impl->bodies.size());
}

std::vector<Contact> ContactWorld::query(const MatX3& centres, const VecX* radii) {
  Impl& w = *m_impl;
  const Eigen::Index n = centres.rows();
  if (w.bodies.empty()) return {};
  // Only proxies inside the instruments' bounding box enter Bullet's world (and leave it after
  // the query): the broadphase then pairs them with the instruments' parts.
  btVector3 lo(BT_LARGE_FLOAT, BT_LARGE_FLOAT, BT_LARGE_FLOAT), hi = -lo;
  for (const Impl::Body& b : w.bodies) {
    const btBroadphaseProxy* h = b.object->getBroadphaseHandle();
    lo.setMin(h->m_aabbMin);
    hi.setMax(h->m_aabbMax);
  }
  for (Eigen::Index i = 0; i < n; ++i) {
    const Real r = radii ? std::max((*radii)[i], Real(1e-9)) : m_params.thickness;
    const btVector3 c(centres(i, 0), centres(i, 1), centres(i, 2));
    if (c.x() + r < lo.x() || c.y() + r < lo.y() || c.z() + r < lo.z() || c.x() - r > hi.x() ||
        c.y() - r > hi.y() || c.z() - r > hi.z())
      continue;
    w.addProxy(static_cast<int>(i), c, r);
  }
  w.broadphase.calculateOverlappingPairs(&w.dispatcher);

  std::vector<Contact> out;
  btBroadphasePairArray& pairs = w.broadphase.getOverlappingPairCache()->getOverlappingPairArray();
  for (int k = 0; k < pairs.size(); ++k) {
    auto* a = static_cast<btCollisionObject*>(pairs[k].m_pProxy0->m_clientObject);
    auto* b = static_cast<btCollisionObject*>(pairs[k].m_pProxy1->m_clientObject);
    if (a->getUserIndex() < 0) std::swap(a, b);
    if (a->getUserIndex() < 0 || b->getUserIndex() >= 0) continue;
    // The broadphase pairs leaves by their fattened volumes (Bullet's global 5 cm margin): keep
    // only pairs whose tight boxes overlap.
    const btBroadphaseProxy* pa = a->getBroadphaseHandle();
    const btBroadphaseProxy* pb = b->getBroadphaseHandle();
    if (!TestAabbAgainstAabb2(pa->m_aabbMin, pa->m_aabbMax, pb->m_aabbMin, pb->m_aabbMax)) continue;
    ++m_pairsTested;
    DeepestCallback cb;
    cb.proxy = a;
    w.world.contactPairTest(a, b, cb);
    if (!cb.found) continue;
    Contact c;
    c.proxy = a->getUserIndex();
    c.body = -1 - b->getUserIndex();
    c.depth = -cb.deepest;
    c.normal = cb.normal;
    out.push_back(c);
  }
  w.removeProxies();
  // Deepest per proxy, in proxy order (the pair cache's order is not part of the contract).
  std::sort(out.begin(), out.end(), [](const Contact& x, const Contact& y) {
    return x.proxy != y.proxy ? x.proxy < y.proxy : x.depth > y.depth;
  });
  out.erase(std::unique(out.begin(), out.end(),
                        [](const Contact& x, const Contact& y) { return x.proxy == y.proxy; }),
            out.end());
  m_contactsFound += static_cast<long long>(out.size());
  return out;
}

#else  // no Bullet: the world cannot be built; the harness reports it before any run

struct ContactWorld::Impl {};

ContactWorld::ContactWorld(const ContactParams& params) : m_params(params) {
  throw UnsupportedError("contact needs Bullet (libbullet-dev), which this build lacks");
}
ContactWorld::~ContactWorld() = default;
int ContactWorld::addBody(const RigidShape&) {
  return -1;
}
void ContactWorld::setPose(int, const Vec3&, const Mat3&) {}
Vec3 ContactWorld::position(int) const {
  return Vec3::Zero();
}
Mat3 ContactWorld::rotation(int) const {
  return Mat3::Identity();
}
int ContactWorld::numBodies() const {
  return 0;
}
std::vector<Contact> ContactWorld::query(const MatX3&, const VecX*) {
  return {};
}

#endif

void ContactWorld::addReaction(int body, const Vec3& force, const Vec3& at) {
  m_force.at(body) += force;
  m_torque.at(body) += (at - position(body)).cross(force);
}

Vec3 ContactWorld::reactionForce(int body) const {
  return m_force.at(body);
}

Vec3 ContactWorld::reactionTorque(int body) const {
  return m_torque.at(body);
}

Real ContactWorld::thinnestRadius(int body) const {
  return m_thinnest.at(body);
}

Vec3 ContactWorld::settledPosition(int body) const {
  return m_settled.at(body);
}

void ContactWorld::settle() {
  for (int b = 0; b < numBodies(); ++b) {
    m_settled[b] = position(b);
    m_settledSet[b] = 1;
  }
}

void ContactWorld::clearReactions() {
  std::fill(m_force.begin(), m_force.end(), Vec3::Zero());
  std::fill(m_torque.begin(), m_torque.end(), Vec3::Zero());
}

ContactResolution resolveContacts(ContactWorld& world, MatX3& x, const VecX& invMass, Real dt,
                                  MatX3* v, const VecX* radii) {
  ContactResolution res;
  const int passes = std::max(world.params().passes, 1);
  for (int pass = 0; pass < passes; ++pass) {
    const std::vector<Contact> contacts = world.query(x, radii);
    if (pass == 0) res.contacts = static_cast<int>(contacts.size());
    if (contacts.empty()) break;
    for (const Contact& c : contacts) {
      const Real w = invMass[c.proxy];
      if (!(w > 0)) continue;
      if (pass == 0) res.maxDepth = std::max(res.maxDepth, c.depth);
      const Vec3 dx = c.depth * c.normal;
      x.row(c.proxy) += dx.transpose();
      Vec3 impulsePerMass = dx / dt;
      if (v) {
        const Real vn = v->row(c.proxy).dot(c.normal);
        if (vn < 0) {
          v->row(c.proxy) -= (vn * c.normal).transpose();
          impulsePerMass -= vn * c.normal;
        }
      }
      const Vec3 onNode = impulsePerMass / (w * dt);
      world.addReaction(c.body, -onNode, x.row(c.proxy).transpose());
    }
  }
  return res;
}

ContactResolution resolveEmbeddedContacts(ContactWorld& world, MatX3& nodes,
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
      const Real depth = c.depth - (now - points.row(c.proxy).transpose()).dot(c.normal);
      if (!(depth > 0)) continue;
      Real sumW2 = 0;
      for (Eigen::Index k = 0; k < K; ++k)
        if (invMass[ids(c.proxy, k)] > 0) sumW2 += weights(c.proxy, k) * weights(c.proxy, k);
      if (!(sumW2 > 0)) continue;
      for (Eigen::Index k = 0; k < K; ++k) {
        const int a = ids(c.proxy, k);
        const Real w = invMass[a];
        if (!(w > 0) || weights(c.proxy, k) == 0) continue;
        const Vec3 dx = (weights(c.proxy, k) * depth / sumW2) * c.normal;
        nodes.row(a) += dx.transpose();
        Vec3 impulsePerMass = dx / dt;
        if (nodeVelocity) {
          Eigen::Map<Vec3> v(nodeVelocity + 3 * a);
          const Real vn = v.dot(c.normal);
          if (vn < 0) {
            v -= vn * c.normal;
            impulsePerMass -= vn * c.normal;
          }
        }
        world.addReaction(c.body, -impulsePerMass / (w * dt), nodes.row(a).transpose());
      }
    }
  }
  return res;
}

int projectPointsOut(ContactWorld& world, MatX3& points) {
  const std::vector<Contact> contacts = world.query(points);
  for (const Contact& c : contacts) points.row(c.proxy) += (c.depth * c.normal).transpose();
  return static_cast<int>(contacts.size());
}

StepStatus solveWithContactConstraints(ContactWorld& world, const StepInput& in,
                                       const ContactModelHooks& model,
                                       const std::vector<int>& immovable, int maxRounds) {
  const int bodies = world.numBodies();
  std::vector<std::vector<int>> nodes(bodies);
  std::vector<std::vector<Vec3>> targets(bodies);
  std::vector<int> owner;  // body of each constrained node, -1 if free
  std::vector<int> lastBodies;
  StepStatus status = StepStatus::Ok;
  for (int round = 0; round < std::max(maxRounds, 1); ++round) {
    const MatX3& x = model.nodes();
    owner.resize(static_cast<size_t>(x.rows()), -1);
    bool added = false;
    // Nodes within twice the thickness count as touching and stay prescribed where they are (a
    // node set exactly on the skin would otherwise be free in the next step, be pulled back in
    // by the tissue and slide off the instrument); deeper ones go onto the skin.
    const Real t = world.params().thickness;
    const VecX radii = VecX::Constant(x.rows(), 2 * t);
    for (const Contact& c : world.query(x, &radii)) {
      if (owner[c.proxy] >= 0 || std::binary_search(immovable.begin(), immovable.end(), c.proxy))
        continue;
      owner[c.proxy] = c.body;
      nodes[c.body].push_back(c.proxy);
      targets[c.body].push_back(x.row(c.proxy).transpose() +
                                std::max(c.depth - t, Real(0)) * c.normal);
      added = c.depth > t || added;
    }
    if (!added && round > 0) break;
    StepInput aug = in;
    lastBodies.clear();
    for (int b = 0; b < bodies; ++b) {
      if (nodes[b].empty()) continue;
      GraspInput g;
      g.tool = -1;
      g.nodes = nodes[b];
      g.targets.resize(static_cast<Eigen::Index>(nodes[b].size()), 3);
      for (size_t k = 0; k < nodes[b].size(); ++k) g.targets.row(k) = targets[b][k].transpose();
      aug.grasps.push_back(std::move(g));
      lastBodies.push_back(b);
    }
    status = model.solve(aug);
    if (status != StepStatus::Ok) return status;
  }
  if (model.graspForces) {
    const std::vector<Vec3> f = model.graspForces();
    for (size_t k = 0; k < lastBodies.size(); ++k) {
      const size_t idx = in.grasps.size() + k;
      if (idx < f.size()) world.addReaction(lastBodies[k], f[idx], world.position(lastBodies[k]));
    }
  }
  return status;
}

StepStatus solveAlongInstrumentPath(ContactWorld& world, const StepInput& in,
                                    const ContactModelHooks& model,
                                    const std::vector<int>& immovable, int maxRounds,
                                    Real maxStepFraction) {
  const int nb = world.numBodies();
  std::vector<Vec3> from(nb), to(nb);
  std::vector<Mat3> rot(nb);
  int steps = 1;
  for (int b = 0; b < nb; ++b) {
    from[b] = world.settledPosition(b);
    to[b] = world.position(b);
    rot[b] = world.rotation(b);
    const Real len = maxStepFraction * world.thinnestRadius(b);
    if (len > 0 && std::isfinite(len))
      steps = std::max(steps, static_cast<int>(std::ceil((to[b] - from[b]).norm() / len)));
  }
  steps = std::min(steps, 1000);
  StepStatus status = StepStatus::Ok;
  for (int s = 1; s <= steps; ++s) {
    const Real a = Real(s) / steps;
    for (int b = 0; b < nb; ++b) world.setPose(b, (1 - a) * from[b] + a * to[b], rot[b]);
    world.clearReactions();
    status = solveWithContactConstraints(world, in, model, immovable, maxRounds);
    if (status != StepStatus::Ok) break;
  }
  for (int b = 0; b < nb; ++b) world.setPose(b, to[b], rot[b]);
  world.settle();
  return status;
}

}  // namespace deform
