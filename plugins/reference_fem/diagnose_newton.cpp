// Diagnostics of the reference FEM's Newton solve on the liver phantom (not a test): meshes the
// phantom, solves the static gravity (or liver-poke) problem, then reports where the exact tangent
// is indefinite (quadrature points whose dP/dF has negative eigenvalues, with the rest quality of
// their elements) and checks the element stiffness of the worst elements against central
// differences of their gradient in the deformed state.
// Run: diagnose_newton RESOLUTION TARGET ORDER [gravity|poke] (DEFORM_REFFEM_TRACE=1 for the
// per-iteration trace of the solver).
#include "fem_solver.h"
#include "liver_poke_case.h"

#include <deform/geometry/phantom.h>
#include <deform/geometry/tet_mesher.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <string>

using namespace deform;
using namespace deform::reference_fem;

namespace {

Real meanRatio(const TetMesh& m, int t) {
  Vec3 p[4];
  for (int k = 0; k < 4; ++k) p[k] = m.V.row(m.T(t, k)).transpose();
  const Real V = (p[1] - p[0]).cross(p[2] - p[0]).dot(p[3] - p[0]) / 6.0;
  Real l2 = 0;
  for (int a = 0; a < 4; ++a)
    for (int b = a + 1; b < 4; ++b) l2 += (p[a] - p[b]).squaredNorm();
  return 12.0 * std::cbrt(9.0 * V * V) / l2;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 4) {
    std::fprintf(stderr, "usage: diagnose_newton RESOLUTION TARGET ORDER [gravity|poke]\n");
    return 2;
  }
  const SurfaceMesh liver = makePhantom("liver", std::atof(argv[1]));
  const ElementOrder order = parseElementOrder(std::atoll(argv[3]));
  const bool poke = argc > 4 && std::string(argv[4]) == "poke";
  TetMeshOptions o;
  o.targetElements = std::atoll(argv[2]);
  o.refineSurface = true;
  o.source = "phantom:liver";
  const TetMeshResult r = tetrahedralize(liver, o);
  std::printf("surface %d vertices, %d tets, min dihedral %.3f deg, min mean ratio %.4f\n",
              liver.numVertices(), r.mesh.numTets(), r.quality.minDihedralDeg,
              r.quality.minMeanRatio);
  Material mat;
  mat.young = 5500;
  mat.poisson = 0.3;
  mat.density = 1000;
  FemSystem sys(r.mesh, mat, MaterialModel::NeoHookean, order);
  const LoadCase lc = liverPokeLoads(sys, poke ? liverPokeVertex(liver) : -1);
  const MatX3& V = sys.rest().V;
  std::printf("nodes %d, fixed %zu\n", sys.numNodes(), lc.fixedNodes.size());
  SolveReport rep;
  const VecX x = solveEquilibrium(sys, lc, {}, &rep);
  std::printf(
      "converged %d newton %d load steps %d failed %d factorisations %d fallbacks %d pcg %d "
      "solve %.1f s (factor %.1f assembly %.1f pcg %.1f objective %.1f)\n",
      rep.converged, rep.newtonIterations, rep.loadSteps, rep.failedLoadSteps, rep.factorizations,
      rep.spdFallbacks, rep.pcgIterations, rep.seconds, rep.factorSeconds, rep.assemblySeconds,
      rep.solveSeconds, rep.objectiveSeconds);
  Real peak = 0;
  for (int i = 0; i < liver.numVertices(); ++i)
    peak = std::max(peak, (x.segment<3>(3 * i) - V.row(i).transpose()).norm());
  std::printf("peak surface displacement %.4f mm\n", 1e3 * peak);

  // Indefinite material points at the solution.
  const NeoHookeanMaterial nh{LameParameters::fromYoungPoisson(mat.young, mat.poisson)};
  const int nen = sys.nodesPerElement();
  struct Bad {
    int t;
    Real lambda, J, quality;
  };
  std::vector<Bad> bad;
  long long points = 0, negative = 0;
  Real minJ = 1e9, maxJ = 0;
  const auto quad = quadraticTetQuadrature();
  for (int t = 0; t < r.mesh.numTets(); ++t) {
    TetRest rest;
    const Vec4i tet = r.mesh.T.row(t).transpose();
    if (!makeTetRest(V.row(tet(0)), V.row(tet(1)), V.row(tet(2)), V.row(tet(3)), rest)) continue;
    Real worst = 1e300, worstJ = 0;
    const int nq = order == ElementOrder::Quadratic ? 4 : 1;
    for (int q = 0; q < nq; ++q) {
      Mat3 F;
      if (order == ElementOrder::Quadratic) {
        const Mat3x10 G = quadraticShapeGradients(rest.gradients(), quad[size_t(q)]);
        Mat3x10 xe;
        for (int a = 0; a < 10; ++a) xe.col(a) = x.segment<3>(3 * sys.elementNode(t, a));
        F = xe * G.transpose();
      } else {
        std::array<Vec3, 4> xe;
        for (int a = 0; a < 4; ++a) xe[size_t(a)] = x.segment<3>(3 * tet(a));
        F = deformationGradient(rest, xe);
      }
      const Real J = F.determinant();
      minJ = std::min(minJ, J);
      maxJ = std::max(maxJ, J);
      const Eigen::SelfAdjointEigenSolver<Mat9> es(nh.stressDerivative(F));
      const Real l = es.eigenvalues()(0);
      ++points;
      if (l < 0) ++negative;
      if (l < worst) {
        worst = l;
        worstJ = J;
      }
    }
    if (worst < 0) bad.push_back({t, worst, worstJ, meanRatio(r.mesh, t)});
  }
  const Real mu = nh.lame.mu;
  std::printf(
      "material points %lld, with negative dP/dF eigenvalue %lld (%.2f%%), in %zu elements; J in "
      "[%.4f, %.4f]\n",
      points, negative, 100.0 * negative / points, bad.size(), minJ, maxJ);
  std::sort(bad.begin(), bad.end(), [](const Bad& a, const Bad& b) { return a.lambda < b.lambda; });
  int histo[6] = {0, 0, 0, 0, 0, 0};  // mean ratio < 0.01, 0.03, 0.1, 0.2, 0.4, else
  for (const Bad& b : bad) {
    const Real q = b.quality;
    ++histo[q < 0.01 ? 0 : q < 0.03 ? 1 : q < 0.1 ? 2 : q < 0.2 ? 3 : q < 0.4 ? 4 : 5];
  }
  int all[6] = {0, 0, 0, 0, 0, 0};
  for (int t = 0; t < r.mesh.numTets(); ++t) {
    const Real q = meanRatio(r.mesh, t);
    ++all[q < 0.01 ? 0 : q < 0.03 ? 1 : q < 0.1 ? 2 : q < 0.2 ? 3 : q < 0.4 ? 4 : 5];
  }
  std::printf("mean ratio bins <0.01 <0.03 <0.1 <0.2 <0.4 rest: indefinite");
  for (int k : histo) std::printf(" %d", k);
  std::printf(" / all");
  for (int k : all) std::printf(" %d", k);
  std::printf("\n");
  for (size_t k = 0; k < std::min<size_t>(bad.size(), 8); ++k)
    std::printf("  tet %d: min eigenvalue %.3g mu, J %.4f, mean ratio %.4f\n", bad[k].t,
                bad[k].lambda / mu, bad[k].J, bad[k].quality);

  // Element stiffness against central differences of the element gradient, deformed state.
  std::vector<int> check;
  for (size_t k = 0; k < std::min<size_t>(bad.size(), 3); ++k) check.push_back(bad[k].t);
  check.push_back(r.mesh.numTets() / 2);
  for (int t : check) {
    VecX xe(3 * nen);
    for (int a = 0; a < nen; ++a) xe.segment<3>(3 * a) = x.segment<3>(3 * sys.elementNode(t, a));
    auto gradAt = [&](const VecX& y) {
      VecX full = x;
      for (int a = 0; a < nen; ++a)
        full.segment<3>(3 * sys.elementNode(t, a)) = y.segment<3>(3 * a);
      VecX g;
      sys.elasticGradient(full, g);
      VecX ge(3 * nen);
      for (int a = 0; a < nen; ++a) ge.segment<3>(3 * a) = g.segment<3>(3 * sys.elementNode(t, a));
      return ge;
    };
    // Element stiffness through the assembled tangent restricted to the element's dofs would mix
    // the neighbours; compare the assembled K's element-dof block with the FD of the assembled
    // gradient instead (both include the neighbours' contributions).
    VecX values;
    sys.stiffnessValues(x, values, false);
    const SparseMatrix& P = sys.stiffnessPattern();
    const Eigen::Map<const SparseMatrix> Kfull(P.rows(), P.cols(), P.nonZeros(), P.outerIndexPtr(),
                                               P.innerIndexPtr(), values.data());
    MatX K(3 * nen, 3 * nen), Kfd(3 * nen, 3 * nen);
    const Real h = 1e-7;
    for (int j = 0; j < 3 * nen; ++j) {
      VecX p = xe, m = xe;
      p(j) += h;
      m(j) -= h;
      Kfd.col(j) = (gradAt(p) - gradAt(m)) / (2 * h);
      for (int i = 0; i < 3 * nen; ++i)
        K(i, j) = Kfull.coeff(3 * sys.elementNode(t, i / 3) + i % 3,
                              3 * sys.elementNode(t, j / 3) + j % 3);
    }
    std::printf("tet %d: |K - K_fd| / |K| = %.3e, |K - K^T| / |K| = %.3e\n", t,
                (K - Kfd).norm() / K.norm(), (K - K.transpose()).norm() / K.norm());
  }
  return 0;
}
