// Rigid instrument dynamics with ODE: virtually coupled tools, hinged grasper jaws, free objects.
#include <deform/error.h>
#include <deform/instruments.h>

#include <cmath>

#ifdef DEFORM_HAVE_ODE
#include <ode/ode.h>
#endif

namespace deform {

Vec3 couplingForce(const CouplingParams& p, const Vec3& xHand, const Vec3& vHand, const Vec3& x,
                   const Vec3& v) {
  return p.stiffness * (xHand - x) + p.damping * (vHand - v);
}

#ifdef DEFORM_HAVE_ODE

namespace {

constexpr Real kJawOpenAngle = 0.5;    // rad, each jaw when open
constexpr Real kJawMotorGain = 20.0;   // 1/s: jaw speed per radian of error
constexpr Real kJawMotorTorque = 0.5;  // N m, the motor's limit

Vec3 vec(const dReal* p) {
  return Vec3(p[0], p[1], p[2]);
}

// Collision categories: jaws collide with shaped bodies, shaped bodies with both.
constexpr unsigned long kJawCategory = 1, kShapeCategory = 2;
constexpr int kMaxContactsPerPair = 8;

}  // namespace

struct InstrumentWorld::Impl {
  dWorldID world = nullptr;
  struct Body {
    dBodyID id = nullptr;
    bool coupled = false;
    CouplingParams coupling;
    Vec3 handPos = Vec3::Zero(), handVel = Vec3::Zero();
    Vec3 lastCoupling = Vec3::Zero();
    dJointID jaw[2] = {nullptr, nullptr};
    bool jawsClosed = false;
    bool holdOrientation = false;
  };
  std::vector<Body> bodies;
  std::vector<dBodyID> jawBodies;
  dSpaceID space = nullptr;
  dJointGroupID contacts = nullptr;
  Real mu = 0;
  int lastContacts = 0;

  Impl(const Vec3& g) {
    dInitODE2(0);
    world = dWorldCreate();
    dWorldSetGravity(world, g.x(), g.y(), g.z());
    space = dSimpleSpaceCreate(nullptr);
    contacts = dJointGroupCreate(0);
  }
  ~Impl() {
    dJointGroupDestroy(contacts);
    dSpaceDestroy(space);  // destroys its geoms
    dWorldDestroy(world);  // destroys its bodies and joints
    dCloseODE();
  }

  dGeomID addGeom(dBodyID body, const ShapePrimitive& p, unsigned long category) {
    dGeomID g = nullptr;
    switch (p.kind) {
      case ShapePrimitive::Kind::Sphere:
        g = dCreateSphere(space, p.radius);
        break;
      case ShapePrimitive::Kind::Capsule:
        g = dCreateCapsule(space, p.radius, p.length);
        break;
      case ShapePrimitive::Kind::Box:
        g = dCreateBox(space, 2 * p.halfExtents.x(), 2 * p.halfExtents.y(), 2 * p.halfExtents.z());
        break;
    }
    dGeomSetBody(g, body);
    dGeomSetOffsetPosition(g, p.centre.x(), p.centre.y(), p.centre.z());
    if (p.kind == ShapePrimitive::Kind::Capsule) {
      // ODE's capsule lies along its local z axis.
      const Mat3 R = Eigen::Quaternion<Real>::FromTwoVectors(Vec3::UnitZ(), p.axis.normalized())
                         .toRotationMatrix();
      dMatrix3 m;
      for (int i = 0; i < 3; ++i) {
        for (int j = 0; j < 3; ++j) m[4 * i + j] = R(i, j);
        m[4 * i + 3] = 0;
      }
      dGeomSetOffsetRotation(g, m);
    }
    dGeomSetCategoryBits(g, category);
    dGeomSetCollideBits(
        g, category == kJawCategory ? kShapeCategory : (kJawCategory | kShapeCategory));
    return g;
  }

  static void nearCallback(void* data, dGeomID a, dGeomID b) {
    Impl& w = *static_cast<Impl*>(data);
    const dBodyID ba = dGeomGetBody(a), bb = dGeomGetBody(b);
    if (ba == bb || (ba && bb && dAreConnected(ba, bb))) return;
    dContact c[kMaxContactsPerPair];
    const int n = dCollide(a, b, kMaxContactsPerPair, &c[0].geom, sizeof(dContact));
    for (int i = 0; i < n; ++i) {
      c[i].surface.mode = dContactSoftERP | dContactSoftCFM | (w.mu > 0 ? dContactApprox1 : 0);
      c[i].surface.mu = w.mu;
      c[i].surface.soft_erp = 0.2;
      c[i].surface.soft_cfm = 1e-6;
      const dJointID j = dJointCreateContact(w.world, w.contacts, &c[i]);
      dJointAttach(j, ba, bb);
    }
    w.lastContacts += n;
  }
};

InstrumentWorld::InstrumentWorld(const Vec3& gravity) : m_impl(std::make_unique<Impl>(gravity)) {}
InstrumentWorld::~InstrumentWorld() = default;

int InstrumentWorld::addBody(Real mass, const Mat3& I, const Vec3& pos, bool gravity, bool coupled,
                             const CouplingParams& coupling, bool holdOrientation) {
  Impl::Body b;
  b.id = dBodyCreate(m_impl->world);
  dMass m;
  dMassSetZero(&m);
  dMassSetParameters(&m, mass, 0, 0, 0, I(0, 0), I(1, 1), I(2, 2), I(0, 1), I(0, 2), I(1, 2));
  dBodySetMass(b.id, &m);
  dBodySetPosition(b.id, pos.x(), pos.y(), pos.z());
  dBodySetGravityMode(b.id, gravity ? 1 : 0);
  dBodySetAutoDisableFlag(b.id, 0);
  b.coupled = coupled;
  b.coupling = coupling;
  b.holdOrientation = holdOrientation;
  b.handPos = pos;
  m_impl->bodies.push_back(b);
  return numBodies() - 1;
}

int InstrumentWorld::addGrasper(Real mass, Real shaftLength, Real jawLength, const Vec3& pos,
                                const CouplingParams& coupling) {
  // Shaft: a thin rod along z whose lower end (the jaws' hinge) is at pos; its body origin is
  // its centre of mass, half a length above.
  const Real L = std::max(shaftLength, Real(1e-3));
  Mat3 I = Mat3::Zero();
  I(0, 0) = I(1, 1) = mass * L * L / 12.0;
  I(2, 2) = mass * 1e-6;
  const int shaft = addBody(mass, I, pos + Vec3(0, 0, 0.5 * L), false, true, coupling, true);
  Impl::Body& s = m_impl->bodies[shaft];
  const Real jm = 0.1 * mass;
  for (int k = 0; k < 2; ++k) {
    const dBodyID jaw = dBodyCreate(m_impl->world);
    dMass m;
    dMassSetZero(&m);
    const Real Ij = jm * jawLength * jawLength / 12.0;
    dMassSetParameters(&m, jm, 0, 0, 0, Ij, Ij, jm * 1e-6, 0, 0, 0);
    dBodySetMass(jaw, &m);
    // Each jaw hangs below the hinge, half a jaw length down.
    dBodySetPosition(jaw, pos.x(), pos.y(), pos.z() - 0.5 * jawLength);
    dBodySetGravityMode(jaw, 0);
    dBodySetAutoDisableFlag(jaw, 0);
    const dJointID h = dJointCreateHinge(m_impl->world, nullptr);
    dJointAttach(h, s.id, jaw);
    dJointSetHingeAnchor(h, pos.x(), pos.y(), pos.z());
    dJointSetHingeAxis(h, k == 0 ? 1 : -1, 0, 0);
    dJointSetHingeParam(h, dParamLoStop, 0.0);
    dJointSetHingeParam(h, dParamHiStop, kJawOpenAngle);
    dJointSetHingeParam(h, dParamFMax, kJawMotorTorque);
    s.jaw[k] = h;
    m_impl->jawBodies.push_back(jaw);
    // A jaw as a box a fifth of its length thick, centred on its body (they collide with shaped
    // bodies only, never with each other).
    ShapePrimitive box;
    box.kind = ShapePrimitive::Kind::Box;
    box.halfExtents = Vec3(0.1 * jawLength, 0.1 * jawLength, 0.5 * jawLength);
    m_impl->addGeom(jaw, box, kJawCategory);
  }
  return shaft;
}

void InstrumentWorld::setShape(int body, const RigidShape& shape) {
  for (const ShapePrimitive& p : shape.parts)
    m_impl->addGeom(m_impl->bodies.at(body).id, p, kShapeCategory);
}

void InstrumentWorld::setFriction(Real mu) {
  m_impl->mu = mu;
}

int InstrumentWorld::lastContacts() const {
  return m_impl->lastContacts;
}

void InstrumentWorld::setJaws(int grasper, bool closed) {
  m_impl->bodies.at(grasper).jawsClosed = closed;
}

Real InstrumentWorld::jawAngle(int grasper) const {
  const Impl::Body& b = m_impl->bodies.at(grasper);
  return b.jaw[0] ? dJointGetHingeAngle(b.jaw[0]) : 0.0;
}

void InstrumentWorld::setHand(int body, const Vec3& pos, const Vec3& vel) {
  Impl::Body& b = m_impl->bodies.at(body);
  b.handPos = pos;
  b.handVel = vel;
}

void InstrumentWorld::addForce(int body, const Vec3& f, const Vec3& at) {
  dBodyAddForceAtPos(m_impl->bodies.at(body).id, f.x(), f.y(), f.z(), at.x(), at.y(), at.z());
}

void InstrumentWorld::addTorque(int body, const Vec3& t) {
  dBodyAddTorque(m_impl->bodies.at(body).id, t.x(), t.y(), t.z());
}

void InstrumentWorld::step(Real dt) {
  for (Impl::Body& b : m_impl->bodies) {
    for (dJointID h : b.jaw) {
      if (!h) continue;
      const Real target = b.jawsClosed ? 0.0 : kJawOpenAngle;
      dJointSetHingeParam(h, dParamVel, kJawMotorGain * (target - dJointGetHingeAngle(h)));
    }
    if (!b.coupled) continue;
    const Vec3 x = vec(dBodyGetPosition(b.id)), v = vec(dBodyGetLinearVel(b.id));
    b.lastCoupling = deform::couplingForce(b.coupling, b.handPos, b.handVel, x, v);
    dBodyAddForce(b.id, b.lastCoupling.x(), b.lastCoupling.y(), b.lastCoupling.z());
  }
  m_impl->lastContacts = 0;
  dSpaceCollide(m_impl->space, m_impl.get(), &Impl::nearCallback);
  dWorldStep(m_impl->world, dt);
  dJointGroupEmpty(m_impl->contacts);
  for (Impl::Body& b : m_impl->bodies) {
    if (!b.holdOrientation) continue;
    dMatrix3 R;
    dRSetIdentity(R);
    dBodySetRotation(b.id, R);
    dBodySetAngularVel(b.id, 0, 0, 0);
  }
}

Vec3 InstrumentWorld::position(int body) const {
  return vec(dBodyGetPosition(m_impl->bodies.at(body).id));
}

Mat3 InstrumentWorld::rotation(int body) const {
  const dReal* R = dBodyGetRotation(m_impl->bodies.at(body).id);  // 3 x 4, row-major
  Mat3 M;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) M(i, j) = R[4 * i + j];
  return M;
}

Vec3 InstrumentWorld::velocity(int body) const {
  return vec(dBodyGetLinearVel(m_impl->bodies.at(body).id));
}

Vec3 InstrumentWorld::couplingForce(int body) const {
  return m_impl->bodies.at(body).lastCoupling;
}

int InstrumentWorld::numBodies() const {
  return static_cast<int>(m_impl->bodies.size());
}

#else  // no ODE in this build

struct InstrumentWorld::Impl {};
InstrumentWorld::InstrumentWorld(const Vec3&) {
  throw UnsupportedError("instrument dynamics need ODE (libode-dev), which this build lacks");
}
InstrumentWorld::~InstrumentWorld() = default;
int InstrumentWorld::addBody(Real, const Mat3&, const Vec3&, bool, bool, const CouplingParams&,
                             bool) {
  return -1;
}
int InstrumentWorld::addGrasper(Real, Real, Real, const Vec3&, const CouplingParams&) {
  return -1;
}
void InstrumentWorld::setShape(int, const RigidShape&) {}
void InstrumentWorld::setFriction(Real) {}
int InstrumentWorld::lastContacts() const {
  return 0;
}
void InstrumentWorld::setJaws(int, bool) {}
Real InstrumentWorld::jawAngle(int) const {
  return 0;
}
void InstrumentWorld::setHand(int, const Vec3&, const Vec3&) {}
void InstrumentWorld::addForce(int, const Vec3&, const Vec3&) {}
void InstrumentWorld::addTorque(int, const Vec3&) {}
void InstrumentWorld::step(Real) {}
Vec3 InstrumentWorld::position(int) const {
  return Vec3::Zero();
}
Mat3 InstrumentWorld::rotation(int) const {
  return Mat3::Identity();
}
Vec3 InstrumentWorld::velocity(int) const {
  return Vec3::Zero();
}
Vec3 InstrumentWorld::couplingForce(int) const {
  return Vec3::Zero();
}
int InstrumentWorld::numBodies() const {
  return 0;
}

#endif

}  // namespace deform
