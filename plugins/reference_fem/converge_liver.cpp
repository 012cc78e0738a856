// Mesh-convergence measurement of the reference FEM on the liver phantom (not a test): the static
// liver-poke problem (scenes/liver_poke.json: E = 5500 Pa, nu = 0.3, rho = 1000, the scene's two
// fixed boxes, gravity, 2 N down on the top of the right lobe spread over the 3 cm pressure patch)
// at three element counts, with the Richardson estimate of convergence.h.
// Run: build/plugins/reference_fem/converge_liver ORDER MATERIAL N0 N1 N2 [RESOLUTION]
//      e.g. converge_liver 2 neo_hookean 2000 5600 16000 (RESOLUTION: of makePhantom, default 1;
//      "gravity" drops the 2 N poke)
#include "convergence.h"
#include "liver_poke_case.h"

#include <deform/geometry/phantom.h>

#include <cstdio>
#include <cstdlib>
#include <string>

using namespace deform;
using namespace deform::reference_fem;

int main(int argc, char** argv) {
  if (argc < 6 || argc > 8) {
    std::fprintf(
        stderr, "usage: converge_liver ORDER(1|2) MATERIAL N0 N1 N2 [RESOLUTION [poke|gravity]]\n");
    return 2;
  }
  const ElementOrder order = parseElementOrder(std::atoll(argv[1]));
  const MaterialModel model = parseMaterialModel(argv[2]);
  const std::vector<long long> counts = {std::atoll(argv[3]), std::atoll(argv[4]),
                                         std::atoll(argv[5])};
  const SurfaceMesh liver = makePhantom("liver", argc >= 7 ? std::atof(argv[6]) : 1.0);
  std::printf("liver phantom: %d surface vertices\n", liver.numVertices());
  Material mat;
  mat.young = 5500;
  mat.poisson = 0.3;
  mat.density = 1000;
  const std::array<Box, 2> fixed = liverPokeFixedBoxes();
  const Vec3 poke = liverPokePoint();
  const bool withPoke = argc < 8 || std::string(argv[7]) != "gravity";
  const int pokeVertex = withPoke ? liverPokeVertex(liver) : -1;
  auto loads = [&](const FemSystem& sys) { return liverPokeLoads(sys, pokeVertex); };
  const ConvergenceStudy s =
      runConvergenceStudy(liver, mat, model, loads, counts, {}, {}, 0, "phantom:liver", order);
  for (const auto& l : s.levels)
    std::printf(
        "P%d tets %lld nodes %lld dofs %lld h %.4g peak %.6g m converged %d mesh %.2f s "
        "solve %.2f s\n",
        int(order), l.elements, l.nodes, 3 * l.nodes, l.h, l.peakDisplacement, l.converged,
        l.meshSeconds, l.solveSeconds);
  // Where the finest two levels differ most (the Richardson error is driven by that vertex).
  const auto& u1 = s.levels[1].surfaceDisplacement;
  const auto& u2 = s.levels[2].surfaceDisplacement;
  Eigen::Index worst = 0;
  (u1 - u2).rowwise().norm().maxCoeff(&worst);
  Real toFixed = 1e9;
  const Vec3 pw = liver.V.row(worst).transpose();
  for (const Box& b : fixed) {
    const Vec3 q = pw.cwiseMax(b.lo).cwiseMin(b.hi);
    toFixed = std::min(toFixed, (q - pw).norm());
  }
  std::printf(
      "largest level difference at vertex %d (%.4f %.4f %.4f), %.4f m from the fixed "
      "boxes, %.4f m from the poke; |u| there %.4g m\n",
      int(worst), pw(0), pw(1), pw(2), toFixed, (pw - poke).norm(), u2.row(worst).norm());
  std::printf("observed order %.3f error %.4g m relative %.2f%% asymptotic %d within 1%% %d\n",
              s.observedOrder, s.errorEstimate, 100 * s.relativeError, s.asymptotic,
              s.withinOnePercent);
  // The clamp's edge (where the fixed boxes cut the surface) is resolved by the mesh: the fixed
  // node set differs between levels there and the displacement gradient is singular along it.
  // The same analysis without the surface vertices within 1 cm of the fixed boxes:
  ConvergenceStudy away = s;
  std::vector<char> include(size_t(liver.numVertices()), 1);
  for (int i = 0; i < liver.numVertices(); ++i)
    for (const Box& b : fixed) {
      const Vec3 p = liver.V.row(i).transpose();
      if ((p.cwiseMax(b.lo).cwiseMin(b.hi) - p).norm() < 0.01) include[size_t(i)] = 0;
    }
  richardson(away, include);
  std::printf(
      "away from the clamp edge: observed order %.3f error %.4g m relative %.2f%% "
      "asymptotic %d within 1%% %d\n",
      away.observedOrder, away.errorEstimate, 100 * away.relativeError, away.asymptotic,
      away.withinOnePercent);
  return 0;
}
