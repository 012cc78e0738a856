// particle_bem: data for the paper's two tables (Zhu, Gu & Zhou 2010, §6), as JSON with the
// paper's own figures beside ours.
//
// bem-timing (Table 1): the guided model on the liver phantom with 284, 508, 784, 876 and 1144
// coarse vertices (= surface particles; the paper's "point number"), per-step medians of the
// three phases (surface computation U = M P, position correction, surface interpolation) and
// their total, plus the precomputation time and the size of M.
// Load: a grasp of the coarse nodes within 1 cm of the liver's top point lifted 1 cm over the
// run and a 0.5 N point force beside it; the bottom 15% of the liver (in z) is fixed.
//
// bem-accuracy (Table 2): coarse surfaces of 284 and 608 vertices against the paper's finer
// surfaces (256, 394, 574 and 506, 1000, 1586 vertices), all decimated from the liver phantom;
// R from bemLossRatio (bem_accuracy.h) under a Gaussian traction patch (radius 0.15 x the
// largest extent, 500 Pa peak, downwards) on the top of the liver, bottom 15% fixed.
#pragma once

#include <nlohmann/json.hpp>

namespace deform::particle_bem {

struct TableOptions {
  int steps = 300;           ///< timed steps per model (bem-timing)
  int interiorPoints = 300;  ///< interior physics points (bem-timing)
  bool quick = false;        ///< smaller meshes, for smoke tests
};

nlohmann::json bemTimingTable(const TableOptions& o = {});
nlohmann::json bemAccuracyTable(const TableOptions& o = {});

}  // namespace deform::particle_bem
