// The contact world's Bullet back end (contact_backend.h): the instruments as compound shapes in
// a btCollisionWorld, proxies and surface triangles inserted around each query. Its own shared
// object, loaded by ContactWorld on first use.
#include "contact_backend.h"

#include <deform/geometry/distance.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>

#include <BulletCollision/CollisionShapes/btTriangleShape.h>
#include <LinearMath/btAabbUtil2.h>
#include <btBulletCollisionCommon.h>

namespace deform {

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

/// Keeps the closest result per triangle, separated ones (within the callback's threshold)
/// included, with the point on the triangle.
struct ClosestCallback : btCollisionWorld::ContactResultCallback {
  const btCollisionObject* proxy = nullptr;
  Real closest = std::numeric_limits<Real>::infinity();
  Vec3 normal = Vec3::UnitZ();
  Vec3 point = Vec3::Zero();
  bool found = false;

  btScalar addSingleResult(btManifoldPoint& cp, const btCollisionObjectWrapper* w0, int, int,
                           const btCollisionObjectWrapper*, int, int) override {
    const Real dist = cp.getDistance();
    if (dist >= m_closestDistanceThreshold || (found && dist >= closest)) return 0;
    const bool proxyIsA = w0->getCollisionObject() == proxy;
    Vec3 n = eig(cp.m_normalWorldOnB);  // from B to A
    if (!proxyIsA) n = -n;
    const Real len = n.norm();
    if (!(len > 0.5)) return 0;
    closest = dist;
    normal = n / len;
    point = eig(proxyIsA ? cp.getPositionWorldOnA() : cp.getPositionWorldOnB());
    found = true;
    return 0;
  }
};

/// Keeps the deepest contact of each key(contact) (a proxy or triangle index), in key order (the
/// pair cache's order is not part of the contract).
template <class C, class Key>
void keepDeepestPerKey(std::vector<C>& out, Key key) {
  std::sort(out.begin(), out.end(), [&](const C& x, const C& y) {
    return key(x) != key(y) ? key(x) < key(y) : x.depth > y.depth;
  });
  out.erase(
      std::unique(out.begin(), out.end(), [&](const C& x, const C& y) { return key(x) == key(y); }),
      out.end());
}

}  // namespace

class BulletContactBackend final : public ContactBackend {
 public:
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

  ~BulletContactBackend() override {
    removeProxies();
    removeTriangles();
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

  /// The union of the instruments' broadphase boxes: only proxies inside it enter the world.
  void bodiesBox(btVector3& lo, btVector3& hi) const {
    lo = btVector3(BT_LARGE_FLOAT, BT_LARGE_FLOAT, BT_LARGE_FLOAT);
    hi = -lo;
    for (const Body& b : bodies) {
      const btBroadphaseProxy* h = b.object->getBroadphaseHandle();
      lo.setMin(h->m_aabbMin);
      hi.setMax(h->m_aabbMax);
    }
  }

  /// Runs the broadphase and calls fn(proxy, body) for every pair of a proxy (user index >= 0)
  /// and an instrument (user index < 0) whose tight boxes overlap. The broadphase pairs leaves by
  /// their fattened volumes (Bullet's global 5 cm margin), hence the second test.
  template <class Fn>
  void forEachProxyBodyPair(Fn&& fn) {
    broadphase.calculateOverlappingPairs(&dispatcher);
    btBroadphasePairArray& pairs = broadphase.getOverlappingPairCache()->getOverlappingPairArray();
    for (int k = 0; k < pairs.size(); ++k) {
      auto* a = static_cast<btCollisionObject*>(pairs[k].m_pProxy0->m_clientObject);
      auto* b = static_cast<btCollisionObject*>(pairs[k].m_pProxy1->m_clientObject);
      if (a->getUserIndex() < 0) std::swap(a, b);
      if (a->getUserIndex() < 0 || b->getUserIndex() >= 0) continue;
      const btBroadphaseProxy* pa = a->getBroadphaseHandle();
      const btBroadphaseProxy* pb = b->getBroadphaseHandle();
      if (!TestAabbAgainstAabb2(pa->m_aabbMin, pa->m_aabbMax, pb->m_aabbMin, pb->m_aabbMax))
        continue;
      fn(a, b);
    }
  }

  /// The contact test of every proxy-instrument pair (forEachProxyBodyPair), counted in
  /// pairsTested, each with a copy of `prototype` pointed at the proxy: a pair with a result goes
  /// to found(proxy user index, instrument part index, callback).
  template <class Callback, class Found>
  void testProxyBodyPairs(const Callback& prototype, long long& pairsTested, Found&& found) {
    forEachProxyBodyPair([&](btCollisionObject* a, btCollisionObject* b) {
      ++pairsTested;
      Callback cb = prototype;
      cb.proxy = a;
      world.contactPairTest(a, b, cb);
      if (cb.found) found(a->getUserIndex(), -1 - b->getUserIndex(), cb);
    });
  }

  // The same pool for surface triangles; their broadphase boxes are padded by the thickness.
  std::vector<std::unique_ptr<btTriangleShape>> triangleShapes;
  std::vector<std::unique_ptr<btCollisionObject>> triangles;
  int trianglesInWorld = 0;

  void addTriangle(int index, const btVector3& a, const btVector3& b, const btVector3& c,
                   btScalar pad) {
    if (trianglesInWorld == static_cast<int>(triangles.size())) {
      triangleShapes.push_back(std::make_unique<btTriangleShape>(a, b, c));
      triangleShapes.back()->setMargin(kMargin);
      triangles.push_back(std::make_unique<btCollisionObject>());
      triangles.back()->setCollisionShape(triangleShapes.back().get());
    }
    btTriangleShape* s = triangleShapes[trianglesInWorld].get();
    s->m_vertices1[0] = a;
    s->m_vertices1[1] = b;
    s->m_vertices1[2] = c;
    btCollisionObject* o = triangles[trianglesInWorld].get();
    btTransform t;
    t.setIdentity();
    o->setWorldTransform(t);
    o->setUserIndex(index);
    world.addCollisionObject(o, kProxyGroup, kBodyGroup);
    btVector3 lo = a, hi = a;
    lo.setMin(b);
    lo.setMin(c);
    hi.setMax(b);
    hi.setMax(c);
    const btVector3 p(pad, pad, pad);
    broadphase.setAabb(o->getBroadphaseHandle(), lo - p, hi + p, &dispatcher);
    ++trianglesInWorld;
  }

  void removeTriangles() {
    for (int k = trianglesInWorld - 1; k >= 0; --k) world.removeCollisionObject(triangles[k].get());
    trianglesInWorld = 0;
  }

  int addBody(const RigidShape& shape) override {
    Body b;
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
    b.object->setUserIndex(-1 - static_cast<int>(bodies.size()));
    world.addCollisionObject(b.object.get(), kBodyGroup, kProxyGroup);
    setAabb(b.object.get());
    bodies.push_back(std::move(b));
    return numBodies() - 1;
  }

  void setPose(int body, const Vec3& pos, const Mat3& R) override {
    btTransform t;
    t.setOrigin(bt(pos));
    t.setBasis(btMatrix3x3(R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0), R(2, 1),
                           R(2, 2)));
    btCollisionObject* o = bodies.at(body).object.get();
    o->setWorldTransform(t);
    setAabb(o);
  }

  Mat3 rotation(int body) const override {
    const btMatrix3x3& b = bodies.at(body).object->getWorldTransform().getBasis();
    Mat3 R;
    for (int i = 0; i < 3; ++i)
      for (int j = 0; j < 3; ++j) R(i, j) = b[i][j];
    return R;
  }

  Vec3 position(int body) const override {
    return eig(bodies.at(body).object->getWorldTransform().getOrigin());
  }

  int numBodies() const override { return static_cast<int>(bodies.size()); }

  std::vector<Contact> query(const MatX3& centres, const VecX* radii, Real thickness,
                             long long& pairsTested) override {
    BulletContactBackend& w = *this;
    const Eigen::Index n = centres.rows();
    if (w.bodies.empty()) return {};
    // Only proxies inside the instruments' bounding box enter Bullet's world (and leave it after
    // the query): the broadphase then pairs them with the instruments' parts.
    btVector3 lo, hi;
    w.bodiesBox(lo, hi);
    for (Eigen::Index i = 0; i < n; ++i) {
      const Real r = radii ? std::max((*radii)[i], Real(1e-9)) : thickness;
      const btVector3 c(centres(i, 0), centres(i, 1), centres(i, 2));
      if (c.x() + r < lo.x() || c.y() + r < lo.y() || c.z() + r < lo.z() || c.x() - r > hi.x() ||
          c.y() - r > hi.y() || c.z() - r > hi.z())
        continue;
      w.addProxy(static_cast<int>(i), c, r);
    }
    std::vector<Contact> out;
    w.testProxyBodyPairs(DeepestCallback{}, pairsTested,
                         [&](int proxy, int body, const DeepestCallback& cb) {
                           Contact c;
                           c.proxy = proxy;
                           c.body = body;
                           c.depth = -cb.deepest;
                           c.normal = cb.normal;
                           out.push_back(c);
                         });
    w.removeProxies();
    keepDeepestPerKey(out, [](const Contact& c) { return c.proxy; });
    return out;
  }

  std::vector<TriangleContact> queryTriangles(const MatX3& V, const MatX3i& F, Real thickness,
                                              long long& pairsTested) override {
    BulletContactBackend& w = *this;
    if (w.bodies.empty()) return {};
    const Real t = thickness;
    btVector3 lo, hi;
    w.bodiesBox(lo, hi);
    const auto vertex = [&](int i) { return btVector3(V(i, 0), V(i, 1), V(i, 2)); };
    for (Eigen::Index f = 0; f < F.rows(); ++f) {
      const btVector3 a = vertex(F(f, 0)), b = vertex(F(f, 1)), c = vertex(F(f, 2));
      btVector3 tlo = a, thi = a;
      tlo.setMin(b);
      tlo.setMin(c);
      thi.setMax(b);
      thi.setMax(c);
      if (tlo.x() - t > hi.x() || tlo.y() - t > hi.y() || tlo.z() - t > hi.z() ||
          thi.x() + t < lo.x() || thi.y() + t < lo.y() || thi.z() + t < lo.z())
        continue;
      w.addTriangle(static_cast<int>(f), a, b, c, t);
    }
    std::vector<TriangleContact> out;
    ClosestCallback within;
    within.m_closestDistanceThreshold = t;
    w.testProxyBodyPairs(
        within, pairsTested, [&](int triangle, int body, const ClosestCallback& cb) {
          TriangleContact c;
          c.triangle = triangle;
          c.body = body;
          c.depth = t - cb.closest;
          c.normal = cb.normal;
          const int f = c.triangle;
          c.bary = closestPointOnTriangle(cb.point, V.row(F(f, 0)).transpose(),
                                          V.row(F(f, 1)).transpose(), V.row(F(f, 2)).transpose())
                       .bary;
          out.push_back(c);
        });
    w.removeTriangles();
    keepDeepestPerKey(out, [](const TriangleContact& c) { return c.triangle; });
    return out;
  }
};

}  // namespace deform

extern "C" __attribute__((visibility("default"))) deform::ContactBackend* deform_contact_backend() {
  return new deform::BulletContactBackend();
}
