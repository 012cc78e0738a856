// deformbench phantom: a built-in organ phantom written as a mesh file.
#include "cli.h"

#include <deform/geometry/mesh_io.h>
#include <deform/geometry/phantom.h>

#include <algorithm>
#include <cctype>
#include <iostream>

namespace deform::harness::cli {

namespace {

struct PhantomArgs {
  std::string name, out;
  double resolution = 1.0;
  bool list = false;

  void declare(CLI::App* phantom) {
    phantom->add_option("name", name, "phantom name (see --list)");
    phantom->add_option("--out", out, "output mesh file (.obj, .off, .stl, .vtp)");
    phantom->add_option("--resolution", resolution, "vertex-count scale (1 = default)")
        ->check(positiveValue(false));
    phantom->add_flag("--list", list, "list the phantoms");
  }
};

int cmdPhantom(const PhantomArgs& a) {
  const std::string &name = a.name, &out = a.out;
  if (a.list) {
    for (const std::string& n : phantomNames()) std::cout << phantomDescription(n) << "\n";
    return 0;
  }
  if (name.empty())
    throw InputError("phantom", "", "name a phantom (see deformbench phantom --list)");
  if (out.empty()) throw InputError("phantom", "", "--out FILE is required");
  const SurfaceMesh mesh = makePhantom(name, a.resolution);
  std::string ext = fs::path(out).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  if (ext == ".obj") {
    writeObj(out, mesh);
  } else if (ext == ".off") {
    writeOff(out, mesh);
  } else if (ext == ".stl") {
    writeStl(out, mesh);
  } else if (ext == ".vtp") {
    writeVtp(out, mesh);
  } else {
    throw InputError(out, "", "unknown extension '" + ext + "' (use .obj, .off, .stl or .vtp)");
  }
  std::cout << "phantom:" << name << ": " << mesh.numVertices() << " vertices, " << mesh.numFaces()
            << " triangles -> " << out << "\n";
  return 0;
}

}  // namespace

Verb addPhantom(CLI::App& app) {
  return makeVerb<PhantomArgs>(app, "phantom", "write a built-in organ phantom mesh", cmdPhantom);
}

}  // namespace deform::harness::cli
