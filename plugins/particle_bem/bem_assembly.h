// particle_bem: the BEM precomputation of the paper's §5.1 (eqs. 2-6).
//
// Discretisation: linear triangles with collocation at the vertices (N nodes, nodal u and p, so
// the coarse vertices carry the surface particles and interpolation to the fine surface is
// barycentric). Eq. 2 becomes, per source node i,
//   sum_j H_ij u_j = sum_j G_ij p_j,   H_ij = c_i delta_ij + sum_e int_e T*(x_i, y) N_j(y) dGamma
//                                      G_ij = sum_e int_e U*(x_i, y) N_j(y) dGamma      (eq. 5)
// (H, G: 3N x 3N, blocks 3x3). The paper writes eqs. 3-4 for constant elements with the
// seven-point rule; we use the same rule with the linear shape functions, plus:
//  - near-singular triangles (source closer than nearFactor x element size): the seven-point
//    rule on a recursive 4-way subdivision (maxLevel levels);
//  - singular triangles (source at one of their vertices): a Duffy transform from that vertex
//    (Gauss-Legendre order x order), which removes the 1/r singularity of U* (weakly singular
//    G) and of T* N_j for j != i;
//  - the strongly singular diagonal blocks H_ii (c_i and the Cauchy principal value) by the
//    rigid-body trick: a rigid translation gives no traction, so H_ii = -sum_{j != i} H_ij.
//
// Mixed boundary conditions (eq. 6 with a fixed region): at fixed nodes u = 0 is known and p
// is unknown, so their columns swap sides: A x = B p_free with A = [H_free | -G_fixed],
// x = (u_free, p_fixed), B = G with fixed columns zeroed. M = (rows u_free of) A^-1 B: the global
// deformation matrix, U = M P. With no fixed node the traction problem leaves rigid motions
// free; the six rigid modes R are then removed by a bordered system [H R; R^T 0] (u orthogonal
// to rigid motions), which needs a self-equilibrated load.
#pragma once

#include "bem_kelvin.h"

#include <deform/sdk/mesh.h>

#include <functional>
#include <vector>

namespace deform::particle_bem {

struct BemQuadrature {
  int duffyOrder = 6;             ///< Gauss-Legendre points per direction on singular triangles
  Real nearFactor = 1.5;          ///< subdivide when |x - centroid| < nearFactor * longest edge
  int maxLevel = 3;               ///< subdivision depth for near-singular triangles
  bool rigidBodyDiagonal = true;  ///< false: leave H_ii = 0 (tests sum the off-diagonal blocks)
};

struct BemMatrices {
  MatX H, G;                      ///< 3N x 3N (H dimensionless, G in m/Pa)
  long long subdividedPairs = 0;  ///< near-singular (node, triangle) pairs
  long long singularPairs = 0;
  long long degenerateTriangles = 0;  ///< zero area, skipped
};

/// H and G of a closed, outward-oriented surface.
BemMatrices assembleBem(const SurfaceMesh& s, Real young, Real poisson,
                        const BemQuadrature& q = {});

/// Tractions on the boundary of a clamped region. With fixed nodes (u = 0, traction unknown)
/// the support is the set of faces whose three nodes are all fixed; a fixed node with a free
/// face too lies on the support's boundary, where the traction jumps: the unknown reaction
/// acts on its support faces only, while on its free faces the traction is the known load.
/// Using the whole column G_j for it (what nodal clamps do) spreads the reaction over the
/// adjacent free elements, a support half an element larger whose size depends on the mesh.
/// SupportColumns holds, for each boundary node j, the column block of G integrated over its
/// support faces only,
///   Gs_ij = sum_{e in support, j in e} int_e U*(x_i, y) N_j(y) dGamma      (3N x 3 per node),
/// which replaces -G_j in the mixed system (the unknown is the support-side traction).
struct SupportColumns {
  std::vector<int> nodes;  ///< fixed nodes with at least one free face
  MatX G;                  ///< 3N x 3 nodes.size(), m/Pa
};
SupportColumns supportColumns(const SurfaceMesh& s, Real young, Real poisson,
                              const std::vector<int>& fixed, const BemQuadrature& q = {});

/// The clamp edge's singular reaction. At the edge of a clamped region the reaction traction
/// grows like s^(-1/2) with the distance s from the edge (the clamped-free half-plane exponent
/// 1/2 +- i ln(3 - 4 nu) / 2 pi; its real part is used), which linear traction elements of
/// ~2 cm cannot follow: the coarse solution is then too stiff and converges slowly (history
/// note, "Fourth pass"). On the support faces along the support's boundary curve the reaction is
/// therefore represented as p(y) = w(y) sum_j N_j(y) p_j with
///   w = lambda_c^(-1/2)      on a face with an edge (a, b) on the curve (c the third vertex,
///                            lambda_c its barycentric = the distance from ab over c's),
///   w = (1 - lambda_a)^(-1/2) on a face touching the curve at the vertex a only,
/// so w = 1 at the vertices off the curve (continuous with the neighbouring support faces) and
/// the exponent is the theory's, with no constant. The integrals int U* N_j w use collapsed
/// coordinates (t = tau^2 from the edge, rho = tau^2 from the vertex), which remove the
/// s^(-1/2) factor (and the 1/r of a source at the collapse vertex), on a graded 8 x 8 grid of
/// 5 x 5 Gauss-Legendre cells. Faces with two or three curve edges keep w = 1.
/// delta holds, per affected fixed node j, int U* N_j (w - 1) over its faces along the curve.
struct SingularSupport {
  std::vector<int> nodes;  ///< fixed nodes with a support face along the curve
  MatX delta;              ///< 3N x 3 nodes.size(), m/Pa
  int edgeFaces = 0, vertexFaces = 0;
};
SingularSupport singularSupport(const SurfaceMesh& s, Real young, Real poisson,
                                const std::vector<int>& fixed);

/// The reaction columns with the singular correction, for solveBemRhs /
/// computeDeformationMatrix: every node of `sc` and of `corr`, column (Gs_j or G_j) + delta_j.
/// For computeDeformationMatrix also add delta to G's columns (addToColumns) so that the
/// boundary nodes' free-face part G_j - Gs_j stays the same.
SupportColumns withSingularSupport(const SupportColumns& sc, const MatX& G,
                                   const SingularSupport& corr);
void addToColumns(MatX& G, const SingularSupport& corr);

/// Lumped nodal areas A_k = sum over adjacent triangles of area / 3 (m^2): a nodal traction p_k
/// with linear interpolation carries the force int N_k p dGamma = A_k p_k.
VecX nodalAreas(const SurfaceMesh& s);

struct DeformationMatrix {
  MatX M;        ///< 3N x 3N, m/Pa: nodal displacements per nodal traction; fixed rows/cols 0
  MatX gravity;  ///< 3N x 3, m per (m/s^2): displacement under unit gravity along x, y, z
  std::vector<int> fixed;
  bool bordered = false;  ///< no fixed node: rigid modes constrained, gravity left at zero
  size_t bytes() const { return size_t(M.size() + gravity.size()) * sizeof(Real); }
};

/// M = H^-1 G with mixed boundary conditions (partial-pivot LU of the mixed system, eq. 6).
/// normals: #N by 3 unit vertex normals (for the gravity particular solution's traction).
/// Gravity response: the particular solution u_p = alpha b |x - c|^2, alpha = -1 / (2 lambda +
/// 8 mu), b = rho g, of Navier's equation with a uniform body force, plus a homogeneous BEM
/// solution correcting its boundary values (u = 0 on fixed nodes, p = 0 elsewhere).
/// support (optional): the boundary nodes' support-side columns (SupportColumns); without it
/// every fixed node's reaction acts over all its faces (the first version).
DeformationMatrix computeDeformationMatrix(BemMatrices&& bem, const SurfaceMesh& s,
                                           const MatX3& normals, const std::vector<int>& fixed,
                                           Real young, Real poisson, Real density,
                                           const SupportColumns* support = nullptr);

/// One BEM solve (the "standard BEM" of Table 2): nodal displacements (3N, m) for nodal
/// tractions (3N, Pa; values at fixed nodes ignored), u = 0 at fixed nodes.
VecX solveBem(const BemMatrices& bem, const SurfaceMesh& s, const std::vector<int>& fixed,
              const VecX& traction);

/// A traction field t(x) (Pa) prescribed on the surface, as a function of position.
using TractionField = std::function<Vec3(const Vec3&)>;

/// Right-hand side of eq. 2 for a traction FIELD rather than its nodal interpolant:
///   b_i = int_Gamma U*(x_i, y) t(y) dGamma(y)       (3N, m)
/// integrated over every element with the rules of assembleBem (seven-point rule, recursive
/// subdivision near the source, Duffy from the source vertex), with elements further subdivided
/// until they are no larger than `resolution` (m) so that the field is resolved; elements where
/// |t| < 1e-12 max|t| at every quadrature point are skipped. (G p, with p the nodal values of
/// t, is the same integral with t replaced by its linear interpolant.)
VecX integrateTractionField(const SurfaceMesh& s, Real young, Real poisson, const TractionField& t,
                            Real resolution, const BemQuadrature& q = {});

/// One BEM solve with a given right-hand side b (3N; b = G p for nodal tractions p): nodal
/// displacements (3N, m), u = 0 at fixed nodes. The fixed nodes' reaction tractions are
/// unknowns on top of whatever b already carries.
/// support (optional): as for computeDeformationMatrix.
VecX solveBemRhs(const BemMatrices& bem, const SurfaceMesh& s, const std::vector<int>& fixed,
                 const VecX& rhs, const SupportColumns* support = nullptr);

/// Fraction of each node's traction support inside a box, phi_j = int_box N_j dGamma /
/// int N_j dGamma (N_j the linear shape function), by the midpoint rule on a samples x samples
/// subdivision of every triangle. 1 deep inside, 0 outside, in between on the box's edge.
VecX fixedFractions(const SurfaceMesh& s, const Box& box, int samples = 16);

/// One BEM solve with a fixed region that cuts through elements, each node constrained in
/// proportion to its fixed fraction phi_j (fixedFractions):
///  - phi_j = 1 (to 1e-9): u_j = 0, p_j unknown (as solveBemRhs);
///  - 0 < phi_j < 1: an elastic support p_j = -k_j u_j added to the load, with
///      k_j = E / sqrt(A_j) * phi_j / (1 - phi_j)     (Pa/m; A_j the lumped nodal area),
///    i.e. the stiffness of tissue one element long (E / h) times the ratio of clamped to free
///    support: stiffer the more of the node's support is clamped, a clamp in the limit phi -> 1
///    and free at phi = 0. So the discrete support moves continuously with the region's edge
///    instead of jumping when a node crosses it; columns j of A become H_j + k_j G_j;
///  - phi_j = 0: free.
/// The factor 1 in k_j is a modelling choice: the loss ratio of the liver cases moves by
/// several percentage points between 0.3 and 3 (README, "Method").
/// rhs as for solveBemRhs. Returns nodal displacements (3N, m).
VecX solveBemPartial(const BemMatrices& bem, const SurfaceMesh& s, const VecX& phi, Real young,
                     const VecX& rhs);

}  // namespace deform::particle_bem
