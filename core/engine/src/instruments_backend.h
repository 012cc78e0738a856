// Instrument dynamics' back end (internal to the core): InstrumentWorld (instruments.cpp)
// forwards every call to it and loads it, ODE's (core/engine/instruments_ode/), from its own
// shared object when a scene first asks for dynamics, so that other runs never map ODE.
#pragma once

#include <deform/engine/instruments.h>

namespace deform {

/// InstrumentWorld's operations, as documented in instruments.h.
class InstrumentBackend {
 public:
  virtual ~InstrumentBackend() = default;
  virtual int addBody(Real mass, const Mat3& inertia, const Vec3& pos, bool gravity, bool coupled,
                      const CouplingParams& coupling, bool holdOrientation) = 0;
  virtual int addGrasper(Real mass, Real shaftLength, Real jawLength, const Vec3& pos,
                         const CouplingParams& coupling) = 0;
  virtual void setShape(int body, const RigidShape& shape) = 0;
  virtual void setFriction(Real mu) = 0;
  virtual int lastContacts() const = 0;
  virtual void setJaws(int grasper, bool closed) = 0;
  virtual Real jawAngle(int grasper) const = 0;
  virtual void setHand(int body, const Vec3& pos, const Vec3& vel) = 0;
  virtual void addForce(int body, const Vec3& force, const Vec3& at) = 0;
  virtual void addTorque(int body, const Vec3& torque) = 0;
  virtual void step(Real dt) = 0;
  virtual Vec3 position(int body) const = 0;
  virtual Mat3 rotation(int body) const = 0;
  virtual Vec3 velocity(int body) const = 0;
  virtual Vec3 couplingForce(int body) const = 0;
  virtual int numBodies() const = 0;
};

/// The back end's shared object (in the SDK library's folder) and its factory, an
/// `InstrumentBackend* deform_instrument_backend(const Vec3& gravity)` returning a new back end
/// owned by the caller.
inline constexpr const char* kInstrumentBackendLibrary = "libdeform_instruments_ode.so";
inline constexpr const char* kInstrumentBackendFactory = "deform_instrument_backend";
using InstrumentBackendFactory = InstrumentBackend* (*)(const Vec3& gravity);

}  // namespace deform
