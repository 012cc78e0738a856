// deformbench SDK: surface-mesh validation and repair. A model needs a closed, manifold,
// consistently outward-oriented, single-component surface with no degenerate triangles and no
// duplicate vertices. validate() lists every defect; requireValid() refuses the first one with
// a message naming the file; repair() fixes what can be fixed and says what it changed.
#pragma once

#include <deform/sdk/mesh.h>

#include <array>
#include <string>
#include <vector>

namespace deform {

enum class MeshDefect {
  Empty,                    ///< no vertices or no triangles
  NonFinite,                ///< NaN or Inf coordinate
  IndexOutOfRange,          ///< a triangle names a vertex that does not exist
  DuplicateVertices,        ///< coincident vertices (within tol::kRelativeWeld of the diagonal)
  DegenerateTriangles,      ///< zero area or repeated index
  BoundaryEdges,            ///< edges used by one triangle (holes)
  NonManifoldEdges,         ///< edges used by more than two triangles
  NonManifoldVertices,      ///< vertices whose triangle fan is not a single disc
  InconsistentOrientation,  ///< an edge traversed in the same direction by both its triangles
  InwardOrientation,        ///< closed and consistent but negative signed volume
  MultipleComponents,       ///< more than one connected component
  UnreferencedVertices      ///< vertices used by no triangle (a warning: readers keep them,
                            ///< requireValidSurface accepts them, repairSurface drops them)
};

/// True for defects that do not make a surface unusable (only UnreferencedVertices).
bool isWarning(MeshDefect d);

struct MeshIssue {
  MeshDefect defect;
  int count;            ///< how many edges/vertices/triangles/components are affected
  std::string message;  ///< e.g. "14 boundary edges (holes)"
};

struct MeshReport {
  std::vector<MeshIssue> issues;  ///< empty when the mesh is valid
  bool ok() const { return issues.empty(); }
  bool has(MeshDefect d) const;
  /// No issue other than warnings (see isWarning): what requireValidSurface accepts.
  bool usable() const;
};

/// Checks every defect above (UnreferencedVertices included). Issues are listed in the enum's
/// order, which is also their priority. Geometric checks (duplicates, zero area, volume sign)
/// are skipped when a coordinate is not finite; topological checks use only the triangles whose
/// indices are in range and distinct. Components are edge-connected. The inward check needs a
/// closed, edge-manifold, consistently oriented surface.
MeshReport validateSurface(const SurfaceMesh& mesh);

/// Throws InputError(file, "", first defect's message) unless the mesh is valid; warnings
/// (UnreferencedVertices) are accepted.
void requireValidSurface(const SurfaceMesh& mesh, const std::string& file);

struct RepairReport {
  int weldedVertices = 0;
  int droppedDegenerate = 0;
  int droppedComponents = 0;
  int flippedTriangles = 0;
  int droppedUnreferenced = 0;
  bool reversedWhole = false;         ///< every triangle flipped because the volume was negative
  int droppedInvalid = 0;             ///< triangles with an index out of range or a NaN/Inf corner
  int droppedDuplicateTriangles = 0;  ///< triangles on the same three vertices as an earlier one
  int droppedComponentTriangles = 0;  ///< triangles in the dropped components
  std::vector<std::string> lines() const;  ///< one human-readable line per change made
};

/// Welds duplicates, drops degenerate triangles, keeps the largest component, orients
/// consistently and outward, drops unreferenced vertices. Holes and non-manifold edges are not
/// repaired: validate afterwards. The vertex order of kept vertices is preserved.
/// In order: drop triangles with an out-of-range index or a non-finite corner; weld vertices
/// within tol::kRelativeWeld * diagonal onto the first-seen one (hash grid); drop triangles with
/// a repeated index or zero area, then repeated triangles (same vertex set, first kept); keep the
/// edge-connected component with the most triangles (ties: the one met first); orient by BFS
/// across two-triangle edges, then reverse all if the signed volume is negative (reversedWhole
/// is reported when more than half of the triangles end up reversed; flippedTriangles counts the
/// others that changed); drop unreferenced vertices.
RepairReport repairSurface(SurfaceMesh& mesh);

/// Self-intersection test of a triangle surface: pairs of triangles whose relative interiors
/// cross. Touching (a shared vertex or edge, a vertex resting on another triangle, two faces
/// lying flat against each other without overlapping area) is not a self-intersection; two
/// coplanar triangles overlapping with positive area (including a neighbour folded flat onto
/// its neighbour across their shared edge) is. Broadphase: a uniform grid over the triangles'
/// bounding boxes (cell about the mean triangle size), each candidate pair tested once in the
/// grid cell holding the low corner of the two boxes' overlap. Narrowphase, in the spirit of
/// Moller ("A fast triangle-triangle intersection test", JGT 2(2), 1997): the signed distances
/// of each triangle's corners to the other's plane (a corner within 1e-9 of the pair's longest
/// edge counts as on the plane); both triangles must have corners strictly on both sides, then
/// the two intervals cut on the planes' common line must overlap by more than that tolerance.
/// Neighbours are decided by their shared indices: one shared vertex -> the opposite edge of
/// either triangle must pierce the other's interior; one shared edge -> only a flat fold (the
/// opposite corner in the other's plane, on the same side of the edge) counts. Coplanar pairs
/// are tested in 2-D (proper edge crossings, a corner or the centroid strictly inside, or for
/// a shared vertex overlapping angular sectors). Triangles with an out-of-range or repeated
/// index, a non-finite corner or zero area are skipped (validateSurface reports those).
/// Deterministic; pairs are reported with first < second, sorted.
struct SelfIntersectionReport {
  long long pairs = 0;                     ///< number of intersecting triangle pairs
  std::vector<std::array<int, 2>> listed;  ///< the first (sorted) pairs, at most maxListed
  long long candidates = 0;                ///< box-overlapping pairs the narrowphase tested
  bool ok() const { return pairs == 0; }
  /// "37 pairs of self-intersecting triangles (first: 120 and 4411)"; "" when ok().
  std::string message() const;
};

SelfIntersectionReport findSelfIntersections(const SurfaceMesh& mesh, int maxListed = 100);

/// Per vertex of a surface with triangles F: held, or on a triangle with a held vertex (the held
/// region and its edge, where a fold spans the strip). `held` has one entry per vertex.
std::vector<char> heldRegionAndEdge(const MatX3i& F, const std::vector<char>& held);

/// The intersecting pairs of `moved`, split into those with a triangle touching a vertex marked
/// in `nearHeld` (heldRegionAndEdge: a fold at the edge of a clamp or a grasp, rigid regions
/// without contact) and the others.
struct SelfIntersectionCount {
  long long free = 0, atHeld = 0;
};
SelfIntersectionCount countSelfIntersections(const SurfaceMesh& moved,
                                             const std::vector<char>& nearHeld);

/// What untangleSelfIntersections() did.
struct UntangleReport {
  long long pairsBefore = 0;  ///< intersecting triangle pairs found first
  long long pairsAfter = 0;   ///< left at the end (== pairsBefore when it gave up: mesh unchanged)
  int movedVertices = 0;      ///< vertices whose position changed
  Real maxMove = 0;           ///< m, the largest vertex displacement
  int rounds = 0;             ///< smoothing rounds run
  bool ok() const { return pairsAfter == 0; }
  /// One line per change ("untangled 7 pairs of self-intersecting triangles by smoothing 31
  /// vertices (largest move 0.41 mm)") or why it gave up; empty when there was nothing to do.
  std::vector<std::string> lines() const;
};

/// Local repair of small self-intersections (folds and tangles of a few triangles, as scanned
/// or smoothed organ surfaces have): the vertices of the intersecting triangles, grown by a few
/// rings of neighbours, are moved by umbrella (uniform Laplacian) smoothing,
/// x_i <- x_i + 1/2 (mean of its neighbours - x_i), three Jacobi sweeps a round, the region
/// growing by a ring every third round and by the vertices of pairs still intersecting, until
/// findSelfIntersections() finds none (at most maxRounds rounds). Connectivity and vertex order
/// are untouched. A tangle that needs a vertex moved farther than maxMoveEdges mean edge
/// lengths, a region of more than maxRegionFraction of the vertices, or more than maxRounds
/// rounds is not a local defect: the mesh is restored and the report says so
/// (pairsAfter == pairsBefore).
UntangleReport untangleSelfIntersections(SurfaceMesh& mesh, int maxRounds = 24,
                                         Real maxMoveEdges = 4, Real maxRegionFraction = 0.1);

/// Throws InputError(file, "", message() + what to do) when the surface self-intersects.
/// Models that build a volume (tetrahedralize() calls it before Gmsh) need it.
void requireNoSelfIntersections(const SurfaceMesh& mesh, const std::string& file);

}  // namespace deform
