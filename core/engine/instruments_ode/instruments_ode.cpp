// Instrument dynamics with ODE (instruments_backend.h): virtually coupled tools, hinged grasper
// jaws, free objects. Its own shared object, loaded by InstrumentWorld on first use.
#include "instruments_backend.h"

#include <deform/sdk/error.h>

#include <cmath>
#include <memory>
#include <vector>

#include <ode/ode.h>

namespace deform {

class OdeInstrumentWorld final : public InstrumentBackend {
 public:
  explicit OdeInstrumentWorld(const Vec3& gravity);
  ~OdeInstrumentWorld() override;
  int addBody(Real mass, const Mat3& inertia, const Vec3& pos, bool gravity, bool coupled,
              const CouplingParams& coupling, bool holdOrientation) override;
  int addGrasper(Real mass, Real shaftLength, Real jawLength, const Vec3& pos,
                 const CouplingParams& coupling) override;
  void setShape(int body, const RigidShape& shape) override;
  void setFriction(Real mu) override;
  int lastContacts() const override;
  void setJaws(int grasper, bool closed) override;
  Real jawAngle(int grasper) const override;
  void setHand(int body, const Vec3& pos, const Vec3& vel) override;
  void addForce(int body, const Vec3& force, const Vec3& at) override;
  void addTorque(int body, const Vec3& torque) override;
  void step(Real dt) override;
  Vec3 position(int body) const override;
  Mat3 rotation(int body) const override;
  Vec3 velocity(int body) const override;
  Vec3 couplingForce(int body) const override;
  int numBodies() const override;

 private:
  struct Impl;
  std::unique_ptr<Impl> m_impl;
};

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

struct OdeInstrumentWorld::Impl {
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

OdeInstrumentWorld::OdeInstrumentWorld(const Vec3& gravity)
    : m_impl(std::make_unique<Impl>(gravity)) {}
OdeInstrumentWorld::~OdeInstrumentWorld() = default;

int OdeInstrumentWorld::addBody(Real mass, const Mat3& I, const Vec3& pos, bool gravity,
                                bool coupled, const CouplingParams& coupling,
                                bool holdOrientation) {
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

int OdeInstrumentWorld::addGrasper(Real mass, Real shaftLength, Real jawLength, const Vec3& pos,
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

void OdeInstrumentWorld::setShape(int body, const RigidShape& shape) {
  for (const ShapePrimitive& p : shape.parts)
    m_impl->addGeom(m_impl->bodies.at(body).id, p, kShapeCategory);
}

void OdeInstrumentWorld::setFriction(Real mu) {
  m_impl->mu = mu;
}

int OdeInstrumentWorld::lastContacts() const {
  return m_impl->lastContacts;
}

void OdeInstrumentWorld::setJaws(int grasper, bool closed) {
  m_impl->bodies.at(grasper).jawsClosed = closed;
}

Real OdeInstrumentWorld::jawAngle(int grasper) const {
  const Impl::Body& b = m_impl->bodies.at(grasper);
  return b.jaw[0] ? dJointGetHingeAngle(b.jaw[0]) : 0.0;
}

void OdeInstrumentWorld::setHand(int body, const Vec3& pos, const Vec3& vel) {
  Impl::Body& b = m_impl->bodies.at(body);
  b.handPos = pos;
  b.handVel = vel;
}

void OdeInstrumentWorld::addForce(int body, const Vec3& f, const Vec3& at) {
  dBodyAddForceAtPos(m_impl->bodies.at(body).id, f.x(), f.y(), f.z(), at.x(), at.y(), at.z());
}

void OdeInstrumentWorld::addTorque(int body, const Vec3& t) {
  dBodyAddTorque(m_impl->bodies.at(body).id, t.x(), t.y(), t.z());
}

void OdeInstrumentWorld::step(Real dt) {
  for (Impl::Body& b : m_impl->bodies) {
    for (dJointID h : b.jaw) {
      if (!h) continue;
      const Real target = b.jawsClosed ? 0.0 : kJawOpenAngle;
      dJointSetHingeParam(h, dParamVel, kJawMotorGain * (target - dJointGetHingeAngle(h)));
    }
    if (!b.coupled) continue;
    const Vec3 x = vec(dBodyGetPosition(b.id)), v = vec(dBodyGetLinearVel(b.id));
    // F_c = k (x_hand - x) + c (v_hand - v) (couplingForce(), instruments.h)
    b.lastCoupling = b.coupling.stiffness * (b.handPos - x) + b.coupling.damping * (b.handVel - v);
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

Vec3 OdeInstrumentWorld::position(int body) const {
  return vec(dBodyGetPosition(m_impl->bodies.at(body).id));
}

Mat3 OdeInstrumentWorld::rotation(int body) const {
  const dReal* R = dBodyGetRotation(m_impl->bodies.at(body).id);  // 3 x 4, row-major
  Mat3 M;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) M(i, j) = R[4 * i + j];
  return M;
}

Vec3 OdeInstrumentWorld::velocity(int body) const {
  return vec(dBodyGetLinearVel(m_impl->bodies.at(body).id));
}

Vec3 OdeInstrumentWorld::couplingForce(int body) const {
  return m_impl->bodies.at(body).lastCoupling;
}

int OdeInstrumentWorld::numBodies() const {
  return static_cast<int>(m_impl->bodies.size());
}

}  // namespace deform

extern "C" __attribute__((visibility("default"))) deform::InstrumentBackend*
deform_instrument_backend(const deform::Vec3& gravity) {
  return new deform::OdeInstrumentWorld(gravity);
}
