// deformbench core: the optional back ends of the core libraries (Gmsh for tetrahedral meshing,
// Bullet for the contact world, ODE for instrument dynamics) are shared objects of their own,
// loaded on first use, so that a process that never meshes, collides or moves instruments never
// maps those libraries (and their dependencies: OpenCASCADE, FLTK, ...). Plugins do not call this;
// the core's own classes (tetrahedralize, ContactWorld, InstrumentWorld) do.
#pragma once

#include <string>

namespace deform {

/// Address of `symbol` in the core component `library` (a file name such as
/// "libdeform_gmsh.so"), looked up in the folder of the SDK library itself (the build tree's or
/// the install tree's lib folder). The library is opened once per process (RTLD_LOCAL, so that
/// its dependencies' symbols never bind to a plugin's) and stays loaded. Throws UnsupportedError
/// "<what> needs <library>: <why>" when the file is missing or lacks the symbol.
void* coreComponentSymbol(const std::string& library, const char* symbol, const std::string& what);

}  // namespace deform
