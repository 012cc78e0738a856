// Gmsh's Delaunay tetrahedral mesher behind gmsh_mesher.h, in a shared object of its own.
#include "gmsh_mesher.h"

#include <gmsh.h>

#include <algorithm>
#include <unordered_map>
#include <utility>
#include <vector>

namespace deform {

namespace {

std::string gmshLastError() {
  std::string e;
  try {
    gmsh::logger::getLastError(e);
  } catch (...) {
  }
  return e;
}

GmshOutput runGmsh(const SurfaceMesh& s, Real h, const GmshSize& size) {
  GmshOutput out;
  gmsh::initialize(0, nullptr, false);
  try {
    gmsh::option::setNumber("General.Terminal", 0);
    gmsh::option::setNumber("General.Verbosity", 1);
    gmsh::option::setNumber("General.NumThreads", 1);
    gmsh::logger::start();
    gmsh::model::add("deformbench");
    gmsh::model::addDiscreteEntity(2, 1);
    const size_t n = size_t(s.numVertices());
    std::vector<std::size_t> tags(n);
    std::vector<double> xyz(3 * n);
    for (size_t i = 0; i < n; ++i) {
      tags[i] = i + 1;
      for (int k = 0; k < 3; ++k) xyz[3 * i + k] = s.V(Eigen::Index(i), k);
    }
    gmsh::model::mesh::addNodes(2, 1, tags, xyz);
    std::vector<std::size_t> tri(3 * size_t(s.numFaces()));
    for (Eigen::Index f = 0; f < s.F.rows(); ++f)
      for (int k = 0; k < 3; ++k) tri[3 * size_t(f) + k] = std::size_t(s.F(f, k)) + 1;
    gmsh::model::mesh::addElementsByType(1, 2, {}, tri);
    const int loop = gmsh::model::geo::addSurfaceLoop({1});
    gmsh::model::geo::addVolume({loop});
    gmsh::model::geo::synchronize();
    // Size h inside (or the given field below h); the discrete surface has no
    // parametrisation, so Gmsh keeps its triangles as they are (no boundary remeshing).
    gmsh::option::setNumber("Mesh.MeshSizeMax", h);
    if (size)
      gmsh::model::mesh::setSizeCallback(
          [&size](int, int, double x, double y, double z) { return double(size(Vec3(x, y, z))); });
    gmsh::option::setNumber("Mesh.MeshSizeMin", 0.0);
    gmsh::option::setNumber("Mesh.MeshSizeExtendFromBoundary", 0);
    gmsh::option::setNumber("Mesh.MeshSizeFromPoints", 0);
    gmsh::option::setNumber("Mesh.MeshSizeFromCurvature", 0);
    gmsh::option::setNumber("Mesh.Algorithm3D", 1);  // Delaunay with boundary recovery
    gmsh::option::setNumber("Mesh.Optimize", 1);
    gmsh::option::setNumber("Mesh.OptimizeNetgen", 0);
    gmsh::model::mesh::generate(3);

    std::vector<std::size_t> nodeTags;
    std::vector<double> coord, param;
    gmsh::model::mesh::getNodes(nodeTags, coord, param, -1, -1, false, false);
    std::vector<std::size_t> elemTags, elemNodes;
    gmsh::model::mesh::getElementsByType(4, elemTags, elemNodes, -1);
    if (elemTags.empty()) {
      const std::string e = gmshLastError();
      out.error = e.empty() ? "Gmsh produced no tetrahedra" : e;
    } else {
      // Map Gmsh node tags to indices: input vertices are tags 1..n and must keep index i.
      std::unordered_map<std::size_t, int> index;
      out.V.resize(Eigen::Index(nodeTags.size()), 3);
      int next = int(n);
      std::vector<std::pair<std::size_t, size_t>> extra;
      for (size_t i = 0; i < nodeTags.size(); ++i) {
        const std::size_t t = nodeTags[i];
        if (t >= 1 && t <= n) {
          index[t] = int(t - 1);
        } else {
          extra.emplace_back(t, i);
        }
      }
      std::sort(extra.begin(), extra.end());  // deterministic order of appended nodes
      MatX3 V(Eigen::Index(n + extra.size()), 3);
      V.topRows(Eigen::Index(n)) = s.V;
      for (size_t i = 0; i < nodeTags.size(); ++i) {
        const std::size_t t = nodeTags[i];
        if (t >= 1 && t <= n) {
          for (int k = 0; k < 3; ++k) {
            if (coord[3 * i + k] != s.V(Eigen::Index(t - 1), k)) {
              out.error = "Gmsh moved input vertex " + std::to_string(t - 1);
            }
          }
        }
      }
      for (const auto& [t, i] : extra) {
        index[t] = next;
        V.row(next++) << coord[3 * i], coord[3 * i + 1], coord[3 * i + 2];
      }
      out.V = V;
      out.T.resize(Eigen::Index(elemTags.size()), 4);
      for (size_t e = 0; e < elemTags.size(); ++e) {
        for (int k = 0; k < 4; ++k) {
          auto it = index.find(elemNodes[4 * e + k]);
          if (it == index.end()) {
            out.error = "Gmsh returned a tetrahedron with an unknown node";
            break;
          }
          out.T(Eigen::Index(e), k) = it->second;
        }
      }
    }
  } catch (const std::exception& e) {
    const std::string last = gmshLastError();
    out.error = last.empty() ? e.what() : last;
  } catch (...) {
    const std::string last = gmshLastError();
    out.error = last.empty() ? "Gmsh failed" : last;
  }
  try {
    gmsh::logger::stop();
    gmsh::finalize();
  } catch (...) {
  }
  return out;
}

}  // namespace

}  // namespace deform

extern "C" __attribute__((visibility("default"))) void deform_gmsh_tetrahedralize_sized(
    const deform::SurfaceMesh& s, deform::Real h, const deform::GmshSize& size,
    deform::GmshOutput& out) {
  out = deform::runGmsh(s, h, size);
}
