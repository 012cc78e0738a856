// Hybrid FEM+PBD, the fine surface MS by position-based dynamics (paper Sec. 4 and 6.3-6.5):
// stretch constraints C = |p1 - p2| - l on every surface edge (paper Eq. (8)-(9)) and bending
// constraints C = angle(n1, n2) - phi across every interior edge (paper Eq. (10)-(11)), projected
// Gauss-Seidel with the classic per-iteration stiffness. The projections themselves are the
// shared kernels of deform/kernels/pbd_kernels.h (the bending kernel evaluates the dihedral angle
// with atan2 and the gradients of Bridson et al. 2003, equivalent to the paper's acos form away
// from flat hinges and finite at them). Control nodes (shared with the coarse volume mesh) have
// inverse mass 0 and take their positions from the FEM solution (paper Step 4).
#pragma once

#include <deform/kernels/pbd_kernels.h>
#include <deform/sdk/mesh.h>

#include <vector>

namespace deform::hybrid_fem_pbd {

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

/// The inverse masses wd[4] that a bending hinge's projection divides by, from its particles'
/// inverse masses w[4]: wd_k = w_k where the particle moves, and the mean inverse mass of the
/// hinge's movable particles where it does not (a control, fixed or grasped node, w_k = 0).
///
/// Why: the classic projection moves particle k by w_k C g_k / sum_j w_j |g_j|^2, which hands
/// the whole correction to the movable particles. Where only one particle of a hinge moves and
/// its gradient is small (an edge end whose opposite angles are near 90 degrees, or a wing across
/// a long edge), that step is many times the bend. The hinges around a free node between control
/// nodes then pull it to far-apart places, and the sweeps settle far from all of them: on the
/// steak phantom a node under a 1 N load jumped 6.3 mm while its eight control neighbours rose
/// 0.7 mm, and it moved with the iteration count. Divided by sum_j wd_j |g_j|^2, each movable
/// particle takes its own share of the correction, as if all four moved. The Gauss-Seidel fixed
/// point around a free node is then the least-squares point of its hinges (each weighted by
/// 1 / sum_j |g_j|^2). A hinge whose four particles move is projected as before.
void hingeDenominatorWeights(const Real w[4], Real wd[4]);

/// `iterations` Gauss-Seidel sweeps over the active constraints (stretch then bending in each
/// sweep) with classic PBD stiffnesses kStretch, kBending in [0, 1] (converted to per-iteration
/// values, Mueller et al. 2007 Sec. 3.3). p: #V by 3 predicted positions, updated in place;
/// w: #V inverse masses. A hinge divides by hingeDenominatorWeights(). Returns the number of
/// degenerate projections skipped.
long long projectSurfaceConstraints(MatX3& p, const VecX& w, const SurfaceConstraints& c,
                                    const ActiveConstraints& active, Real kStretch, Real kBending,
                                    int iterations);

}  // namespace deform::hybrid_fem_pbd
