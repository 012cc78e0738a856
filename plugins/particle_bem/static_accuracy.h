// particle_bem: the paper's static accuracy measure (Zhu, Gu & Zhou 2010, Table 2), which the
// harness's bem-accuracy table asks for through the plugin's "static_accuracy" measure
// (ModelInfo::measures, registry.h).
//
// R = sum|u^o - u^imp| / sum|u^o| over the fine vertices, from bemLossRatio (bem_accuracy.h):
// both surfaces cut along the fixed box and decimated from `organ`, a Gaussian traction patch
// (radius 0.15 x the largest extent, 500 Pa peak, downwards) around the organ's top vertex
// integrated over each mesh, the bottom 15% fixed, E = 5500 Pa, nu = 0.45, exact clamp with the
// singular reaction, gradient transfer; one assembly and one solve per mesh.
#pragma once

#include <deform/sdk/mesh.h>

#include <nlohmann/json.hpp>

#include <filesystem>
#include <utility>
#include <vector>

namespace deform::particle_bem {

/// The organ's top vertex, where the measure's load patch is centred: the first row of V with
/// the largest z.
int topVertex(const MatX3& V);

/// One object per (coarse, fine) pair: coarse_vertices / fine_vertices (the requested counts),
/// coarse_surface_vertices / fine_surface_vertices (the solved, conforming meshes), vertex_ratio
/// (fine / coarse solved), loss_ratio, displacement_ratio, seconds, cached. Each row is cached
/// in the precomputation cache (cacheDir empty: no caching) keyed by the organ mesh, the counts
/// and the case.
nlohmann::json bemStaticAccuracy(const SurfaceMesh& organ,
                                 const std::vector<std::pair<int, int>>& rows,
                                 const std::filesystem::path& cacheDir);

/// The "static_accuracy" measure: request {"organ": "phantom:NAME", "rows": [[coarse, fine],
/// ...], "cache_dir": "..."} (cache_dir absent or empty: no caching); reply {"rows": [...]}
/// (bemStaticAccuracy). Bad input throws InputError.
nlohmann::json staticAccuracyMeasure(const nlohmann::json& request);

}  // namespace deform::particle_bem
