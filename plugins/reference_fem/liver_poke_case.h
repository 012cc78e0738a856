// The liver-poke problem of scenes/liver_poke.json in the reference FEM's own terms, for the
// programs and tests that study the solver on the liver phantom without the harness
// (converge_liver, diagnose_newton, the quadratic-element Richardson test): the phantom's back
// and underside held by the scene's two boxes, gravity, and a 2 N downward push spread over a
// 3 cm patch around the surface vertex nearest the scene's poke point.
#pragma once

#include "fem_solver.h"

#include <deform/sdk/mesh.h>

#include <array>

namespace deform::reference_fem {

/// The scene's fixed boxes (m): the phantom's back and its underside.
inline std::array<Box, 2> liverPokeFixedBoxes() {
  return {Box{Vec3(-0.11, -0.08, -0.05), Vec3(0.11, -0.035, 0.05)},
          Box{Vec3(-0.11, -0.08, -0.05), Vec3(0.11, 0.03, -0.032)}};
}

/// The scene's poke point (m), on the top of the right lobe.
inline Vec3 liverPokePoint() {
  return Vec3(-0.0394, -0.0024, 0.0422);
}

/// The surface vertex of `liver` nearest the scene's poke point.
inline int liverPokeVertex(const SurfaceMesh& liver) {
  return nearestVertex(liver.V, liverPokePoint());
}

/// The scene's loads on `sys`: its nodes inside the fixed boxes, gravity and, unless pokeVertex
/// is negative (gravity alone), the 2 N push at pokeVertex (a surface vertex = node index).
inline LoadCase liverPokeLoads(const FemSystem& sys, int pokeVertex) {
  const std::array<Box, 2> fixed = liverPokeFixedBoxes();
  LoadCase lc;
  const MatX3& V = sys.rest().V;
  for (int i = 0; i < sys.numNodes(); ++i)
    if (fixed[0].contains(V.row(i).transpose()) || fixed[1].contains(V.row(i).transpose()))
      lc.fixedNodes.push_back(i);
  lc.gravity = Vec3(0, 0, -9.81);
  if (pokeVertex < 0) return lc;
  const PointLoadPatch p = PointLoadSpreader(sys).patch(pokeVertex, 0.03);
  for (size_t k = 0; k < p.nodes.size(); ++k)
    lc.nodeForces.emplace_back(p.nodes[k], p.weights[k] * Vec3(0, 0, -2.0));
  return lc;
}

}  // namespace deform::reference_fem
