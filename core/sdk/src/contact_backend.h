// The contact world's collision back end (internal to the core): the instruments' shapes and
// poses and the two narrowphase queries. ContactWorld (contact_world.cpp) keeps everything else
// (reactions, settled and previous poses, inverse masses, statistics) and loads the back end,
// Bullet's (core/engine/contact_bullet/), from its own shared object on first use, so that a
// process that never collides never maps Bullet.
#pragma once

#include <deform/sdk/contact.h>

#include <vector>

namespace deform {

class ContactBackend {
 public:
  virtual ~ContactBackend() = default;
  /// The body's index (addBody() order).
  virtual int addBody(const RigidShape& shape) = 0;
  virtual void setPose(int body, const Vec3& pos, const Mat3& rot) = 0;
  virtual Vec3 position(int body) const = 0;
  virtual Mat3 rotation(int body) const = 0;
  virtual int numBodies() const = 0;
  /// ContactWorld::query(); thickness: the radius of proxies without one (m). Adds the pairs
  /// passed to the narrowphase to pairsTested.
  virtual std::vector<Contact> query(const MatX3& centres, const VecX* radii, Real thickness,
                                     long long& pairsTested) = 0;
  /// ContactWorld::queryTriangles(), with the contact thickness (m).
  virtual std::vector<TriangleContact> queryTriangles(const MatX3& V, const MatX3i& F,
                                                      Real thickness, long long& pairsTested) = 0;
};

/// The back end's shared object (in the SDK library's folder) and its factory, a
/// `ContactBackend* deform_contact_backend()` returning a new back end owned by the caller.
inline constexpr const char* kContactBackendLibrary = "libdeform_contact_bullet.so";
inline constexpr const char* kContactBackendFactory = "deform_contact_backend";
using ContactBackendFactory = ContactBackend* (*)();

}  // namespace deform
