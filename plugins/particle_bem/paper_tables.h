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

#include <deform/mesh.h>

#include <nlohmann/json.hpp>

#include <filesystem>
#include <utility>
#include <vector>

namespace deform::particle_bem {

struct TableOptions {
  int steps = 300;           ///< timed steps per model (bem-timing)
  int interiorPoints = 300;  ///< interior physics points (bem-timing)
  bool quick = false;        ///< smaller meshes, for smoke tests
};

nlohmann::json bemTimingTable(const TableOptions& o = {});
nlohmann::json bemAccuracyTable(const TableOptions& o = {});

/// The paper's static measure alone (Table 2's R = sum|u^o - u^imp| / sum|u^o| over the fine
/// vertices): bemAccuracyTable's headline `loss_ratio` (both surfaces cut along the fixed box
/// and decimated from `organ`, the Gaussian field integrated over each mesh, exact clamp with
/// the singular reaction, gradient transfer; LossRatioCase::variants = false, so one assembly
/// and one solve per mesh instead of the table's dozen). The load case is built from the
/// organ as bemAccuracyTable builds it from the liver (centre at the top vertex, radius 0.15 x
/// the largest extent, 500 Pa down, bottom 15% fixed, E = 5500 Pa, nu = 0.45), so for the
/// liver phantom each row's `loss_ratio` equals the table's. One object per (coarse, fine)
/// pair: coarse_vertices / fine_vertices (the requested counts), coarse_surface_vertices /
/// fine_surface_vertices (the solved, conforming meshes), vertex_ratio (fine / coarse solved),
/// loss_ratio, displacement_ratio, seconds, cached. Each row is cached in the precomputation
/// cache (cacheDir empty: no caching) keyed by the organ mesh, the counts and the case.
nlohmann::json bemStaticAccuracy(const SurfaceMesh& organ,
                                 const std::vector<std::pair<int, int>>& rows,
                                 const std::filesystem::path& cacheDir);

}  // namespace deform::particle_bem
