// readMesh: dispatch on the file extension.
#include <deform/mesh_io.h>

#include "mesh_io_util.h"

namespace deform {

LoadedMesh readMesh(const std::string& path) {
  const std::string ext = io::lowerExtension(path);
  auto surfaceOnly = [](SurfaceMesh&& s) {
    LoadedMesh m;
    m.surface = std::move(s);
    return m;
  };
  if (ext == ".obj") return surfaceOnly(readObj(path));
  if (ext == ".stl") return surfaceOnly(readStl(path));
  if (ext == ".off") return surfaceOnly(readOff(path));
  if (ext == ".ply") return surfaceOnly(readPly(path));
  if (ext == ".vtk") return readVtk(path);
  if (ext == ".msh") return readMsh(path);
  throw InputError(path, "",
                   "unknown mesh extension '" + ext + "' (expected .obj .stl .off .ply .vtk .msh)");
}

}  // namespace deform
