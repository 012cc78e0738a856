// readMesh and readMeshFromMemory: dispatch on the file extension.
#include <deform/geometry/mesh_io.h>

#include "mesh_io_util.h"

namespace deform {
namespace {

enum class MeshFormat { Obj, Stl, Off, Ply, Vtk, Msh };

MeshFormat formatOf(const std::string& name) {
  const std::string ext = io::lowerExtension(name);
  if (ext == ".obj") return MeshFormat::Obj;
  if (ext == ".stl") return MeshFormat::Stl;
  if (ext == ".off") return MeshFormat::Off;
  if (ext == ".ply") return MeshFormat::Ply;
  if (ext == ".vtk") return MeshFormat::Vtk;
  if (ext == ".msh") return MeshFormat::Msh;
  throw InputError(name, "",
                   "unknown mesh extension '" + ext + "' (expected .obj .stl .off .ply .vtk .msh)");
}

LoadedMesh surfaceOnly(SurfaceMesh&& s) {
  LoadedMesh m;
  m.surface = std::move(s);
  return m;
}

LoadedMesh readAs(MeshFormat format, std::string_view data, const std::string& name) {
  switch (format) {
    case MeshFormat::Obj:
      return surfaceOnly(io::readObjData(data, name));
    case MeshFormat::Stl:
      return surfaceOnly(io::readStlData(data, name));
    case MeshFormat::Off:
      return surfaceOnly(io::readOffData(data, name));
    case MeshFormat::Ply:
      return surfaceOnly(io::readPlyData(data, name));
    case MeshFormat::Vtk:
      return io::readVtkData(data, name);
    case MeshFormat::Msh:
      return io::readMshData(data, name);
  }
  throw InputError(name, "", "unknown mesh format");
}

}  // namespace

LoadedMesh readMesh(const std::string& path) {
  const MeshFormat format = formatOf(path);  // refuse an unknown extension before opening
  return readAs(format, io::readWholeFile(path), path);
}

LoadedMesh readMeshFromMemory(const std::string& data, const std::string& name) {
  return readAs(formatOf(name), data, name);
}

}  // namespace deform
