// deformbench SDK: an organ surface minus a union of axis-aligned boxes, as a closed triangle
// surface that a volume mesher can fill, so that a tet mesh conforms to a fixed region.
//
// Why: a fixed region "pins every model node inside it" (scene format). A mesh whose elements cross
// the box faces pins a node set that changes with the mesh, so the Dirichlet boundary moves by
// O(h) between refinements and a convergence study measures where each mesh puts the clamp edge.
// The pinned material inside the boxes does not move, so the solid that can deform is the organ
// minus the boxes, Omega' = Omega \ (B_1 u ... u B_m), clamped (u = 0) on the caps
// dOmega' n (B_1 u ... u B_m) and free on the rest of its boundary. Meshing Omega' makes the
// clamped boundary exact at every refinement.
//
// The boolean is CGAL's exact corefinement (Polygon Mesh Processing, corefine_and_compute_
// difference on the exact-predicates-exact-constructions kernel; Loriot, Tournois & Yaz, CGAL
// 5.5 manual, "Polygon Mesh Processing: Corefinement and Boolean Operations"); the caps are
// then remeshed (isotropic remeshing, Botsch & Kobbelt, "A remeshing approach to multiresolution
// modeling", SGP 2004) so that no cap triangle is a sliver, with the cut polylines, the box edges
// and every vertex of the organ part held fixed.
#pragma once

#include <deform/sdk/mesh.h>

#include <string>
#include <vector>

namespace deform {

struct BoxClipOptions {
  /// Target edge length of the cap triangles (m). 0: the mean edge length of the input surface.
  Real capEdgeLength = 0;
  /// A vertex closer to a box face plane than snapFraction x its shortest incident edge (and
  /// over that face, within the same margin) is first moved onto the plane, so that the cut does
  /// not pass a hair's breadth from it and leave sliver triangles (and sliver tets) behind. It
  /// then lies on the closed box: pinned. 0: no snapping, every outside vertex kept exactly.
  /// 0.3 (was 0.05): a vertex left 0.05 to 0.3 of an edge off a plane leaves a cut segment that
  /// short, so the cap triangles on it (which the remeshing cannot fix: the cut points are held)
  /// had angles down to 0.04 deg and the tets on them dihedral angles down to 0.04 deg (liver
  /// phantom, scenes/liver_grasp_lift.json); with 0.3 the clipped meshes are about as good as
  /// the whole organ's. The moves depend on the input surface only, not on the tet size.
  Real snapFraction = 0.3;
  /// Names the input in error messages (file path or "phantom:NAME").
  std::string source;
};

struct BoxClipResult {
  /// Closed, manifold, outward surface of the organ minus the boxes. Vertex order: the kept input
  /// vertices first, in input order (so inputToClipped is increasing where >= 0), then the new
  /// vertices (cut points on box faces, cap vertices).
  SurfaceMesh surface;
  /// Per input vertex: its index in `surface` (same coordinates, bit for bit, unless snapped onto
  /// a box plane), or -1 when the vertex is not on the clipped surface (inside the union of the
  /// boxes).
  std::vector<int> inputToClipped;
  /// Per triangle of `surface`: 1 on a box face (a cap: pinned), 0 part of the organ's surface.
  std::vector<char> capFace;
  int boxesCut = 0;      ///< boxes that removed some volume (the others were no-ops)
  int removedInput = 0;  ///< input vertices with inputToClipped == -1
  int snappedInput = 0;  ///< input vertices moved onto a box plane (BoxClipOptions::snapFraction)
};

/// The organ surface (closed, manifold, outward; validated) minus the union of the boxes.
/// Every cap vertex lies exactly (bit for bit) on its box face plane(s); vertices of the input
/// outside the closed boxes are kept exactly, except those snapped onto a plane (see
/// BoxClipOptions::snapFraction), which then lie on a box. Boxes that do not overlap the organ are
/// skipped; a box with zero extent along an axis removes nothing. Overlapping boxes are fine. A box
/// strictly inside the organ leaves a cavity (a second closed component). Throws
/// InputError(options.source, "fixed boxes", ...) when the boxes contain the whole organ, or when
/// the boolean operation fails. Deterministic: the same input gives the same output bit for bit
/// in any process, whatever it allocated before (the corefinement's output, whose order follows
/// heap addresses, is put in a canonical order with exactly rounded coordinates before the caps
/// are remeshed).
BoxClipResult clipSurfaceByBoxes(const SurfaceMesh& surface, const std::vector<Box>& boxes,
                                 const BoxClipOptions& options = {});

/// Per triangle of (V, F): 1 when its three vertices lie exactly on one face plane of one box
/// (x_k = lo_k or x_k = hi_k, compared bit for bit) within that box: a cap of
/// clipSurfaceByBoxes, or a refinement of one; 0 otherwise (the organ's own surface). Does not
/// need CGAL.
std::vector<char> facesOnBoxFaces(const MatX3& V, const MatX3i& F, const std::vector<Box>& boxes);

}  // namespace deform
