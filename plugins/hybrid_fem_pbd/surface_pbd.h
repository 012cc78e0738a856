// Hybrid FEM+PBD, the fine surface MS by position-based dynamics (paper Sec. 4 and 6.3-6.5):
// stretch constraints C = |p1 - p2| - l on every surface edge (paper Eq. (8)-(9)) and bending
// constraints C = angle(n1, n2) - phi across every interior edge (paper Eq. (10)-(11)), projected
// Gauss-Seidel with the classic per-iteration stiffness. The projections themselves are the
// shared kernels of deform/pbd_kernels.h (the bending kernel evaluates the dihedral angle with
// atan2 and the gradients of Bridson et al. 2003, equivalent to the paper's acos form away from
// flat hinges and finite at them). Control nodes (shared with the coarse volume mesh) have
// inverse mass 0 and take their positions from the FEM solution (paper Step 4).
#pragma once

#include <deform/mesh.h>
#include <deform/pbd_kernels.h>

#include <vector>

namespace deform::hybrid {

struct SurfaceConstraints {
  std::vector<pbd::DistanceConstraint> stretch;  ///< one per unique edge, rest length l (m)
  std::vector<pbd::DihedralConstraint> bending;  ///< one per edge with two triangles, phi (rad)
};

/// Stretch and bending constraints of a triangle surface from its rest positions (restV: #V by 3,
/// F: #F by 3 counter-clockwise). Edges with one triangle (a cut's open boundary) get a stretch
/// constraint only. Degenerate hinges are skipped and counted in *skipped.
SurfaceConstraints buildSurfaceConstraints(const MatX3& restV, const MatX3i& F,
                                           long long* skipped = nullptr);

/// Orders the hinge of edge (a, b) shared by triangles fa and fb as DihedralConstraint expects
/// (p[2] -> p[3] along fa's winding, p[0] / p[1] the wings of fa / fb); restAngle untouched.
/// False when the triangles do not share that edge.
bool orderHinge(const MatX3i& F, int fa, int fb, int a, int b, pbd::DihedralConstraint& h);

/// Indices of the constraints that touch at least one movable particle (w > 0): the only ones
/// worth projecting, each list in greedy-colour order (constraints next to each other rarely
/// share a movable particle; the order is fixed and deterministic).
struct ActiveConstraints {
  std::vector<int> stretch;
  std::vector<int> bending;
  /// Colour c holds stretch[stretchColourStart[c] .. stretchColourStart[c + 1]) (likewise for
  /// bending). The last colour may share movable particles when the 63 colours ran out
  /// (*ColourOverflow): it must then be projected one constraint at a time.
  std::vector<int> stretchColourStart, bendingColourStart;
  bool stretchColourOverflow = false, bendingColourOverflow = false;
};
ActiveConstraints activeConstraints(const SurfaceConstraints& c, const VecX& w);

/// `iterations` Gauss-Seidel sweeps over the active constraints (stretch then bending in each
/// sweep) with classic PBD stiffnesses kStretch, kBending in [0, 1] (converted to per-iteration
/// values, Mueller et al. 2007 Sec. 3.3). p: #V by 3 predicted positions, updated in place;
/// w: #V inverse masses. Returns the number of degenerate projections skipped.
long long projectSurfaceConstraints(MatX3& p, const VecX& w, const SurfaceConstraints& c,
                                    const ActiveConstraints& active, Real kStretch, Real kBending,
                                    int iterations);

}  // namespace deform::hybrid
