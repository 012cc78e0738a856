// Tetrahedral meshing's Gmsh back end (internal to the core): tetrahedralize() (tet_mesher.cpp)
// loads it from its own shared object when a model first asks for tets, so that a process that
// never meshes never maps Gmsh (and OpenCASCADE, FLTK and the rest of its dependencies).
#pragma once

#include <deform/sdk/mesh.h>

#include <functional>
#include <string>

namespace deform {

struct GmshOutput {
  MatX3 V;
  MatX4i T;
  std::string error;  // empty on success
};

/// The target edge length (m) at a point; empty: uniform.
using GmshSize = std::function<Real(const Vec3& x)>;

/// The back end's shared object (in the SDK library's folder) and its entry point
/// `void deform_gmsh_tetrahedralize_sized(const SurfaceMesh& s, Real h, const GmshSize& size,
/// GmshOutput& out)`: Gmsh's Delaunay tets of the closed surface s at size h (m) inside, or
/// min(h, size(x)) where size is given, the input vertices first and unmoved; out.error says
/// why not.
inline constexpr const char* kGmshLibrary = "libdeform_gmsh.so";
inline constexpr const char* kGmshEntry = "deform_gmsh_tetrahedralize_sized";
using GmshTetrahedralize = void (*)(const SurfaceMesh& s, Real h, const GmshSize& size,
                                    GmshOutput& out);

}  // namespace deform
