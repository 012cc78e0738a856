// The reference's point force: the pressure patch it is spread over (PointLoadSpreader) and the
// large-load case it exists for, 20 N on the 0.1 m cube phantom of E = 5.5 kPa (the hybrid
// tables' largest load), which must converge and stay far inside the harness's divergence box.
#include "fem_solver.h"

#include <deform/geometry/phantom.h>
#include <deform/geometry/tet_mesher.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <set>

using namespace deform;
using namespace deform::reference_fem;

namespace {

struct CubeProblem {
  TetMesh mesh;
  std::vector<int> fixed;  ///< nodes of the bottom tenth
  int top = -1;            ///< the surface vertex nearest the top centre (= its node)
  Real size = 0;           ///< edge of the cube, m
};

const CubeProblem& cube() {
  static const CubeProblem p = [] {
    CubeProblem c;
    const SurfaceMesh s = makePhantom("cube", 0.5);
    TetMeshOptions o;
    o.targetElements = 3000;
    o.refineSurface = true;
    o.source = "phantom:cube";
    c.mesh = tetrahedralize(s, o).mesh;
    const Box b = boundingBox(s.V);
    c.size = b.size().maxCoeff();
    c.top = nearestVertex(s.V, Vec3(b.center().x(), b.center().y(), b.hi.z()));
    for (int i = 0; i < c.mesh.numVertices(); ++i)
      if (c.mesh.V(i, 2) <= b.lo.z() + 0.1 * b.size().z()) c.fixed.push_back(i);
    return c;
  }();
  return p;
}

Material tissue() {
  Material m;
  m.young = 5500;
  m.poisson = 0.3;
  m.density = 1000;
  return m;
}

}  // namespace

TEST(ReferenceFemPointLoad, PatchCoversTheOneRingSumsToOneAndDecaysOutwards) {
  const CubeProblem& c = cube();
  const PointLoadSpreader spreader(c.mesh);
  const SurfaceMesh b = tetBoundary(c.mesh);
  std::set<int> ring;
  Real longest = 0;
  for (int f = 0; f < b.numFaces(); ++f)
    for (int k = 0; k < 3; ++k)
      if (b.F(f, k) == c.top)
        for (int j = 0; j < 3; ++j) {
          ring.insert(b.F(f, j));
          longest = std::max(longest, (c.mesh.V.row(b.F(f, j)) - c.mesh.V.row(c.top)).norm());
        }
  ASSERT_GT(ring.size(), 3u);
  for (const Real radius : {0.0, 0.01, 0.02}) {
    const PointLoadPatch p = spreader.patch(c.top, radius);
    EXPECT_EQ(p.nodes.front(), c.top);
    EXPECT_NEAR(p.radius, std::max(radius, 1.5 * longest), 1e-15);
    Real sum = 0;
    for (size_t k = 0; k < p.nodes.size(); ++k) {
      EXPECT_GT(p.weights[k], 0.0);
      EXPECT_LT((c.mesh.V.row(p.nodes[k]) - c.mesh.V.row(c.top)).norm(), p.radius);
      // The top face is flat: every patch node lies on it (nothing of the sides is loaded).
      EXPECT_NEAR(c.mesh.V(p.nodes[k], 2), c.mesh.V(c.top, 2), 1e-12);
      sum += p.weights[k];
    }
    EXPECT_NEAR(sum, 1.0, 1e-12);
    for (int n : ring)
      EXPECT_NE(std::find(p.nodes.begin(), p.nodes.end(), n), p.nodes.end()) << "one-ring " << n;
  }
  // A larger radius spreads the force over more nodes and takes share from the centre.
  const PointLoadPatch small = spreader.patch(c.top, 0.0), large = spreader.patch(c.top, 0.02);
  EXPECT_GT(large.nodes.size(), small.nodes.size());
  EXPECT_LT(large.weights.front(), small.weights.front());
}

// 20 N up (tension) and down (pressure) at the top of the cube, bottom tenth fixed: Newton with
// load stepping converges, the reaction at the fixed nodes balances the load, the loaded point
// moves along the force, and every node stays within the divergence box (10 x the organ).
TEST(ReferenceFemPointLoad, TwentyNewtonsOnTheCubeConvergeInsideTheBox) {
  const CubeProblem& c = cube();
  const FemSystem sys(c.mesh, tissue(), MaterialModel::NeoHookean);
  const PointLoadSpreader spreader(c.mesh);
  const PointLoadPatch patch = spreader.patch(c.top, 0.03);  // the plugin's default
  const Box box = boundingBox(c.mesh.V);
  for (const Real fz : {20.0, -20.0}) {
    LoadCase lc;
    lc.fixedNodes = c.fixed;
    for (size_t k = 0; k < patch.nodes.size(); ++k)
      lc.nodeForces.emplace_back(patch.nodes[k], patch.weights[k] * Vec3(0, 0, fz));
    EquilibriumSolver solver(sys);
    VecX x = sys.restPositions();
    const SolveReport rep = solver.solveStatic(lc, x);
    ASSERT_TRUE(rep.converged) << "fz " << fz << ": residual " << rep.residual << " of scale "
                               << rep.forceScale << " after " << rep.loadSteps << " load steps";
    ASSERT_TRUE(x.allFinite());
    Vec3 reaction = Vec3::Zero();
    for (int n : c.fixed) reaction += solver.lastGradient().segment<3>(3 * n);
    EXPECT_LT((reaction + Vec3(0, 0, fz)).norm(), 1e-5 * std::abs(fz)) << reaction.transpose();
    const Vec3 u = x.segment<3>(3 * c.top) - c.mesh.V.row(c.top).transpose();
    EXPECT_GT(u.z() * fz, 0.0) << "the loaded point moves along the force: " << u.transpose();
    EXPECT_GT(std::abs(u.z()), 0.01 * c.size) << "a 20 N load visibly deforms 5.5 kPa tissue";
    for (int i = 0; i < sys.numNodes(); ++i)
      ASSERT_LT((x.segment<3>(3 * i) - box.center()).cwiseAbs().maxCoeff(), 5 * c.size)
          << "node " << i << " left the divergence box (fz " << fz << ")";
  }
}
