// Loading the organ a scene describes: its surface (a phantom or a mesh file, checked and
// repaired where the scene allows it), tets, material and fixed region.
#include <deform/engine/interaction.h>
#include <deform/engine/scene.h>
#include <deform/geometry/mesh_check.h>
#include <deform/geometry/mesh_io.h>
#include <deform/geometry/phantom.h>
#include <deform/sdk/cache.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

namespace deform {

namespace fs = std::filesystem;

namespace {

/// Drops vertices no triangle uses; returns old -> new index (-1 for dropped).
std::vector<int> compactSurface(SurfaceMesh& mesh) {
  std::vector<int> map(mesh.V.rows(), -1);
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) {
      const int v = mesh.F(f, k);
      if (v >= 0 && v < int(map.size())) map[v] = 0;
    }
  int next = 0;
  for (int& m : map)
    if (m == 0) m = next++;
  if (next == mesh.V.rows()) return map;
  MatX3 V(next, 3);
  for (size_t i = 0; i < map.size(); ++i)
    if (map[i] >= 0) V.row(map[i]) = mesh.V.row(i);
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f)
    for (int k = 0; k < 3; ++k) mesh.F(f, k) = map[mesh.F(f, k)];
  mesh.V = std::move(V);
  return map;
}

bool repairable(const MeshReport& report) {
  for (const auto& issue : report.issues) {
    switch (issue.defect) {
      case MeshDefect::DuplicateVertices:
      case MeshDefect::DegenerateTriangles:
      case MeshDefect::InconsistentOrientation:
      case MeshDefect::InwardOrientation:
      case MeshDefect::MultipleComponents:
      case MeshDefect::UnreferencedVertices:
        break;
      default:
        return false;
    }
  }
  return true;
}

}  // namespace

Organ loadOrgan(const Scene& scene, std::vector<std::string>* repairLog) {
  const OrganSpec& spec = scene.organ;
  const auto log = [&](const std::string& line) {
    if (repairLog) repairLog->push_back(line);
  };
  Organ organ;
  organ.source = spec.mesh;
  organ.material = spec.material;
  organ.fixed = spec.fixed;
  std::string meshName = spec.mesh;
  const bool phantom = spec.mesh.rfind("phantom:", 0) == 0;
  if (phantom) {
    organ.surface = makePhantom(spec.mesh.substr(8), spec.resolution);
  } else {
    if (!fs::exists(spec.mesh))
      throw InputError(scene.file, "/organ/mesh", "mesh file not found: " + spec.mesh);
    LoadedMesh loaded = readMesh(spec.mesh);
    organ.surface = std::move(loaded.surface);
    organ.volume = std::move(loaded.volume);
  }
  if (spec.scale != 1.0) {
    organ.surface.V *= spec.scale;
    if (organ.volume) organ.volume->V *= spec.scale;
  }
  const int inputVertices = organ.surface.numVertices();

  // Listed fixed vertices index the file's vertices; remember where they are so they can be
  // found again after unreferenced vertices are dropped or the mesh is repaired.
  std::vector<Vec3> fixedAt;
  for (size_t i = 0; i < spec.fixed.surfaceVertices.size(); ++i) {
    const int v = spec.fixed.surfaceVertices[i];
    if (v >= inputVertices) {
      throw InputError(scene.file, "/organ/fixed/vertices/" + std::to_string(i),
                       "vertex " + std::to_string(v) + " does not exist (the mesh has " +
                           std::to_string(inputVertices) + " vertices)");
    }
    fixedAt.push_back(organ.surface.V.row(v).transpose());
  }

  const bool facesInRange =
      organ.surface.F.size() == 0 ||
      (organ.surface.F.minCoeff() >= 0 && organ.surface.F.maxCoeff() < organ.surface.V.rows());
  if (facesInRange) {
    const std::vector<int> map = compactSurface(organ.surface);
    const int dropped = inputVertices - organ.surface.numVertices();
    if (dropped > 0) {
      log("dropped " + std::to_string(dropped) +
          " vertices used by no triangle (they would be pinned by no model)");
      for (size_t i = 0; i < spec.fixed.surfaceVertices.size(); ++i) {
        if (map[spec.fixed.surfaceVertices[i]] < 0)
          throw InputError(scene.file, "/organ/fixed/vertices/" + std::to_string(i),
                           "vertex " + std::to_string(spec.fixed.surfaceVertices[i]) +
                               " is used by no triangle");
      }
      if (organ.volume) {
        // Keep "surface vertex i is volume node i": surface nodes first, interior nodes after.
        TetMesh& vol = *organ.volume;
        std::vector<int> volMap(vol.V.rows(), -1);
        for (size_t i = 0; i < map.size(); ++i)
          if (map[i] >= 0 && i < size_t(vol.V.rows())) volMap[i] = map[i];
        int next = organ.surface.numVertices();
        for (int& m : volMap)
          if (m < 0) m = next++;
        MatX3 V(vol.V.rows(), 3);
        for (Eigen::Index i = 0; i < vol.V.rows(); ++i) V.row(volMap[i]) = vol.V.row(i);
        for (Eigen::Index t = 0; t < vol.T.rows(); ++t)
          for (int k = 0; k < 4; ++k) vol.T(t, k) = volMap[vol.T(t, k)];
        vol.V = std::move(V);
      }
    }
  }

  if (spec.repair) {
    const int before = organ.surface.numVertices();
    const MatX3i facesBefore = organ.surface.F;
    const RepairReport rep = repairSurface(organ.surface);
    for (const auto& line : rep.lines()) log(line);
    const bool changed = organ.surface.numVertices() != before ||
                         organ.surface.F.rows() != facesBefore.rows() ||
                         organ.surface.F != facesBefore;
    if (changed && organ.volume) {
      organ.volume.reset();
      log("dropped the tetrahedral volume: the repaired surface no longer matches it");
    }
  }
  const MeshReport report = validateSurface(organ.surface);
  if (!report.ok()) {
    std::string problem = report.issues.front().message;
    if (!spec.repair && repairable(report))
      problem += " (\"repair\": true in the scene's organ would fix this)";
    throw InputError(spec.mesh, "", problem);
  }
  if (spec.repair) {
    // Small folds and tangles (scanned or smoothed organs have them) stop the tet meshers only;
    // untangle them here so that every model gets the same surface.
    const UntangleReport untangle = untangleSelfIntersections(organ.surface);
    for (const auto& line : untangle.lines()) log(line);
    if (untangle.movedVertices > 0 && organ.volume) {
      organ.volume.reset();
      log("dropped the tetrahedral volume: the untangled surface no longer matches it");
    }
  }

  organ.fixed.surfaceVertices.clear();
  for (const Vec3& p : fixedAt)
    organ.fixed.surfaceVertices.push_back(nearestVertex(organ.surface.V, p));
  std::sort(organ.fixed.surfaceVertices.begin(), organ.fixed.surfaceVertices.end());
  organ.fixed.surfaceVertices.erase(
      std::unique(organ.fixed.surfaceVertices.begin(), organ.fixed.surfaceVertices.end()),
      organ.fixed.surfaceVertices.end());
  checkGraspsReachOrgan(scene, organ);
  checkLoadsReachOrgan(scene, organ);
  checkPlatesReachOrgan(scene, organ);
  // A traction whose region holds no surface triangle would load nothing.
  for (size_t i = 0; i < scene.loads.size(); ++i) {
    const LoadSpec& l = scene.loads[i];
    if (l.type == LoadType::Traction && regionPatch(organ.surface, l.region).vertices.empty())
      throw InputError(scene.file, "/loads/" + std::to_string(i) + "/region/box",
                       "no surface triangle of the organ lies inside this box (all three "
                       "vertices inside): the traction would load nothing");
  }
  return organ;
}

void checkPlatesReachOrgan(const Scene& scene, const Organ& organ) {
  for (size_t i = 0; i < scene.plates.size(); ++i)
    if (plateSurfaceVertices(organ.surface.V, scene.plates[i].region).empty())
      throw InputError(scene.file, "/plates/" + std::to_string(i) + "/region/box",
                       "no surface vertex of the organ lies inside this box: the plate would "
                       "hold nothing");
}

}  // namespace deform
