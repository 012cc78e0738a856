// deformbench SDK: tetrahedralisation of a closed triangle surface with Gmsh (Geuzaine & Remacle,
// "Gmsh: a 3-D finite element mesh generator with built-in pre- and post-processing facilities",
// IJNME 79(11), 2009, doi:10.1002/nme.2579), keeping the surface exactly.
//
// Contract: every input surface vertex is a mesh node with the same index (volume node i ==
// surface vertex i for i < #V); nodes Gmsh adds (interior nodes, and surface nodes from the
// optional edge refinement) are appended after. The boundary of the tets is the input surface
// (or its refinement, which lies on the same flat triangles). Every tet is positively oriented.
//
// Gmsh is a process-wide singleton and can crash or loop on bad input, so the mesher runs in a
// forked child process under a static mutex (one Gmsh session per call, initialised and finalised
// there), returns the mesh through a pipe and is killed (SIGKILL) when it exceeds
// TetMeshOptions::timeoutSeconds. A crash, a timeout or a Gmsh error becomes an InputError
// (source, "", "cannot tetrahedralise: <reason>").
#pragma once

#include <deform/sdk/mesh.h>

#include <algorithm>
#include <string>

namespace deform {

class Cache;

/// A size field graded toward a point, for a mesh that must be fine only where the interaction
/// is (a grasp's held patch, a load): within `radius` of `centre` the target edge is `ratio` x the
/// interior edge length h, beyond it grows by `growth` per unit distance until it reaches h. Every
/// size scales with h, so meshes at h, h / 1.4, h / 2 are refined by those ratios everywhere,
/// near the centre too (what a convergence study needs).
struct MeshGrading {
  Vec3 centre = Vec3::Zero();  ///< m
  Real radius = 0;             ///< m; 0: no grading (uniform size h)
  Real ratio = 1;              ///< size near the centre over h, (0, 1]
  Real growth = 0.3;           ///< m of size per m of distance beyond the radius
  bool active() const { return radius > 0 && ratio < 1; }
  /// The target edge length at x for interior edge length h (h itself when not active).
  Real size(const Vec3& x, Real h) const {
    if (!active()) return h;
    const Real d = std::max<Real>(0, (x - centre).norm() - radius);
    return std::min(h, ratio * h + growth * d);
  }
};

struct TetMeshOptions {
  /// Target interior edge length (m). 0: derived from targetElements and the enclosed volume.
  Real edgeLength = 0;
  /// Target number of tets when edgeLength is 0 (approximate: the surface's own edge lengths
  /// bound the element size near the boundary).
  long long targetElements = 20000;
  /// Split surface edges longer than the edge length (longest-edge bisection) before meshing, so
  /// the elements next to the surface are as fine as the interior. Original vertices keep their
  /// indices; new surface vertices are appended; the geometry (flat triangles) is unchanged.
  bool refineSurface = false;
  /// Finer elements near a point (interior and, with refineSurface, surface edges).
  MeshGrading grading;
  /// Wall-clock limit of the Gmsh child process, s.
  Real timeoutSeconds = 600;
  /// Names the input in error messages (file path or "phantom:NAME").
  std::string source;
  /// Refuse a self-intersecting surface before calling Gmsh (findSelfIntersections in
  /// mesh_check.h; milliseconds), with a message naming the first pair of triangles.
  bool checkSelfIntersections = true;
};

struct TetMeshQuality {
  long long elements = 0;
  long long nodes = 0;
  Real minDihedralDeg = 0;  ///< smallest dihedral angle over all tets, degrees
  Real maxDihedralDeg = 0;  ///< largest dihedral angle, degrees
  /// Worst mean ratio eta = 12 (3V)^{2/3} / sum l_ij^2 (1 for a regular tet, 0 for a flat one).
  Real minMeanRatio = 0;
  long long degenerate = 0;  ///< tets with volume <= 0 after orientation (should be 0)
};

struct TetMeshResult {
  TetMesh mesh;           ///< nodes: input vertices first, then appended nodes
  int inputVertices = 0;  ///< #V of the input surface
  SurfaceMesh boundary;   ///< the (possibly refined) surface that bounds the tets
  Real edgeLength = 0;    ///< the interior target edge length used, m
  TetMeshQuality quality;
  double seconds = 0;  ///< wall time of meshing (including the child process)
};

/// Tetrahedralises a closed, manifold, outward-oriented surface (validate it first) that does
/// not self-intersect (checked unless options.checkSelfIntersections is false). Throws
/// InputError(options.source, "", "cannot tetrahedralise: ...") when it cannot.
TetMeshResult tetrahedralize(const SurfaceMesh& surface, const TetMeshOptions& options = {});

/// The volume of a surface for a model that works on tets (`network = volume` of pbd and
/// massspring): the surface tetrahedralised with about `elements` tets, without surface
/// refinement, so that surface vertex i is node i and the interior nodes follow. Kept in `cache`
/// (entry "tets.surface", keyed by the surface and `elements`), so the models of one organ share
/// one mesh. Throws InputError(source, "", "cannot tetrahedralise: ...") when it cannot.
TetMesh surfaceVolumeCached(const SurfaceMesh& surface, long long elements,
                            const std::string& source, Cache& cache);

/// Quality measures of a tet mesh (tets assumed positively oriented).
TetMeshQuality tetMeshQuality(const TetMesh& mesh);

/// Longest-edge bisection (Rivara) of a closed triangle surface until no edge is longer than
/// maxEdge (m), or with an active grading than grading.size(its midpoint, maxEdge). Kept vertices
/// keep their indices; midpoints are appended. Deterministic.
SurfaceMesh refineSurfaceEdges(const SurfaceMesh& surface, Real maxEdge,
                               const MeshGrading& grading = {});

/// Interior edge length that gives about `elements` tets in the enclosed `volume` (m^3) with
/// Gmsh's Delaunay mesher (calibrated constant, see tet_mesher.cpp).
Real edgeLengthForElements(Real volume, long long elements);

}  // namespace deform
