// deformbench SDK: surface-mesh validation and repair. A model needs a closed, manifold,
// consistently outward-oriented, single-component surface with no degenerate triangles and no
// duplicate vertices. validate() lists every defect; requireValid() refuses the first one with
// a message naming the file; repair() fixes what can be fixed and says what it changed.
#pragma once

#include <deform/mesh.h>

#include <string>
#include <vector>

namespace deform {

enum class MeshDefect {
  Empty,               ///< no vertices or no triangles
  NonFinite,           ///< NaN or Inf coordinate
  IndexOutOfRange,     ///< a triangle names a vertex that does not exist
  DuplicateVertices,   ///< coincident vertices (within tol::kRelativeWeld of the diagonal)
  DegenerateTriangles, ///< zero area or repeated index
  BoundaryEdges,       ///< edges used by one triangle (holes)
  NonManifoldEdges,    ///< edges used by more than two triangles
  NonManifoldVertices, ///< vertices whose triangle fan is not a single disc
  InconsistentOrientation,  ///< an edge traversed in the same direction by both its triangles
  InwardOrientation,   ///< closed and consistent but negative signed volume
  MultipleComponents,  ///< more than one connected component
  UnreferencedVertices ///< vertices used by no triangle (a warning: dropped by the loader)
};

struct MeshIssue {
  MeshDefect defect;
  int count;            ///< how many edges/vertices/triangles/components are affected
  std::string message;  ///< e.g. "14 boundary edges (holes)"
};

struct MeshReport {
  std::vector<MeshIssue> issues;  ///< empty when the mesh is valid
  bool ok() const { return issues.empty(); }
  bool has(MeshDefect d) const;
};

/// Checks every defect above (UnreferencedVertices included).
MeshReport validateSurface(const SurfaceMesh& mesh);

/// Throws InputError(file, "", first defect's message) unless the mesh is valid.
void requireValidSurface(const SurfaceMesh& mesh, const std::string& file);

struct RepairReport {
  int weldedVertices = 0;
  int droppedDegenerate = 0;
  int droppedComponents = 0;
  int flippedTriangles = 0;
  int droppedUnreferenced = 0;
  bool reversedWhole = false;  ///< every triangle flipped because the volume was negative
  std::vector<std::string> lines() const;  ///< one human-readable line per change made
};

/// Welds duplicates, drops degenerate triangles, keeps the largest component, orients
/// consistently and outward, drops unreferenced vertices. Holes and non-manifold edges are not
/// repaired: validate afterwards. The vertex order of kept vertices is preserved.
RepairReport repairSurface(SurfaceMesh& mesh);

}  // namespace deform
