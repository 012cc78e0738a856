// Contact (Bullet collision world) and instrument dynamics (ODE): what the world reports for
// points against spheres, capsule shafts and boxes, the shared contact response, the virtual
// coupling's spring law, and that worlds exist only when the scene asks for them.
#include <deform/engine/instruments.h>
#include <deform/engine/interaction.h>
#include <deform/engine/scene.h>
#include <deform/sdk/contact.h>
#include <deform/sdk/registry.h>
#include <deform_harness/runner.h>
#include <gtest/gtest.h>

#include "harness_test_models.h"

namespace deform {
namespace {

/// Signed distance from p to a probe (tip sphere at c, capsule shaft from c along +z).
Real probeDistance(const Vec3& p, const Vec3& c, Real tip, Real shaftLen, Real shaftR) {
  const Real dTip = (p - c).norm() - tip;
  const Real s = std::clamp((p - c).z(), Real(0), shaftLen);
  const Real dShaft = (p - (c + Vec3(0, 0, s))).norm() - shaftR;
  return std::min(dTip, dShaft);
}

TEST(ContactWorld, ReportsPointsInsideATipWithDepthAndOutwardNormal) {
  ContactParams params;
  params.thickness = 1e-4;
  ContactWorld w(params);
  const int b = w.addBody(probeShape(0.01, 0.0, 0.0, Vec3::UnitZ()));
  w.setPose(b, Vec3(0.1, 0, 0));
  MatX3 p(3, 3);
  p << 0.1, 0, -0.006,  // 4 mm deep below the centre
      0.1, 0.02, 0,     // outside
      0.1, 0, 0.01005;  // just outside, but within the contact thickness
  const std::vector<Contact> c = w.query(p);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c[0].proxy, 0);
  EXPECT_NEAR(c[0].depth, 0.004 + 1e-4, 1e-9);
  EXPECT_TRUE(c[0].normal.isApprox(Vec3(0, 0, -1), 1e-9)) << c[0].normal.transpose();
  EXPECT_EQ(c[1].proxy, 2);
  EXPECT_NEAR(c[1].depth, 1e-4 - 5e-5, 1e-9);
  EXPECT_TRUE(c[1].normal.isApprox(Vec3(0, 0, 1), 1e-9));
}

TEST(ContactWorld, ShaftAndBoxesCountAndTheDeepestInstrumentWins) {
  ContactWorld w;
  const int probe = w.addBody(probeShape(0.005, 0.1, 0.003, Vec3::UnitZ()));
  w.setPose(probe, Vec3::Zero());
  RigidShape box;
  ShapePrimitive p;
  p.kind = ShapePrimitive::Kind::Box;
  p.halfExtents = Vec3(0.01, 0.02, 0.03);
  box.parts.push_back(p);
  const int cube = w.addBody(box);
  w.setPose(cube, Vec3(1, 0, 0));
  MatX3 x(3, 3);
  x << 0.002, 0, 0.05,  // inside the shaft, 1 mm from its side (+x)
      1.0, 0.015, 0.0,  // inside the box, 5 mm from its +y face
      0.5, 0.5, 0.5;    // nowhere
  const std::vector<Contact> c = w.query(x);
  ASSERT_EQ(c.size(), 2u);
  EXPECT_EQ(c[0].body, probe);
  EXPECT_NEAR(c[0].depth, 0.001 + w.params().thickness, 1e-7);
  EXPECT_TRUE(c[0].normal.isApprox(Vec3::UnitX(), 1e-6)) << c[0].normal.transpose();
  EXPECT_EQ(c[1].body, cube);
  EXPECT_NEAR(c[1].depth, 0.005 + w.params().thickness, 1e-6);
  EXPECT_TRUE(c[1].normal.isApprox(Vec3::UnitY(), 1e-6)) << c[1].normal.transpose();
  EXPECT_GE(w.pairsTested(), 2);
}

TEST(ContactWorld, ProxySpheresUseTheirOwnRadii) {
  ContactWorld w;
  w.setPose(w.addBody(probeShape(0.01, 0, 0, Vec3::UnitZ())), Vec3::Zero());
  MatX3 x(2, 3);
  x << 0, 0, 0.015,  //
      0, 0, 0.025;
  VecX r(2);
  r << 0.008, 0.008;
  const std::vector<Contact> c = w.query(x, &r);
  ASSERT_EQ(c.size(), 1u);
  EXPECT_EQ(c[0].proxy, 0);
  EXPECT_NEAR(c[0].depth, 0.003, 1e-9);
}

TEST(ResolveContacts, PushesNodesOutAndTheToolFeelsTheOppositeImpulse) {
  ContactWorld w;
  const int b = w.addBody(probeShape(0.01, 0.05, 0.01, Vec3::UnitZ()));
  const Vec3 c(0, 0, 0.008);
  w.setPose(b, c);
  MatX3 x(5, 3);
  x << 0, 0, 0,          //
      0.003, 0, 0,       //
      -0.004, 0.002, 0,  //
      0.02, 0, 0,        // outside
      0, 0.001, 0.001;   // immovable
  VecX invMass = VecX::Constant(5, 1.0 / 0.002);
  invMass[4] = 0;
  const MatX3 before = x;
  MatX3 v = MatX3::Zero(5, 3);
  v.row(0) << 0, 0, 0.3;  // moving into the tool
  const Real dt = 1e-3;
  ContactProxy proxy;
  proxy.nodes = &x;
  proxy.invMass = &invMass;
  proxy.velocity = v.data();
  const ContactResolution r = respondToContact(w, proxy, ContactResponse::Project, dt);
  EXPECT_EQ(r.contacts, 4);
  for (int i = 0; i < 4; ++i) {
    EXPECT_GE(probeDistance(x.row(i).transpose(), c, 0.01, 0.05, 0.01), -1e-9) << "node " << i;
  }
  EXPECT_EQ(x.row(3), before.row(3));
  EXPECT_EQ(x.row(4), before.row(4)) << "an immovable node stays";
  EXPECT_NEAR(v(0, 2), 0.0, 1e-12) << "the inward normal velocity is removed";
  // Reaction: minus the sum of m (dx/dt + dv) / dt over the moved nodes.
  Vec3 expect = Vec3::Zero();
  for (int i = 0; i < 3; ++i) expect -= 0.002 * (x.row(i) - before.row(i)).transpose() / (dt * dt);
  expect -= 0.002 * Vec3(0, 0, -0.3) / dt;
  EXPECT_TRUE(w.reactionForce(b).isApprox(expect, 1e-9))
      << w.reactionForce(b).transpose() << " vs " << expect.transpose();
  w.clearReactions();
  EXPECT_EQ(w.reactionForce(b), Vec3::Zero());
}

// Several nodes against one light body, resolved in sequence: the body's predicted motion from
// the first contacts reduces the depth the later ones see, so the body is not pushed by more than
// the penetration (the one-way response pushed every node out and gave the body all of it).
TEST(ResolveContacts, NodesAgainstALightBodyShareTheDepthAndDoNotOverpushIt) {
  const Real dt = 1e-3, bodyMass = 0.001, nodeMass = 0.01;
  ContactWorld w;
  const int b = w.addBody(probeShape(0.01, 0, 0, Vec3::UnitZ()));
  const Vec3 c(0, 0, 0.0095);  // a sphere 0.5 mm into the plane z = 0
  w.setPose(b, c);
  w.setInverseMass(b, 1.0 / bodyMass);
  MatX3 x(3, 3);
  x << 0, 0, 0,  //
      0.0005, 0, 0, -0.0005, 0.0003, 0;
  const MatX3 before = x;
  const VecX invMass = VecX::Constant(3, 1.0 / nodeMass);
  ContactProxy proxy;
  proxy.nodes = &x;
  proxy.invMass = &invMass;
  respondToContact(w, proxy, ContactResponse::Project, dt);
  // The body moves up by w_b F dt^2 in its next step; the deepest node, directly below it, must
  // end out of the body at that position (within the contact skin), and the body must not move
  // more than the penetration of the deepest node (0.5 mm + thickness).
  const Vec3 dxBody = w.reactionForce(b) * dt * dt / bodyMass;
  EXPECT_GT(dxBody.z(), 0.0) << "the body is pushed up (out of the tissue)";
  EXPECT_LT(dxBody.z(), 0.0005 + 1e-4 + 1e-9) << "no more than the penetration";
  const Vec3 cNext = c + dxBody;
  for (int i = 0; i < 3; ++i)
    EXPECT_GE((x.row(i).transpose() - cNext).norm(), 0.01 - 1e-4 - 1e-9) << "node " << i;
  // The heavy nodes (10 g against 1 g) moved by at most a tenth of what the body did.
  for (int i = 0; i < 3; ++i)
    EXPECT_LE((x.row(i) - before.row(i)).norm(), 0.1 * dxBody.norm() + 1e-12) << "node " << i;
}

// Contact as prescribed positions (solveWithContactConstraints) is frictionless and pushes: a
// node held while touching whose tissue then pulls the instrument (it sagged away under it) is
// let go, so the instrument feels only the push of the node pressed into it. Before issue 35
// the held node stuck to it: on liver_instruments the quasi-static reference pulled the box
// down into the sagging organ and sideways.
TEST(ContactConstraints, ANodeThatPullsTheInstrumentIsReleased) {
  ContactParams params;
  params.thickness = 2e-4;
  ContactWorld w(params);
  const int b = w.addBody(probeShape(0.01, 0, 0, Vec3::UnitZ()));  // a sphere resting on z = 0
  w.setPose(b, Vec3(0, 0, 0.01));
  // Each node on a spring (k) to its rest position; node 0 is pressed 1 mm into the sphere (its
  // rest also 1 mm aside: a tangential force the frictionless contact does not pass on), node 1
  // touches it (0.1 mm outside) while its rest is 2 mm below.
  const Real k = 50;
  const Real zSkin = 0.01 - std::sqrt(0.01 * 0.01 - 0.003 * 0.003);
  MatX3 rest(2, 3);
  rest << 0.001, 0, 0.001,  //
      0.003, 0, zSkin - 0.0021;
  MatX3 x(2, 3);
  x << 0, 0, 0.001,  //
      0.003, 0, zSkin - 0.0001;
  std::vector<Vec3> force;  // per node, on what holds it, after the last solve
  std::vector<Vec3> perGrasp;
  int solves = 0;
  ContactConstraintSolver solver;
  solver.maxRounds = 4;
  solver.solve = [&](const StepInput& in) {
    ++solves;
    x = rest;
    perGrasp.clear();
    force.assign(2, Vec3::Zero());
    for (const NodeGrasp& g : in.nodeConstraints) {
      Vec3 sum = Vec3::Zero();
      for (size_t i = 0; i < g.nodes.size(); ++i) {
        x.row(g.nodes[i]) = g.targets.row(Eigen::Index(i));
        force[size_t(g.nodes[i])] = k * (rest.row(g.nodes[i]) - x.row(g.nodes[i])).transpose();
        sum += force[size_t(g.nodes[i])];
      }
      perGrasp.push_back(sum);
    }
    return StepStatus::Ok;
  };
  solver.graspForces = [&] { return perGrasp; };
  solver.nodeReaction = [&](int n) { return force[size_t(n)]; };
  ContactProxy proxy;
  proxy.nodes = &x;
  StepInput in;
  ASSERT_EQ(solveWithContactConstraints(w, proxy, in, solver), StepStatus::Ok);
  EXPECT_GE(solves, 2);
  EXPECT_LT((x.row(1) - rest.row(1)).norm(), 1e-12) << "the pulling node was let go";
  EXPECT_LE(x(0, 2), 1e-12) << "the pressed node is out of the sphere";
  const Vec3 f = w.reactionForce(b);
  EXPECT_GT(f.z(), 0) << "the tissue pushes the sphere up: " << f.transpose();
  EXPECT_NEAR(f.z(), k * (rest(0, 2) - x(0, 2)), 1e-9) << "only the pressed node's push";
  EXPECT_NEAR(f.x(), 0, 1e-9) << "frictionless: no tangential force";
  EXPECT_NEAR(f.y(), 0, 1e-9);
}

TEST(ResolveEmbeddedContacts, MovesTheEmbeddedPointsOutThroughTheirNodes) {
  ContactWorld w;
  const Vec3 c(0.5, 0.5, 1.0);
  w.setPose(w.addBody(probeShape(0.3, 0, 0, Vec3::UnitZ())), c);
  // One unit cell; two points embedded on its top face.
  MatX3 nodes(8, 3);
  for (int i = 0; i < 8; ++i) nodes.row(i) << (i & 1), (i >> 1) & 1, (i >> 2) & 1;
  EmbeddingIds ids(2, 8);
  EmbeddingWeights W(2, 8);
  const Vec3 pts[2] = {Vec3(0.5, 0.5, 1.0), Vec3(0.6, 0.4, 1.0)};
  for (int s = 0; s < 2; ++s)
    for (int i = 0; i < 8; ++i) {
      ids(s, i) = i;
      const Vec3 n = nodes.row(i).transpose();
      W(s, i) = (n.x() ? pts[s].x() : 1 - pts[s].x()) * (n.y() ? pts[s].y() : 1 - pts[s].y()) *
                (n.z() ? pts[s].z() : 1 - pts[s].z());
    }
  const VecX invMass = VecX::Ones(8);
  ContactProxy proxy;
  proxy.nodes = &nodes;
  proxy.invMass = &invMass;
  proxy.embedding = embeddingOf(ids, W);
  respondToContact(w, proxy, ContactResponse::Project, 1e-3);
  for (int s = 0; s < 2; ++s) {
    Vec3 p = Vec3::Zero();
    for (int i = 0; i < 8; ++i) p += W(s, i) * nodes.row(i).transpose();
    EXPECT_GE((p - c).norm(), 0.3 - 1e-9) << "point " << s << " at " << p.transpose();
  }
}

TEST(VirtualCoupling, TheForceIsTheSpringDamperLawAndMovesTheBody) {
  CouplingParams k;
  k.stiffness = 300;
  k.damping = 4;
  const Vec3 f = couplingForce(k, Vec3(0.01, 0, 0), Vec3(0, 0.5, 0), Vec3::Zero(), Vec3::Zero());
  EXPECT_TRUE(f.isApprox(Vec3(3.0, 2.0, 0)));

  InstrumentWorld w(Vec3(0, 0, -9.81));
  const Real m = 0.05, dt = 1e-3;
  const Vec3 x0(0.1, 0.2, 0.3);
  const int b = w.addBody(m, Mat3::Identity() * 1e-5, x0, false, true, k);
  const Vec3 hand = x0 + Vec3(0.004, -0.002, 0.01), handV(0.1, 0, -0.2);
  w.setHand(b, hand, handV);
  w.step(dt);
  const Vec3 expected = k.stiffness * (hand - x0) + k.damping * handV;
  EXPECT_TRUE(w.couplingForce(b).isApprox(expected, 1e-12)) << w.couplingForce(b).transpose();
  // Semi-implicit Euler on a free body without gravity: v = F dt / m, x = x0 + v dt.
  EXPECT_TRUE(w.velocity(b).isApprox(expected * dt / m, 1e-9)) << w.velocity(b).transpose();
  EXPECT_TRUE(w.position(b).isApprox(x0 + expected * dt * dt / m, 1e-9));

  // Second step: the law uses the body's new state.
  const Vec3 x1 = w.position(b), v1 = w.velocity(b);
  w.step(dt);
  EXPECT_TRUE(
      w.couplingForce(b).isApprox(k.stiffness * (hand - x1) + k.damping * (handV - v1), 1e-12));
}

TEST(VirtualCoupling, AFreeObjectFallsAndAGrasperFollowsItsHand) {
  InstrumentWorld w(Vec3(0, 0, -9.81));
  const int obj = w.addBody(0.01, Mat3::Identity() * 1e-6, Vec3::Zero(), true, false);
  CouplingParams k;
  k.stiffness = 200;
  k.damping = 2 * std::sqrt(200 * 0.06);  // critically damped for shaft + jaws
  const int g = w.addGrasper(0.05, 0.3, 0.015, Vec3(1, 0, 0), k);
  w.setJaws(g, false);
  for (int i = 0; i < 2000; ++i) {
    w.setHand(g, Vec3(1, 0, 0.02) + Vec3(0, 0, 0.15), Vec3::Zero());
    w.step(1e-3);
  }
  EXPECT_NEAR(w.position(obj).z(), -0.5 * 9.81 * 4.0, 0.05) << "2 s of free fall";
  EXPECT_NEAR(w.position(g).z(), 0.17, 1e-3) << "the shaft settles at its hand";
  EXPECT_NEAR(w.couplingForce(g).norm(), 0.0, 1e-3) << "no force once settled (no gravity)";
  EXPECT_GT(w.jawAngle(g), 0.3) << "the jaws opened";
  w.setJaws(g, true);
  for (int i = 0; i < 500; ++i) w.step(1e-3);
  EXPECT_LT(w.jawAngle(g), 0.05) << "and closed";
}

Scene kinematicScene() {
  Scene s;
  s.dt = 0.01;
  ToolSpec t;
  t.type = ToolType::Grasper;
  t.trajectory = {KeyFrame{0, Vec3::Zero(), true}, KeyFrame{0.5, Vec3(0, 0, 0.01), true}};
  s.tools.push_back(t);
  LoadSpec l;
  l.at = Vec3(0.1, 0, 0);
  l.force = Vec3(0, 0, 1);
  s.loads.push_back(l);
  return s;
}

TEST(Worlds, AKinematicSceneCreatesNeitherBulletNorOde) {
  const Scene s = kinematicScene();
  EXPECT_FALSE(s.needsContact());
  EXPECT_FALSE(s.needsDynamics());
  const SurfaceMesh rest = testing::tetSurface();
  Interaction inter(s, rest);
  EXPECT_EQ(inter.contactWorld(), nullptr);
  EXPECT_EQ(inter.instrumentWorld(), nullptr);
  EXPECT_TRUE(inter.describeWorlds().empty());
  testing::RigidTestModel model;
  Organ organ;
  organ.surface = rest;
  Cache cache{std::filesystem::path()};
  const ParamValues none;
  model.init(ModelSetup{organ, none, cache, s.dt, s.gravity});
  const StepInput in = inter.prepare(0, s.dt, model);
  EXPECT_EQ(in.contact, nullptr);
  EXPECT_EQ(inter.contactWorld(), nullptr);
  EXPECT_EQ(inter.instrumentWorld(), nullptr);
  EXPECT_TRUE(inter.handForces().empty());

  // The same through the runner: no world recorded, no hand force.
  harness::RunRecord rec;
  Scene run = s;
  run.duration = 0.05;
  harness::simulate(model, run, organ, harness::RunOptions{}, rec);
  EXPECT_TRUE(rec.worlds.empty());
  EXPECT_TRUE(rec.handForces.empty());
  EXPECT_EQ(rec.contactPairs, -1);
}

TEST(Worlds, ProbesAndDynamicsCreateOnlyWhatTheyNeed) {
  const SurfaceMesh rest = testing::tetSurface();
  Scene probe = kinematicScene();
  ToolSpec p;
  p.type = ToolType::Probe;
  p.trajectory = {KeyFrame{0, Vec3(0, 0, 0.2), false}};
  probe.tools.push_back(p);
  {
    Interaction inter(probe, rest);
    EXPECT_NE(inter.contactWorld(), nullptr);
    EXPECT_EQ(inter.instrumentWorld(), nullptr);
    EXPECT_EQ(inter.describeWorlds().size(), 1u);
  }
  Scene dyn = kinematicScene();
  dyn.tools[0].dynamics = ToolDynamics{};
  {
    Interaction inter(dyn, rest);
    EXPECT_EQ(inter.contactWorld(), nullptr);
    ASSERT_NE(inter.instrumentWorld(), nullptr);
    EXPECT_EQ(inter.instrumentWorld()->numBodies(), 1);
  }
  Scene object = kinematicScene();
  ObjectSpec o;
  ShapePrimitive sp;
  sp.radius = 0.01;
  o.shape.parts.push_back(sp);
  object.objects.push_back(o);
  {
    Interaction inter(object, rest);
    EXPECT_NE(inter.contactWorld(), nullptr);
    EXPECT_NE(inter.instrumentWorld(), nullptr);
  }
}

TEST(Worlds, ADynamicGrasperReportsTheCouplingForceEveryStep) {
  Scene s = kinematicScene();
  s.loads.clear();
  s.gravity = Vec3::Zero();
  ToolDynamics d;
  d.coupling.stiffness = 100;
  d.coupling.damping = 1;
  s.tools[0].dynamics = d;
  s.duration = 0.1;
  const SurfaceMesh rest = testing::tetSurface();
  Organ organ;
  organ.surface = rest;
  testing::RigidTestModel model;
  Cache cache{std::filesystem::path()};
  const ParamValues none;
  model.init(ModelSetup{organ, none, cache, s.dt, s.gravity});
  harness::RunRecord rec;
  harness::simulate(model, s, organ, harness::RunOptions{}, rec);
  ASSERT_EQ(rec.instruments.size(), 1u);
  EXPECT_EQ(rec.instruments[0], "tools/0");
  EXPECT_EQ(rec.handForces.size(), static_cast<size_t>(s.numSteps()));
  EXPECT_EQ(rec.worlds.size(), 1u);
  // The hand moves up: the coupling pulls the tool up.
  EXPECT_GT(rec.handForces[1].force.z(), 0);
  // This model reports no grasp force: the instrument felt no tissue, and the run says so.
  ASSERT_FALSE(model.inputs.empty());
  ASSERT_FALSE(model.inputs.back().grasps.empty()) << "the grasp holds vertices";
  EXPECT_EQ(rec.numeric.count("forceless_grasp_steps"), 1u);
  harness::assessValidity(s, rec);
  EXPECT_FALSE(rec.valid);
  EXPECT_NE(rec.invalidReason.find("no force for a grasp"), std::string::npos) << rec.invalidReason;
  // One that reports a force (zero here) is not flagged.
  model.graspForce = true;
  model.reset();
  harness::RunRecord withForce;
  harness::simulate(model, s, organ, harness::RunOptions{}, withForce);
  EXPECT_EQ(withForce.numeric.count("forceless_grasp_steps"), 0u);
}

nlohmann::json instrumentScene() {
  return nlohmann::json::parse(R"({
    "organ": {"mesh": "phantom:cube"},
    "tools": [{"type": "probe", "radius": 0.004,
               "shaft": {"length": 0.08, "radius": 0.003, "axis": [0, 0, 2]},
               "dynamics": {"mass": 0.02, "stiffness": 150, "damping": 1.5},
               "trajectory": [{"t": 0, "pos": [0, 0, 0.1]}]},
              {"type": "grasper", "radius": 0.005,
               "dynamics": {"jaw_length": 0.01, "shaft_length": 0.2, "damping": 0.5},
               "trajectory": [{"t": 0, "pos": [0, 0, 0.1], "jaw": "closed"}]}],
    "objects": [{"shape": "box", "size": [0.01, 0.02, 0.004], "mass": 0.003, "pos": [0, 0, 0.2],
                 "trajectory": [{"t": 0, "pos": [0, 0, 0.2]}], "stiffness": 50}],
    "contact": {"thickness": 0.0003, "passes": 3},
    "models": [{"plugin": "pbd"}]
  })");
}

void expectSceneError(const nlohmann::json& j, const std::string& path, const std::string& what) {
  try {
    parseScene(j, "s.json");
    ADD_FAILURE() << "no error; expected " << path;
  } catch (const InputError& e) {
    EXPECT_EQ(e.place(), path) << e.what();
    EXPECT_NE(std::string(e.what()).find(what), std::string::npos) << e.what();
  }
}

TEST(InstrumentScene, ParsesProbeShaftDynamicsObjectsAndContact) {
  const Scene s = parseScene(instrumentScene(), "s.json");
  ASSERT_EQ(s.tools.size(), 2u);
  EXPECT_DOUBLE_EQ(s.tools[0].shaftLength, 0.08);
  EXPECT_DOUBLE_EQ(s.tools[0].shaftRadius, 0.003);
  EXPECT_TRUE(s.tools[0].shaftAxis.isApprox(Vec3::UnitZ())) << "the axis is normalised";
  ASSERT_TRUE(s.tools[0].dynamics);
  EXPECT_DOUBLE_EQ(s.tools[0].dynamics->mass, 0.02);
  EXPECT_DOUBLE_EQ(s.tools[0].dynamics->coupling.stiffness, 150);
  EXPECT_DOUBLE_EQ(s.tools[0].dynamics->coupling.damping, 1.5);
  ASSERT_TRUE(s.tools[1].dynamics);
  EXPECT_DOUBLE_EQ(s.tools[1].dynamics->jawLength, 0.01);
  EXPECT_DOUBLE_EQ(s.tools[1].dynamics->shaftLength, 0.2);
  EXPECT_DOUBLE_EQ(s.tools[1].dynamics->coupling.damping, 0.5);
  EXPECT_DOUBLE_EQ(s.tools[1].dynamics->coupling.stiffness, CouplingParams{}.stiffness);
  ASSERT_EQ(s.objects.size(), 1u);
  EXPECT_EQ(s.objects[0].shapeName, "box");
  EXPECT_TRUE(s.objects[0].shape.parts.at(0).halfExtents.isApprox(Vec3(0.005, 0.01, 0.002)));
  EXPECT_DOUBLE_EQ(s.objects[0].coupling.stiffness, 50);
  EXPECT_EQ(s.objects[0].trajectory.size(), 1u);
  EXPECT_DOUBLE_EQ(s.contact.thickness, 0.0003);
  EXPECT_EQ(s.contact.passes, 3);
  EXPECT_TRUE(s.needsContact());
  EXPECT_TRUE(s.needsDynamics());
}

TEST(InstrumentScene, UnknownOrMisplacedKeysAreErrorsWithTheirPath) {
  auto j = instrumentScene();
  j["tools"][0]["shaft"]["lenght"] = 0.1;
  expectSceneError(j, "/tools/0/shaft/lenght", "unknown key 'lenght'");
  j = instrumentScene();
  j["tools"][1]["shaft"] = {{"length", 0.1}};
  expectSceneError(j, "/tools/1/shaft", "applies only to probes");
  j = instrumentScene();
  j["tools"][0]["dynamics"]["jaw_length"] = 0.01;
  expectSceneError(j, "/tools/0/dynamics/jaw_length", "unknown key");
  j = instrumentScene();
  j["objects"][0]["radius"] = 0.01;
  expectSceneError(j, "/objects/0/radius", "applies only to spheres");
  j = instrumentScene();
  j["objects"][0]["shape"] = "cone";
  expectSceneError(j, "/objects/0/shape", "\"sphere\" or \"box\"");
  j = instrumentScene();
  j["contact"]["passes"] = 0;
  expectSceneError(j, "/contact/passes", "must be in [1, 100]");
  j = instrumentScene();
  j["contact"]["restitution"] = 0.3;
  expectSceneError(j, "/contact/restitution", "unknown key");
  j = instrumentScene();
  j["objects"][0].erase("mass");
  expectSceneError(j, "/objects/0/mass", "required key is missing");
  j = instrumentScene();
  j["tools"][0]["dynamics"]["stiffness"] = -1;
  expectSceneError(j, "/tools/0/dynamics/stiffness", "must be > 0");
}

TEST(InstrumentScene, ToolsAndObjectsNeedTheirCapabilities) {
  const Scene s = parseScene(instrumentScene(), "s.json");
  ModelInfo info;
  info.name = "toy";
  info.capabilities = {Capability::Grasp};
  EXPECT_NE(harness::unsupportedReason(info, s).find("contact"), std::string::npos);
  info.capabilities.push_back(Capability::Contact);
  EXPECT_NE(harness::unsupportedReason(info, s).find("reaction_force"), std::string::npos);
  info.capabilities.push_back(Capability::ReactionForce);
  EXPECT_NE(harness::unsupportedReason(info, s).find("contact_reaction"), std::string::npos);
  info.capabilities.push_back(Capability::ContactReaction);
  EXPECT_EQ(harness::unsupportedReason(info, s), "");
  EXPECT_STREQ(capabilityName(Capability::Contact), "contact");
}

}  // namespace
}  // namespace deform
