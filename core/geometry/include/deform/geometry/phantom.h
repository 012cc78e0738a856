// deformbench SDK: built-in organ-like phantoms, so every command runs on a fresh machine with
// no data files. Each phantom is closed, manifold, outward oriented, one component, with no
// degenerate triangles, at a realistic size in metres. Deterministic: same name and resolution,
// same mesh, bit for bit.
#pragma once

#include <deform/sdk/mesh.h>

#include <string>
#include <vector>

namespace deform {

/// Names: liver, gallbladder, stomach, intestine, cube, sphere, steak, beam.
///
/// At resolution 1 (bounding-box sizes in m; every organ is centred on its bounding box):
///   liver        8122 V  0.200 x 0.150 x 0.090  wedge: thick right lobe at -x (0.09 m) tapering
///                        to a thin left lobe at +x (~0.02 m), domed top (+z), shallow concave
///                        underside, concave posterior (-y) side; volume 0.98 L.
///   gallbladder  1472 V  0.086 x 0.042 x 0.029  pear, 0.090 m along its gently bent axis in the
///                        xy plane: fundus (radius 17 mm) at -x, neck (5.5 mm) at +x; 38 mL.
///   stomach      3362 V  0.170 x 0.164 x 0.059  J-shaped bag in the xy plane, 0.245 m along its
///                        curve: fundus at +y (half-width 48 mm), body running down, antrum
///                        turning 150 degrees to the pylorus (11 mm); flattened in z; 0.53 L.
///   intestine     882 V  0.116 x 0.133 x 0.027  tube of radius 13.5 mm, 0.184 m along an S-curve
///                        in the xy plane (two 45 mm-radius arcs of 100 degrees), rounded ends.
///   cube          866 V  0.100 x 0.100 x 0.100  centred, 12 x 12 grid of split squares a face.
///   sphere       1442 V  radius 0.05, centred, geodesic-like (valence 5 at 12 points,
///                        no latitude-longitude pole slivers).
///   steak         706 V  0.120 x 0.118 x 0.021  slab, rounded and slightly irregular outline,
///                        uneven top; 16 x 16 x 3 lattice.
///   beam          674 V  x in [0, 0.1], y and z in [-0.005, 0.005] exactly; 40 x 4 x 4 lattice
///                        of 2.5 mm cubes (cells 10c x c x c; resolution picks c).
/// Organ vertex counts follow the metaballs paper's Table 1 (8128, 1461, 3349, 887); resolution
/// 0.27 gives the ~2.2k-vertex liver of the PBD comparisons. Minimum triangle quality
/// 4 sqrt(3) area / sum of squared edges is >= 0.45 for every phantom and resolution (the unit
/// tests require 0.4; measured worst 0.47, steak at resolution 20).
std::vector<std::string> phantomNames();

/// One line per phantom: what it is, its size and its default vertex count.
std::string phantomDescription(const std::string& name);

/// Builds a phantom. resolution scales the vertex count roughly linearly (1.0 = the default
/// count, near the papers': liver ~8100, gallbladder ~1500, stomach ~3300, intestine ~900).
/// Small resolutions are clamped to the coarsest valid mesh (about 100 to 250 vertices).
/// Throws InputError("phantom:NAME", "", ...) for an unknown name, and
/// InputError("phantom:NAME", "resolution", ...) for a resolution outside (0, 100] or NaN.
SurfaceMesh makePhantom(const std::string& name, Real resolution = 1.0);

}  // namespace deform
