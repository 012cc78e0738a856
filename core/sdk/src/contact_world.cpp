// ContactWorld (contact.h): the bookkeeping of the instruments (reactions, settled and previous
// poses, inverse masses, statistics) around the collision back end (contact_backend.h), which is
// loaded from its own shared object when the first world is built.
#include "contact_backend.h"

#include <deform/internal/component.h>
#include <deform/sdk/contact.h>
#include <deform/sdk/error.h>

#include <algorithm>
#include <cmath>
#include <limits>

namespace deform {

struct ContactWorld::Impl {
  std::unique_ptr<ContactBackend> backend;
};

ContactWorld::ContactWorld(const ContactParams& params)
    : m_params(params), m_impl(std::make_unique<Impl>()) {
#ifndef DEFORM_HAVE_BULLET  // the harness reports it before any run
  throw UnsupportedError("contact needs Bullet (libbullet-dev), which this build lacks");
#else
  const auto create = reinterpret_cast<ContactBackendFactory>(
      coreComponentSymbol(kContactBackendLibrary, kContactBackendFactory, "contact"));
  m_impl->backend.reset(create());
#endif
}

ContactWorld::~ContactWorld() = default;

int ContactWorld::addBody(const RigidShape& shape) {
  m_impl->backend->addBody(shape);
  m_force.push_back(Vec3::Zero());
  m_torque.push_back(Vec3::Zero());
  Real thin = std::numeric_limits<Real>::infinity();
  for (const ShapePrimitive& p : shape.parts)
    thin =
        std::min(thin, p.kind == ShapePrimitive::Kind::Box ? p.halfExtents.minCoeff() : p.radius);
  m_thinnest.push_back(thin);
  m_invMass.push_back(0);
  m_settled.push_back(Vec3::Zero());
  m_settledSet.push_back(0);
  m_prevPos.push_back(Vec3::Zero());
  m_prevRot.push_back(Mat3::Identity());
  return numBodies() - 1;
}

void ContactWorld::setPose(int body, const Vec3& pos, const Mat3& R) {
  m_prevPos.at(body) = m_settledSet[body] ? position(body) : pos;
  m_prevRot.at(body) = m_settledSet[body] ? rotation(body) : R;
  m_impl->backend->setPose(body, pos, R);
  if (!m_settledSet[body]) {
    m_settled[body] = pos;
    m_settledSet[body] = 1;
  }
}

Mat3 ContactWorld::rotation(int body) const {
  return m_impl->backend->rotation(body);
}

Vec3 ContactWorld::position(int body) const {
  return m_impl->backend->position(body);
}

int ContactWorld::numBodies() const {
  return m_impl->backend->numBodies();
}

std::vector<Contact> ContactWorld::query(const MatX3& centres, const VecX* radii) {
  std::vector<Contact> out =
      m_impl->backend->query(centres, radii, m_params.thickness, m_pairsTested);
  m_contactsFound += static_cast<long long>(out.size());
  return out;
}

std::vector<TriangleContact> ContactWorld::queryTriangles(const MatX3& V, const MatX3i& F) {
  std::vector<TriangleContact> out =
      m_impl->backend->queryTriangles(V, F, m_params.thickness, m_pairsTested);
  m_contactsFound += static_cast<long long>(out.size());
  return out;
}

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

Vec3 ContactWorld::bodyDisplacement(int body, const Vec3& p) const {
  const Vec3 local = rotation(body).transpose() * (p - position(body));
  return p - (m_prevPos.at(body) + m_prevRot.at(body) * local);
}

void ContactWorld::setInverseMass(int body, Real invMass) {
  m_invMass.at(body) = std::isfinite(invMass) && invMass > 0 ? invMass : 0;
}

Real ContactWorld::inverseMass(int body) const {
  return m_invMass.at(body);
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

}  // namespace deform
