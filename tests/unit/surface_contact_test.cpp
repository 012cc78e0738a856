// Contact on surface triangles (issue F8: "the surface triangles for the others"): a tool thinner
// than the vertex spacing is found on the triangle and pushed out through its vertices by the
// barycentric weights; the penalty force and Coulomb friction use the same triangles; the scene
// keys of the contact method are parsed strictly.
#include <deform/engine/scene.h>
#include <deform/geometry/distance.h>
#include <deform/sdk/contact.h>
#include <deform/sdk/error.h>
#include <gtest/gtest.h>

namespace deform {
namespace {

/// A coarse square patch in the plane z = 0: side `side`, split into two triangles, normal +z.
struct Patch {
  MatX3 V;
  MatX3i F;
};
Patch squarePatch(Real side) {
  Patch p;
  p.V.resize(4, 3);
  p.V << 0, 0, 0, side, 0, 0, side, side, 0, 0, side, 0;
  p.F.resize(2, 3);
  p.F << 0, 1, 2, 0, 2, 3;
  return p;
}

/// Smallest distance from the sphere centre c to the patch's triangles.
Real patchDistance(const Patch& p, const Vec3& c) {
  Real d = 1e9;
  for (Eigen::Index f = 0; f < p.F.rows(); ++f)
    d = std::min(d, std::sqrt(closestPointOnTriangle(c, p.V.row(p.F(f, 0)).transpose(),
                                                     p.V.row(p.F(f, 1)).transpose(),
                                                     p.V.row(p.F(f, 2)).transpose())
                                  .dist2));
  return d;
}

/// Contact parameters with the 0.1 mm skin thickness of these tests.
ContactParams withSkin() {
  ContactParams params;
  params.thickness = 1e-4;
  return params;
}

/// A spherical probe tip of radius r, its centre placed at `at`; returns the body.
int placeProbe(ContactWorld& w, Real r, const Vec3& at) {
  const int b = w.addBody(probeShape(r, 0.0, 0.0, Vec3::UnitZ()));
  w.setPose(b, at);
  return b;
}

/// The impulse (N s) the vertices of `mass` kg received in a step of dt that moved them from
/// `before` to `after`.
Vec3 receivedImpulse(const MatX3& before, const MatX3& after, Real mass, Real dt) {
  Vec3 impulse = Vec3::Zero();
  for (Eigen::Index i = 0; i < after.rows(); ++i)
    impulse += mass * (after.row(i) - before.row(i)).transpose() / dt;
  return impulse;
}

/// The projection response on a surface proxy that is its own nodes.
ContactResolution projectSurface(ContactWorld& w, MatX3& V, const MatX3i& F, const VecX& invMass,
                                 Real dt, const MatX3* atStepStart = nullptr) {
  ContactProxy proxy;
  proxy.nodes = &V;
  proxy.invMass = &invMass;
  proxy.faces = &F;
  proxy.atStepStart = atStepStart;
  return respondToContact(w, proxy, ContactResponse::Project, dt);
}

/// The penalty response on the same proxy, over a step of 1 ms.
ContactResolution penaltyForces(ContactWorld& w, MatX3 V, const MatX3i& F, MatX3* v, MatX3& f) {
  ContactProxy proxy;
  proxy.nodes = &V;
  proxy.velocity = v ? v->data() : nullptr;
  proxy.faces = &F;
  return respondToContact(w, proxy, ContactResponse::Penalty, 1e-3, f.data());
}

TEST(TriangleContact, AThinTipInTheMiddleOfATriangleIsFoundWhereVerticesMissIt) {
  ContactWorld w(withSkin());
  const Real r = 1e-3;                             // 2 mm tip, the triangle's legs are 10 mm
  placeProbe(w, r, Vec3(0.006, 0.002, r - 5e-4));  // 0.5 mm into the first triangle
  const Patch p = squarePatch(0.01);
  EXPECT_TRUE(w.query(p.V).empty()) << "no vertex is near the tip";
  const std::vector<TriangleContact> c = w.queryTriangles(p.V, p.F);
  ASSERT_EQ(c.size(), 1u);
  EXPECT_EQ(c[0].triangle, 0);
  EXPECT_NEAR(c[0].depth, 5e-4 + 1e-4, 1e-8);
  EXPECT_TRUE(c[0].normal.isApprox(Vec3(0, 0, -1), 1e-6)) << c[0].normal.transpose();
  // The deepest point is below the tip centre: (6, 2) mm = 0.4 a + 0.4 b + 0.2 c.
  EXPECT_TRUE(c[0].bary.isApprox(Vec3(0.4, 0.4, 0.2), 1e-6)) << c[0].bary.transpose();
}

TEST(TriangleContact, ShaftsAndBoxesAgainstATriangleGiveTheirDistance) {
  ContactParams params;
  params.thickness = 2e-4;
  ContactWorld w(params);
  // A shaft lying along x, 0.3 mm into the patch; a box whose bottom face is 1 mm into it.
  ShapePrimitive cap;
  cap.kind = ShapePrimitive::Kind::Capsule;
  cap.axis = Vec3::UnitX();
  cap.radius = 1e-3;
  cap.length = 0.004;
  const int shaft = w.addBody(RigidShape{{cap}});
  w.setPose(shaft, Vec3(0.006, 0.0015, 1e-3 - 3e-4));  // over the first triangle only
  const Patch p = squarePatch(0.01);
  std::vector<TriangleContact> c = w.queryTriangles(p.V, p.F);
  ASSERT_EQ(c.size(), 1u);
  // GJK/EPA shapes carry Bullet's collision margin (1 um here) on the triangle.
  EXPECT_NEAR(c[0].depth, 3e-4 + 2e-4, 2e-6);
  EXPECT_GT(-c[0].normal.z(), 0.999);
  ShapePrimitive box;
  box.kind = ShapePrimitive::Kind::Box;
  box.halfExtents = Vec3(0.001, 0.001, 0.002);
  ContactWorld w2(params);
  const int cube = w2.addBody(RigidShape{{box}});
  w2.setPose(cube, Vec3(0.003, 0.007, 0.002 - 1e-3));  // inside the second triangle only
  c = w2.queryTriangles(p.V, p.F);
  ASSERT_EQ(c.size(), 1u);
  EXPECT_EQ(c[0].triangle, 1);
  EXPECT_NEAR(c[0].depth, 1e-3 + 2e-4, 2e-6);
  EXPECT_GT(-c[0].normal.z(), 0.999);
}

TEST(ResolveSurfaceContacts, AThinTipLeavesNoTrianglePointInsideAndFeelsTheImpulse) {
  const ContactParams params = withSkin();
  ContactWorld w(params);
  const Real r = 1e-3;
  const Vec3 at(0.006, 0.002, r - 8e-4);
  const int b = placeProbe(w, r, at);
  Patch p = squarePatch(0.01);
  const MatX3 before = p.V;
  const VecX invMass = VecX::Constant(4, 1.0 / 0.002);  // 2 g vertices
  const Real dt = 1e-3;
  const ContactResolution res = projectSurface(w, p.V, p.F, invMass, dt);
  EXPECT_EQ(res.contacts, 1);
  EXPECT_NEAR(res.maxDepth, 9e-4, 1e-8);
  // Vertex-sphere contact would have left the patch untouched.
  EXPECT_GE(patchDistance(p, at), r + 0.99 * params.thickness);
  EXPECT_LT(p.V(0, 2), 0) << "the patch was pushed down";
  // The minimum-norm distribution: the vertices of the touched triangle move in proportion to
  // their barycentric weights (0.4, 0.4, 0.2); vertex 3 (other triangle) stays.
  EXPECT_NEAR(p.V(0, 2) / p.V(2, 2), 2.0, 1e-3);
  EXPECT_NEAR(p.V(1, 2) / p.V(2, 2), 2.0, 1e-3);
  EXPECT_EQ(p.V(3, 2), 0.0);
  // Reaction: minus the impulse the vertices received, sum m dx / dt / dt, pushes the tool up.
  const Vec3 impulse = receivedImpulse(before, p.V, 0.002, dt);
  EXPECT_TRUE(w.reactionForce(b).isApprox(-impulse / dt, 1e-9))
      << w.reactionForce(b).transpose() << " vs " << (-impulse / dt).transpose();
  EXPECT_GT(w.reactionForce(b).z(), 0);
}

// A body with dynamics takes its share: the tissue point (generalized inverse mass W) moves by
// W / (W + 1/m) of the depth, and the reaction, applied for one step, moves the body by the rest.
TEST(ResolveSurfaceContacts, ALightBodySharesTheCorrectionInProportionToInverseMasses) {
  const ContactParams params = withSkin();
  const Real r = 1e-3, dt = 1e-3;
  const Vec3 at(0.006, 0.002, r - 8e-4);
  const VecX invMass = VecX::Constant(4, 1.0 / 0.002);  // 2 g vertices
  // Generalized inverse mass of the contact point, barycentrics (0.4, 0.4, 0.2).
  const Real W = invMass[0] * (0.4 * 0.4 + 0.4 * 0.4 + 0.2 * 0.2);
  for (const Real bodyMass : {0.0, 0.005, 0.0005}) {
    SCOPED_TRACE(bodyMass);
    ContactWorld w(params);
    const int b = placeProbe(w, r, at);
    if (bodyMass > 0) w.setInverseMass(b, 1.0 / bodyMass);
    EXPECT_EQ(w.inverseMass(b), bodyMass > 0 ? 1.0 / bodyMass : 0.0);
    Patch p = squarePatch(0.01);
    const MatX3 before = p.V;
    projectSurface(w, p.V, p.F, invMass, dt);
    const Real depth = 9e-4;
    const Real share = bodyMass > 0 ? W / (W + 1.0 / bodyMass) : 1.0;
    // The contact point (bary 0.4, 0.4, 0.2 of vertices 0, 1, 2) moved down by share * depth
    // (to 0.5%: the later passes find the curved tip's next-deepest point a little deeper).
    const Real tol = 5e-3 * depth;
    const Real pointMoved = 0.4 * p.V(0, 2) + 0.4 * p.V(1, 2) + 0.2 * p.V(2, 2);
    EXPECT_NEAR(pointMoved, -share * depth, tol);
    // One step of the body under the reaction: dx_b = w_b F dt^2, the rest of the depth.
    if (bodyMass > 0) {
      const Vec3 dxBody = w.reactionForce(b) * dt * dt / bodyMass;
      EXPECT_NEAR(dxBody.z(), (1 - share) * depth, tol);
      EXPECT_NEAR(dxBody.z() - pointMoved, depth, tol) << "together they separate by the depth";
    }
    EXPECT_TRUE(w.reactionForce(b).isApprox(-receivedImpulse(before, p.V, 0.002, dt) / dt, 1e-9))
        << "action = reaction";
  }
}

TEST(ResolveSurfaceContacts, EmbeddedTrianglesMoveTheirNodesAndRemoveTheInwardVelocity) {
  const ContactParams params = withSkin();
  ContactWorld w(params);
  const Real r = 1e-3;
  const Vec3 at(0.004, 0.004, r - 6e-4);
  placeProbe(w, r, at);
  // Surface vertex a is the mean of nodes a and a + 4, the latter 2 mm below: a two-layer patch.
  const Patch p0 = squarePatch(0.01);
  MatX3 nodes(8, 3);
  nodes.topRows(4) = p0.V;
  nodes.bottomRows(4) = p0.V;
  nodes.topRows(4).col(2).array() += 1e-3;
  nodes.bottomRows(4).col(2).array() -= 1e-3;
  EmbeddingIds ids(4, 2);
  EmbeddingWeights wts(4, 2);
  for (int a = 0; a < 4; ++a) {
    ids.row(a) << a, a + 4;
    wts.row(a) << 0.5, 0.5;
  }
  VecX invMass = VecX::Constant(8, 1000.0);
  invMass[7] = 0;  // an immovable node
  VecX vel = VecX::Zero(24);
  for (int n = 0; n < 8; ++n) vel[3 * n + 2] = 0.1;  // moving up, into the tool
  ContactProxy proxy;
  proxy.nodes = &nodes;
  proxy.invMass = &invMass;
  proxy.velocity = vel.data();
  proxy.faces = &p0.F;
  proxy.embedding = embeddingOf(ids, wts);
  respondToContact(w, proxy, ContactResponse::Project, 1e-3);
  Patch surf;
  surf.F = p0.F;
  surf.V = 0.5 * (nodes.topRows(4) + nodes.bottomRows(4));
  EXPECT_GE(patchDistance(surf, at), r + 0.99 * params.thickness);
  EXPECT_EQ(nodes(7, 2), p0.V(3, 2) - 1e-3) << "an immovable node moved";
  // The surface point nearest the tip no longer moves up into the tool.
  const auto surfaceVelocity = [&](int a) {
    return 0.5 * (Eigen::Map<const Vec3>(vel.data() + 3 * a) +
                  Eigen::Map<const Vec3>(vel.data() + 3 * (a + 4)));
  };
  Real best = 1e9;
  Vec3 vp = Vec3::Zero();
  for (int f = 0; f < 2; ++f) {
    const Eigen::Vector3i t = surf.F.row(f);
    const TriangleClosestPoint cp =
        closestPointOnTriangle(at, surf.V.row(t[0]).transpose(), surf.V.row(t[1]).transpose(),
                               surf.V.row(t[2]).transpose());
    if (cp.dist2 >= best) continue;
    best = cp.dist2;
    vp = Vec3::Zero();
    for (int a = 0; a < 3; ++a) vp += cp.bary[a] * surfaceVelocity(t[a]);
  }
  EXPECT_LE(vp.z(), 1e-9) << "still moving up into the tool: " << vp.transpose();
  EXPECT_GT(surfaceVelocity(3).z(), 0.09) << "a vertex away from the contact lost its velocity";
}

TEST(PenaltyContact, TheForceIsPressureStiffnessTimesAreaTimesDepthSpreadByBarycentricWeights) {
  ContactParams params = withSkin();
  params.method = ContactMethod::Penalty;
  params.stiffness = 2e6;
  params.damping = 0;
  ContactWorld w(params);
  const Real r = 1e-3;
  const int b = placeProbe(w, r, Vec3(0.006, 0.002, r - 4e-4));
  const Patch p = squarePatch(0.01);
  MatX3 f = MatX3::Zero(4, 3);
  const ContactResolution res = penaltyForces(w, p.V, p.F, nullptr, f);
  EXPECT_EQ(res.contacts, 1);
  const Real area = 0.5 * 0.01 * 0.01, depth = 4e-4 + 1e-4;
  const Real fn = params.stiffness * area * depth;
  EXPECT_NEAR(f(0, 2), -0.4 * fn, 1e-9 * fn);
  EXPECT_NEAR(f(1, 2), -0.4 * fn, 1e-9 * fn);
  EXPECT_NEAR(f(2, 2), -0.2 * fn, 1e-9 * fn);
  EXPECT_EQ(f(3, 2), 0.0);
  EXPECT_NEAR(w.reactionForce(b).z(), fn, 1e-9 * fn);
  // Damping: a patch moving up into the tool at 0.1 m/s feels c_A A 0.1 more.
  ContactParams damped = params;
  damped.damping = 500;
  ContactWorld w2(damped);
  placeProbe(w2, r, Vec3(0.006, 0.002, r - 4e-4));
  MatX3 v = MatX3::Zero(4, 3);
  v.col(2).setConstant(0.1);
  MatX3 f2 = MatX3::Zero(4, 3);
  penaltyForces(w2, p.V, p.F, &v, f2);
  EXPECT_NEAR(-f2.col(2).sum(), fn + 500 * area * 0.1, 1e-9 * fn);
}

TEST(ContactFriction, StaticFrictionDragsTheTouchedPointAlongAndFrictionlessDoesNot) {
  // A round tool (3 mm sphere) resting 0.3 mm into the patch moves 0.2 mm along x in the step.
  const auto run = [](Real mu, Vec3* reaction) {
    ContactParams params = withSkin();
    params.friction = mu;
    ContactWorld w(params);
    const int b = w.addBody(probeShape(0.003, 0.0, 0.0, Vec3::UnitZ()));
    w.setPose(b, Vec3(0.0043, 0.002, 0.003 - 3e-4));
    w.setPose(b, Vec3(0.0045, 0.002, 0.003 - 3e-4));
    Patch p = squarePatch(0.01);
    const MatX3 x0 = p.V;
    projectSurface(w, p.V, p.F, VecX::Constant(4, 1000.0), 1e-3, &x0);
    *reaction = w.reactionForce(b);
    return p.V;
  };
  Vec3 r0, r1, rk;
  const MatX3 none = run(0.0, &r0);
  const MatX3 stick = run(1.0, &r1);
  const MatX3 slip = run(0.1, &rk);
  const MatX3 x0 = squarePatch(0.01).V;
  // Static (|dt| = 0.2 mm < mu d = 0.4 mm): the contact point moves with the tool, so the patch
  // (here only the touched triangle's vertices) moves along +x; the tool feels -x.
  EXPECT_GT(stick(0, 0), 0);
  EXPECT_LT(r1.x(), 0);
  // Frictionless, only the tilt of the pushed triangle moves anything along x.
  EXPECT_LT((none - x0).col(0).cwiseAbs().maxCoeff(), 0.01 * stick(0, 0)) << "frictionless";
  EXPECT_LT(std::abs(r0.x()), 0.01 * std::abs(r1.x()));
  // Kinetic (mu d = 0.04 mm < 0.2 mm): dragged less, pushed back less.
  EXPECT_GT(slip(0, 0), 0);
  EXPECT_LT(slip(0, 0), stick(0, 0));
  EXPECT_GT(rk.x(), r1.x());
}

TEST(ContactScene, MethodStiffnessDampingAndFrictionAreParsedStrictly) {
  using nlohmann::json;
  json j = {{"organ", {{"mesh", "phantom:cube"}}},
            {"dt", 1e-3},
            {"duration", 0.01},
            {"models", json::array({{{"plugin", "pbd"}}})}};
  j["contact"] = {{"method", "penalty"}, {"stiffness", 5e5}, {"damping", 20}, {"friction", 0.4}};
  Scene s = parseScene(j, "s.json");
  EXPECT_EQ(s.contact.method, ContactMethod::Penalty);
  EXPECT_DOUBLE_EQ(s.contact.stiffness, 5e5);
  EXPECT_DOUBLE_EQ(s.contact.damping, 20);
  EXPECT_DOUBLE_EQ(s.contact.friction, 0.4);
  j["contact"] = json::object();
  s = parseScene(j, "s.json");
  EXPECT_EQ(s.contact.method, ContactMethod::Projection) << "the default";
  EXPECT_EQ(s.contact.friction, 0.0);
  const auto fails = [&](const json& contact, const std::string& where) {
    json k = j;
    k["contact"] = contact;
    try {
      parseScene(k, "s.json");
      ADD_FAILURE() << contact.dump() << " was accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(where), std::string::npos) << e.what();
    }
  };
  fails({{"method", "spring"}}, "/contact/method");
  fails({{"stiffness", 1e5}}, "/contact/stiffness");  // projection has no stiffness
  fails({{"method", "penalty"}, {"stiffness", -1}}, "/contact/stiffness");
  fails({{"method", "penalty"}, {"damping", -1}}, "/contact/damping");
  fails({{"friction", -0.1}}, "/contact/friction");
}

TEST(ContactProxy, AProxyThatDoesNotDescribeWhatTheResponseNeedsIsRefusedInOneLine) {
  ContactWorld w;
  w.setPose(w.addBody(probeShape(0.002, 0.0, 0.0, Vec3::UnitZ())), Vec3(0.005, 0.005, 0.0));
  Patch p = squarePatch(0.01);
  const VecX invMass = VecX::Constant(3, 1.0);  // one short
  const auto message = [&](ContactProxy proxy, ContactResponse r, Real* force) {
    try {
      respondToContact(w, proxy, r, 1e-3, force);
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  ContactProxy proxy;
  EXPECT_NE(message(proxy, ContactResponse::Project, nullptr).find("proxy.nodes"),
            std::string::npos);
  proxy.nodes = &p.V;
  proxy.invMass = &invMass;
  EXPECT_NE(message(proxy, ContactResponse::Project, nullptr).find("proxy.invMass"),
            std::string::npos);
  EXPECT_NE(message(proxy, ContactResponse::Penalty, nullptr).find("proxy.faces"),
            std::string::npos);
  proxy.faces = &p.F;
  EXPECT_NE(message(proxy, ContactResponse::Penalty, nullptr).find("force array"),
            std::string::npos);
  const VecX radii = VecX::Constant(4, 1e-3);
  proxy.radii = &radii;
  EXPECT_NE(message(proxy, ContactResponse::Project, nullptr).find("proxy.radii"),
            std::string::npos);
  // Nothing was moved by a refused call.
  EXPECT_EQ(p.V, squarePatch(0.01).V);
}

TEST(ContactProxy, DisplayProjectionMovesPointsOutWithoutReaction) {
  ContactWorld w;
  const int b = w.addBody(probeShape(0.002, 0.0, 0.0, Vec3::UnitZ()));
  w.setPose(b, Vec3(0.0, 0.0, 0.0015));
  MatX3 points(2, 3);
  points << 0, 0, 0,  //
      0.01, 0, 0;
  ContactProxy proxy;
  proxy.nodes = &points;
  const ContactResolution r = respondToContact(w, proxy, ContactResponse::Display, 1e-3);
  EXPECT_EQ(r.contacts, 1);
  EXPECT_NEAR(r.maxDepth, 0.0005 + w.params().thickness, 1e-9);
  EXPECT_NEAR((points.row(0).transpose() - Vec3(0, 0, 0.0015)).norm(), 0.002 + w.params().thickness,
              1e-9);
  EXPECT_EQ(points(1, 0), 0.01);
  EXPECT_EQ(w.reactionForce(b), Vec3::Zero());
}

}  // namespace
}  // namespace deform
