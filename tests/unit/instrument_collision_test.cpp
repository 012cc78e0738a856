// Rigid bodies with shapes collide with each other in ODE (issue F8 follow-up): an object resting
// on another does not fall through it, a grasper's jaws push an object, and bodies without shapes
// pass through each other as before.
#include <deform/engine/instruments.h>
#include <deform/sdk/contact.h>
#include <gtest/gtest.h>

namespace deform {
namespace {

Mat3 sphereInertia(Real m, Real r) {
  return Mat3::Identity() * (0.4 * m * r * r);
}

RigidShape sphere(Real r) {
  ShapePrimitive p;
  p.kind = ShapePrimitive::Kind::Sphere;
  p.radius = r;
  return RigidShape{{p}};
}

/// A sphere (r = 1 cm) falls for 0.3 s onto another held by a stiff coupling 3 cm below.
Vec3 dropOnHeldSphere(bool shapes) {
  InstrumentWorld w(Vec3(0, 0, -9.81));
  CouplingParams hold;
  hold.stiffness = 2000;
  hold.damping = 20;
  const Real r = 0.01;
  const int base = w.addBody(0.1, sphereInertia(0.1, r), Vec3::Zero(), false, true, hold, true);
  const int ball = w.addBody(0.01, sphereInertia(0.01, r), Vec3(0, 0, 0.03), true, false);
  if (shapes) {
    w.setShape(base, sphere(r));
    w.setShape(ball, sphere(r));
  }
  for (int k = 0; k < 300; ++k) {
    w.setHand(base, Vec3::Zero(), Vec3::Zero());
    w.step(1e-3);
  }
  return w.position(ball);
}

TEST(InstrumentCollision, AnObjectRestsOnAnotherOnlyWhenBothHaveShapes) {
  const Vec3 rests = dropOnHeldSphere(true);
  // It rests on top (centres 2 r apart, give or take ODE's soft contact) ...
  EXPECT_NEAR(rests.z(), 0.02, 2e-3) << rests.transpose();
  // ... and without shapes it falls through as before (0.44 m in 0.3 s).
  EXPECT_LT(dropOnHeldSphere(false).z(), -0.2);
}

TEST(InstrumentCollision, AGraspersJawsPushAnObjectButTheJawsDoNotCollideWithEachOther) {
  InstrumentWorld w(Vec3::Zero());
  CouplingParams c;
  c.stiffness = 500;
  c.damping = 5;
  const Real jaw = 0.015;
  const int g = w.addGrasper(0.05, 0.2, jaw, Vec3(0, 0, 0.05), c);
  w.setJaws(g, true);
  // A free sphere just below the closed jaws' tips; the hand moves the grasper down 2 cm.
  const Real r = 0.005;
  const Vec3 start(0, 0, 0.05 - jaw - r - 1e-3);
  const int ball = w.addBody(0.005, sphereInertia(0.005, r), start, false, false);
  w.setShape(ball, sphere(r));
  int touching = 0;
  for (int k = 0; k < 400; ++k) {
    const Real t = (k + 1) * 1e-3;
    w.setHand(g, Vec3(0, 0, 0.05 + 0.5 * 0.2 - 0.05 * std::min(t, 0.4)), Vec3(0, 0, -0.05));
    w.step(1e-3);
    touching += w.lastContacts() > 0;
  }
  EXPECT_LT(w.position(ball).z(), start.z() - 5e-3) << "the jaws did not push the object down";
  EXPECT_NEAR(w.jawAngle(g), 0.0, 0.05) << "the closed jaws were pushed apart by each other";
  EXPECT_GT(touching, 0);
}

}  // namespace
}  // namespace deform
