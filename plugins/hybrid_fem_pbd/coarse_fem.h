// Hybrid FEM+PBD, the coarse volume mesh MV by linear finite elements (paper Sec. 3, Eqs. (1)-(5),
// Sec. 6.2): 4-node tetrahedra with linear shape functions, element stiffness
// K_e = V_e B^T D B (Eq. (4), evaluated by the shared kernel deform/kernels/fem_tet.h's
// LinearMaterial), assembled into K once, the fixed nodes eliminated, and K factorised once
// (CHOLMOD supernodal LL^T). Each step solves the quasi-static equilibrium K u = f (Eq. (5)).
//
// Because K never changes, each step uses superposition instead of a full solve: the columns of
// K^-1 for the three dofs of every loaded node are solved once and cached, and the response to a
// constant body force (gravity, f_i = sum over tets of rho V_e / 4 g) is solved once per gravity
// vector; u = u_g + sum_loads K^-1[:, node] f. This is exactly K^-1 f, at O(#dofs) per load.
//
// Prescribed displacements (grasps) keep the factorisation too: rows C u = d (each row a node's
// displacement, or a shape-function combination of up to three nodes) are imposed with Lagrange
// multipliers r solved on the Schur complement (capacitance matrix) S = C K^-1 C^T:
//   u = K^-1 (f + C^T r),  S r = d - C K^-1 f,
// with Z = K^-1 C^T built from the cached node columns and S factorised (complete orthogonal
// decomposition, so dependent rows are harmless) only when the set of rows changes.
//
// Paper: "A Hybrid Model Method for Accurate Surface Deformation and Incision Based on FEM and
// PBD", Scientific Programming 2021, article 8343312
// (/work/shared/papers/hybrid-fem-pbd-incision.md).
#pragma once

#include <deform/kernels/sparse.h>
#include <deform/sdk/mesh.h>
#include <deform/sdk/model.h>

#include <Eigen/Dense>
#include <array>
#include <map>
#include <memory>
#include <vector>

#include "load_processing.h"
#include "response_product.h"

namespace deform::hybrid_fem_pbd {

class CoarseLinearFem {
 public:
  struct NodalForce {
    int node = 0;
    Vec3 force = Vec3::Zero();  ///< N
  };
  /// sum_k N_k u(node_k) = displacement (m).
  struct Prescribed {
    CoarseAttachment at;
    Vec3 displacement = Vec3::Zero();
    int axes = 7;  ///< the components prescribed (bits 1 x, 2 y, 4 z); a sliding plate's: one
  };

  /// Assembles and factorises K. mesh: positively oriented tets (m); fixed: pinned node indices.
  /// When nothing is pinned, K is singular; a tiny multiple (1e-8) of its mean diagonal is added
  /// so that it factorises (reported by regularised()). Throws InputError(source, ...) when the
  /// factorisation fails or a tet is degenerate.
  void init(const TetMesh& mesh, const Material& material, const std::vector<int>& fixed,
            const std::string& source);

  /// Displacements u (#nodes by 3, m) under the given nodal forces, a body acceleration
  /// (m/s^2, times density), and prescribed displacements. reactions (optional, resized to
  /// #prescribed): the force (N) each prescription applies to MV, i.e. its Lagrange multipliers r
  /// (the entry's nodes receive N_k r, and sum_k N_k = 1), so that K u = f + sum C^T r: the FEM
  /// reaction K u - f at the prescribed nodes. An axis whose nodes are all pinned has no row and
  /// reports 0 (its load goes to the fixed support). Dependent rows (two prescriptions on the
  /// same node) share their reaction by the minimum-norm solution.
  void solve(const std::vector<NodalForce>& forces, const Vec3& gravity,
             const std::vector<Prescribed>& prescribed, MatX3& u,
             std::vector<Vec3>* reactions = nullptr);

  /// Only nodes [0, count) are read by the caller (the hybrid model reads the control nodes, the
  /// coarse surface, nodes 0..#Vc-1): solve() then adds the prescribed displacements' response
  /// Z lambda to those nodes' rows only and leaves the other nodes' rows of u at 0 (not
  /// computed). Z lambda is the per-step cost of a grasp: #free x #rows, three times the control
  /// rows on the liver (17k volume nodes, 5.5k on the surface). count < 0: every node (default).
  void setOutputNodes(int count);
  /// With output nodes set (setOutputNodes), store Z's output rows in single precision and
  /// accumulate Z lambda in double (response_product.h; the default of the hybrid model's
  /// `precision = float32`), instead of double storage. Takes effect at the next rebuild of the
  /// prescribed rows (call before the first solve).
  void setSinglePrecisionResponse(bool on);

  int numNodes() const { return m_numNodes; }
  int numFreeDofs() const { return m_numFree; }
  bool regularised() const { return m_regularised; }
  long long degenerateTets() const { return m_degenerate; }
  const SparseMatrix& stiffness() const { return m_K; }  ///< reduced to free dofs

 private:
  const MatX& nodeColumns(int node);  ///< K^-1 restricted to node's free dofs (#free by 3)
  /// The constraint rows of `prescribed` (one per entry and free axis), Z = K^-1 C^T and the
  /// factorised S = C Z (and Z's output rows).
  void buildPrescribedRows(const std::vector<Prescribed>& prescribed);
  int m_numNodes = 0, m_numFree = 0;
  std::vector<int> m_dof;  ///< node * 3 + axis -> free dof or -1
  SparseMatrix m_K;
  std::unique_ptr<SparseCholesky> m_chol;
  VecX m_nodeMass;                                 ///< lumped, kg
  static constexpr size_t kColumnCacheSize = 512;  ///< nodes whose columns m_columns keeps
  std::map<int, MatX> m_columns;
  Vec3 m_gravity = Vec3::Zero();
  VecX m_gravityU;
  bool m_regularised = false;
  long long m_degenerate = 0;
  // Capacitance data for the current prescribed rows.
  std::vector<std::array<Real, 8>> m_rowKey;
  MatX m_Z;  ///< #free by #rows
  Eigen::CompleteOrthogonalDecomposition<MatX> m_S;
  std::vector<int> m_rowAxis;
  std::vector<CoarseAttachment> m_rowAt;
  VecX m_scratch, m_forceScratch, m_rhs, m_lambda, m_zl;
  int m_outputNodes = -1;
  std::vector<int> m_outDofs;  ///< free dofs of nodes [0, m_outputNodes)
  MatX m_Zout;                 ///< m_Z's rows at m_outDofs (double response)
  bool m_floatResponse = false;
  BlockedResponse m_ZoutF;  ///< m_Z's rows at m_outDofs in float (single-precision response)
  std::vector<std::array<Real, 8>> m_keyScratch;
};

}  // namespace deform::hybrid_fem_pbd
