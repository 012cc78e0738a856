// deformbench SDK: rigid instrument dynamics with the Open Dynamics Engine (ODE). A tool that the
// scene gives "dynamics" is a rigid body driven towards its keyframed trajectory (the hand)
// through a virtual coupling, the spring-damper by which haptic devices drive a simulated tool
// (Colgate, Stanley and Brown 1995, "Issues in the haptic display of tool use", IROS):
//
//   F_c = k (x_hand - x) + c (v_hand - v),
//
// x, v the body's position and velocity. F_c is the force the hand exerts on the tool; the hand
// feels -F_c. The coupling is translational (a 3-DOF force-feedback device): the hand holds a
// tool's orientation, so a tool body's rotation is reset to the identity after every step (an
// explicit angular spring on a thin shaft would need a far smaller time step to stay stable). The
// tissue's reaction (contact and grasp forces reported by the model) acts on the body too, so the
// coupling force carries the tissue's stiffness to the hand. A grasper is a shaft with two jaws on
// hinges at its tip, opened and closed by hinge motors. A rigid object (the metaballs paper's
// "small object transfer" task, Sec. 6) is a free body under gravity, optionally with a coupling of
// its own (pushed along a trajectory).
//
// One InstrumentWorld per run; ODE integrates with dWorldStep (semi-implicit Euler, exact LCP for
// the joints); the coupling and the tissue's forces are explicit over the step.
#pragma once

#include <deform/sdk/contact.h>
#include <deform/sdk/types.h>

#include <memory>
#include <vector>

namespace deform {

/// Virtual coupling gains (SI).
struct CouplingParams {
  Real stiffness = 200.0;  ///< k, N/m
  Real damping = 2.0;      ///< c, N s/m
};

/// The coupling force F_c = k (xHand - x) + c (vHand - v), N.
Vec3 couplingForce(const CouplingParams& p, const Vec3& xHand, const Vec3& vHand, const Vec3& x,
                   const Vec3& v);

class InstrumentWorld {
 public:
  /// gravity: m/s^2 (acts on objects; tools are carried by the hand and feel none).
  explicit InstrumentWorld(const Vec3& gravity);
  ~InstrumentWorld();
  InstrumentWorld(const InstrumentWorld&) = delete;
  InstrumentWorld& operator=(const InstrumentWorld&) = delete;

  /// A rigid body of `mass` (kg) and body-frame inertia tensor (kg m^2) at pos, at rest.
  /// coupled: driven by a virtual coupling (call setHand() before every step). gravity: whether
  /// gravity acts on it. holdOrientation: its rotation is kept at the identity (a hand-held
  /// tool). Returns the body index.
  int addBody(Real mass, const Mat3& inertia, const Vec3& pos, bool gravity, bool coupled,
              const CouplingParams& coupling = {}, bool holdOrientation = false);
  /// A grasper: a shaft body (mass, a rod of `shaftLength` m along +z above pos) and two jaws
  /// (each a tenth of the mass, `jawLength` m) hinged at pos about the x axis, driven by hinge
  /// motors to +-jawOpenAngle (open) or 0 (closed). Coupled, no gravity, orientation held.
  /// Returns the shaft body.
  int addGrasper(Real mass, Real shaftLength, Real jawLength, const Vec3& pos,
                 const CouplingParams& coupling);
  /// Gives a body a collision shape (its primitives in the body frame, as contact.h's
  /// RigidShape): bodies with shapes and the grasper's jaws collide with each other through ODE
  /// (dCollide on geoms in a simple space, a contact joint per contact point, Coulomb friction
  /// mu = setFriction()), except a grasper's two jaws with each other and bodies joined by a
  /// joint. Without shapes nothing collides (the default).
  void setShape(int body, const RigidShape& shape);
  /// Coulomb friction of the body-body contacts (default 0: frictionless).
  void setFriction(Real mu);
  /// Contact points between bodies in the last step.
  int lastContacts() const;
  /// Jaw command of a grasper's shaft body.
  void setJaws(int grasper, bool closed);
  /// Current opening angle of a grasper's first jaw, rad (0 closed).
  Real jawAngle(int grasper) const;

  /// Where the hand is at the end of the coming step, and its velocity.
  void setHand(int body, const Vec3& pos, const Vec3& vel);
  /// A force (N) at a world point (m) and a torque (N m) for the coming step only.
  void addForce(int body, const Vec3& force, const Vec3& at);
  void addTorque(int body, const Vec3& torque);
  /// Advances every body by dt (s) with the coupling forces from the state at the step's start.
  void step(Real dt);

  Vec3 position(int body) const;
  Mat3 rotation(int body) const;
  Vec3 velocity(int body) const;
  /// Coupling force the hand exerted on the body during the last step (zero for free bodies), N.
  Vec3 couplingForce(int body) const;
  int numBodies() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> m_impl;
};

}  // namespace deform
