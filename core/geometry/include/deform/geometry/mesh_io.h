// deformbench SDK: mesh readers and writers. Every reader throws InputError naming the file and
// the place (line or byte offset) on malformed input: truncated data, NaN/Inf coordinates,
// indices out of range, empty meshes. Polygons with more than three corners are fan-triangulated.
#pragma once

#include <deform/sdk/mesh.h>

#include <optional>
#include <string>
#include <vector>

namespace deform {

/// What a mesh file held: always a surface; a tet volume too when the file has tetrahedra
/// (then `surface` is the volume's boundary, indexing the same nodes as `volume->V`).
///
/// Vertices referenced by no face are kept as they are in the file (vertex order is never
/// changed by a reader): validateSurface reports them as UnreferencedVertices, a warning that
/// requireValidSurface accepts, and repairSurface drops them. With tetrahedra, `surface.V` is the
/// whole node list (interior nodes and nodes used by no tet stay unreferenced by `surface.F`), so
/// surface vertex i is volume node i. Surface elements stored beside tetrahedra are ignored.
struct LoadedMesh {
  SurfaceMesh surface;
  std::optional<TetMesh> volume;
  int reorientedTets = 0;  ///< tets read with negative volume, stored with two nodes swapped
  int degenerateTets = 0;  ///< tets with zero volume (kept as read)
};

/// Reads .obj, .stl (ASCII or binary; a binary header need not start with "solid"), .off, .ply
/// (ASCII and binary little/big endian), .vtk (legacy POLYDATA or UNSTRUCTURED_GRID, ASCII or
/// binary) and .msh (Gmsh 2.2 ASCII and legacy Gmsh 1.0; tetrahedra and/or triangles; Gmsh 4
/// and binary .msh are refused with a message saying to re-save as 2.2). Chosen by extension
/// (case-insensitive). Coordinates are returned unscaled, in file units.
LoadedMesh readMesh(const std::string& path);

/// readMesh on a file's contents already in memory: `name` picks the format by its extension and
/// names the input in errors.
LoadedMesh readMeshFromMemory(const std::string& data, const std::string& name);

SurfaceMesh readObj(const std::string& path);
SurfaceMesh readStl(const std::string& path);
SurfaceMesh readOff(const std::string& path);
SurfaceMesh readPly(const std::string& path);
LoadedMesh readVtk(const std::string& path);
LoadedMesh readMsh(const std::string& path);

/// Writers. Throw InputError (file, "", reason) when the file cannot be written. Files are
/// written atomically (temporary file + rename).
void writeObj(const std::string& path, const SurfaceMesh& mesh);
void writeOff(const std::string& path, const SurfaceMesh& mesh);
void writeStl(const std::string& path, const SurfaceMesh& mesh);  ///< binary STL
/// VTK XML PolyData (.vtp), ASCII, with optional per-vertex scalar fields (name, #V values).
void writeVtp(const std::string& path, const SurfaceMesh& mesh,
              const std::vector<std::pair<std::string, VecX>>& pointScalars = {});
/// VTK XML UnstructuredGrid (.vtu) of tetrahedra.
void writeVtu(const std::string& path, const TetMesh& mesh,
              const std::vector<std::pair<std::string, VecX>>& pointScalars = {});
/// Gmsh 2.2 ASCII with tetrahedra.
void writeMsh(const std::string& path, const TetMesh& mesh);

/// A ParaView .pvd collection: (time, file relative to the .pvd) pairs.
void writePvd(const std::string& path, const std::vector<std::pair<Real, std::string>>& series);

}  // namespace deform
