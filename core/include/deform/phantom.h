// deformbench SDK: built-in organ-like phantoms, so every command runs on a fresh machine with
// no data files. Each phantom is closed, manifold, outward oriented, one component, with no
// degenerate triangles, at a realistic size in metres. Deterministic: same name and resolution,
// same mesh, bit for bit.
#pragma once

#include <deform/mesh.h>

#include <string>
#include <vector>

namespace deform {

/// Names: liver, gallbladder, stomach, intestine, cube, sphere, steak, beam.
std::vector<std::string> phantomNames();

/// One line per phantom: what it is, its size and its default vertex count.
std::string phantomDescription(const std::string& name);

/// Builds a phantom. resolution scales the vertex count roughly linearly (1.0 = the default
/// count, near the papers': liver ~8100, gallbladder ~1500, stomach ~3300, intestine ~900).
/// Throws InputError("phantom:NAME", "", ...) for an unknown name or resolution <= 0.
SurfaceMesh makePhantom(const std::string& name, Real resolution = 1.0);

}  // namespace deform
