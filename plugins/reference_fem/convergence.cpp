#include "convergence.h"

#include <algorithm>
#include <chrono>
#include <cmath>

namespace deform::reference_fem {

namespace {

ConvergenceLevel solveLevel(const TetMesh& mesh, int numSurface, const Material& material,
                            MaterialModel model, const LoadCaseBuilder& loads,
                            const SolveOptions& solve, ElementOrder order) {
  ConvergenceLevel L;
  L.elements = mesh.numTets();
  L.nodes = mesh.numVertices();
  const SurfaceMesh b = tetBoundary(mesh);
  L.h = std::cbrt(signedVolume(b.V, b.F) / Real(mesh.numTets()));
  FemSystem sys(mesh, material, model, order);
  L.nodes = sys.numNodes();
  SolveReport rep;
  const VecX x = solveEquilibrium(sys, loads(sys), solve, &rep);
  L.converged = rep.converged;
  L.solveSeconds = rep.seconds;
  L.surfaceDisplacement.resize(numSurface, 3);
  for (int i = 0; i < numSurface; ++i)
    L.surfaceDisplacement.row(i) = (x.segment<3>(3 * i) - mesh.V.row(i).transpose()).transpose();
  L.peakDisplacement = L.surfaceDisplacement.rowwise().norm().maxCoeff();
  return L;
}

}  // namespace

void richardson(ConvergenceStudy& s, const std::vector<char>& include) {
  if (s.levels.size() < 3) return;
  const auto& L = s.levels;
  const size_t n = L.size();
  auto maxDiff = [&](const MatX3& a, const MatX3& b) {
    Real m = 0;
    for (Eigen::Index i = 0; i < a.rows(); ++i)
      if (include.empty() || include[size_t(i)]) m = std::max(m, (a.row(i) - b.row(i)).norm());
    return m;
  };
  const Real d01 = maxDiff(L[n - 3].surfaceDisplacement, L[n - 2].surfaceDisplacement);
  const Real d12 = maxDiff(L[n - 2].surfaceDisplacement, L[n - 1].surfaceDisplacement);
  const Real h0 = L[n - 3].h, h1 = L[n - 2].h, h2 = L[n - 1].h;
  Real peak = 0;
  for (Eigen::Index i = 0; i < L[n - 1].surfaceDisplacement.rows(); ++i)
    if (include.empty() || include[size_t(i)])
      peak = std::max(peak, L[n - 1].surfaceDisplacement.row(i).norm());
  s.reason.clear();
  if (!(h0 > h1 && h1 > h2)) {
    s.reason = "not_refining";
  } else if (h0 / h1 < 1.1 || h1 / h2 < 1.1) {
    s.reason = "levels_too_close";
  } else if (!(d12 > 0) || !(d01 > 0)) {
    s.reason = "coincide";
  } else if (d12 >= d01) {
    s.reason = "not_monotone";
  }
  if (!(d12 > 0) || !(d01 > 0) || !(h0 > h1 && h1 > h2)) {
    s.observedOrder = 0;
    s.errorEstimate = d12;
    s.relativeError = peak > 0 ? d12 / peak : 0;
    s.asymptotic = d12 == 0 && d01 == 0;
    s.withinOnePercent = s.asymptotic;
    return;
  }
  // Solve (h0^p - h1^p)/(h1^p - h2^p) = d01/d12 for p by bisection on [0.05, 8]; the left side
  // increases monotonically with p for h0 > h1 > h2.
  const Real target = d01 / d12;
  auto ratio = [&](Real p) {
    return (std::pow(h0, p) - std::pow(h1, p)) / (std::pow(h1, p) - std::pow(h2, p));
  };
  Real lo = 0.05, hi = 8;
  Real p;
  if (target <= ratio(lo)) {
    p = lo;
  } else if (target >= ratio(hi)) {
    p = hi;
  } else {
    for (int it = 0; it < 200; ++it) {
      const Real mid = 0.5 * (lo + hi);
      (ratio(mid) < target ? lo : hi) = mid;
    }
    p = 0.5 * (lo + hi);
  }
  s.observedOrder = p;
  s.asymptotic = p >= 0.5 && p <= 4.0;
  s.errorEstimate = d12 * std::pow(h2, p) / (std::pow(h1, p) - std::pow(h2, p));
  s.relativeError = peak > 0 ? s.errorEstimate / peak : 0;
  s.withinOnePercent = s.asymptotic && s.relativeError <= 0.01;
  if (s.reason.empty() && !s.asymptotic) s.reason = "not_asymptotic";
}

ConvergenceStudy runConvergenceStudyOnMeshes(const std::vector<TetMesh>& meshes, int numSurface,
                                             const Material& material, MaterialModel model,
                                             const LoadCaseBuilder& loads,
                                             const SolveOptions& solve, ElementOrder order) {
  ConvergenceStudy s;
  for (const TetMesh& m : meshes)
    s.levels.push_back(solveLevel(m, numSurface, material, model, loads, solve, order));
  richardson(s, {});
  return s;
}

ConvergenceStudy runConvergenceStudy(const SurfaceMesh& surface, const Material& material,
                                     MaterialModel model, const LoadCaseBuilder& loads,
                                     const std::vector<long long>& elementCounts,
                                     const SolveOptions& solve,
                                     const std::vector<Vec3>& excludeNear, Real excludeRadius,
                                     const std::string& source, ElementOrder order) {
  ConvergenceStudy s;
  for (long long count : elementCounts) {
    TetMeshOptions o;
    o.targetElements = count;
    o.refineSurface = true;
    o.source = source;
    const TetMeshResult r = tetrahedralize(surface, o);
    ConvergenceLevel L =
        solveLevel(r.mesh, surface.numVertices(), material, model, loads, solve, order);
    L.meshSeconds = r.seconds;
    s.levels.push_back(std::move(L));
  }
  std::vector<char> include(size_t(surface.numVertices()), 1);
  for (int i = 0; i < surface.numVertices(); ++i)
    for (const Vec3& p : excludeNear)
      if ((surface.V.row(i).transpose() - p).norm() < excludeRadius) include[size_t(i)] = 0;
  richardson(s, include);
  return s;
}

}  // namespace deform::reference_fem
