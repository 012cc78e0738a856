// InstrumentWorld (instruments.h): every call forwarded to the ODE back end
// (instruments_backend.h), loaded from its own shared object when the first world is built.
#include "instruments_backend.h"

#include <deform/engine/instruments.h>
#include <deform/internal/component.h>
#include <deform/sdk/error.h>

#include <cmath>

namespace deform {

Vec3 couplingForce(const CouplingParams& p, const Vec3& xHand, const Vec3& vHand, const Vec3& x,
                   const Vec3& v) {
  return p.stiffness * (xHand - x) + p.damping * (vHand - v);
}

struct InstrumentWorld::Impl {
  std::unique_ptr<InstrumentBackend> backend;
};

InstrumentWorld::InstrumentWorld(const Vec3& gravity) : m_impl(std::make_unique<Impl>()) {
#ifndef DEFORM_HAVE_ODE
  (void)gravity;
  throw UnsupportedError("instrument dynamics need ODE (libode-dev), which this build lacks");
#else
  const auto create = reinterpret_cast<InstrumentBackendFactory>(coreComponentSymbol(
      kInstrumentBackendLibrary, kInstrumentBackendFactory, "instrument dynamics"));
  m_impl->backend.reset(create(gravity));
#endif
}
InstrumentWorld::~InstrumentWorld() = default;

int InstrumentWorld::addBody(Real mass, const Mat3& I, const Vec3& pos, bool gravity, bool coupled,
                             const CouplingParams& coupling, bool holdOrientation) {
  return m_impl->backend->addBody(mass, I, pos, gravity, coupled, coupling, holdOrientation);
}
int InstrumentWorld::addGrasper(Real mass, Real shaftLength, Real jawLength, const Vec3& pos,
                                const CouplingParams& coupling) {
  return m_impl->backend->addGrasper(mass, shaftLength, jawLength, pos, coupling);
}
void InstrumentWorld::setShape(int body, const RigidShape& shape) {
  m_impl->backend->setShape(body, shape);
}
void InstrumentWorld::setFriction(Real mu) {
  m_impl->backend->setFriction(mu);
}
int InstrumentWorld::lastContacts() const {
  return m_impl->backend->lastContacts();
}
void InstrumentWorld::setJaws(int grasper, bool closed) {
  m_impl->backend->setJaws(grasper, closed);
}
Real InstrumentWorld::jawAngle(int grasper) const {
  return m_impl->backend->jawAngle(grasper);
}
void InstrumentWorld::setHand(int body, const Vec3& pos, const Vec3& vel) {
  m_impl->backend->setHand(body, pos, vel);
}
void InstrumentWorld::addForce(int body, const Vec3& force, const Vec3& at) {
  m_impl->backend->addForce(body, force, at);
}
void InstrumentWorld::addTorque(int body, const Vec3& torque) {
  m_impl->backend->addTorque(body, torque);
}
void InstrumentWorld::step(Real dt) {
  m_impl->backend->step(dt);
}
Vec3 InstrumentWorld::position(int body) const {
  return m_impl->backend->position(body);
}
Mat3 InstrumentWorld::rotation(int body) const {
  return m_impl->backend->rotation(body);
}
Vec3 InstrumentWorld::velocity(int body) const {
  return m_impl->backend->velocity(body);
}
Vec3 InstrumentWorld::couplingForce(int body) const {
  return m_impl->backend->couplingForce(body);
}
int InstrumentWorld::numBodies() const {
  return m_impl->backend->numBodies();
}

}  // namespace deform
