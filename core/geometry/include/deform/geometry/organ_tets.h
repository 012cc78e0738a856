// deformbench SDK: the tet mesh of an organ as the reference solvers (reference_fem and calculix)
// build it, so that both solve on one mesh: Gmsh tets of the organ's surface (or, with fixed boxes
// and conformFixed, of the organ minus the boxes, whose caps are then the clamped boundary), kept
// in the on-disk cache; and the 10-node (quadratic) tets made from it by adding one node at the
// midpoint of every edge.
#pragma once

#include <deform/geometry/tet_mesher.h>
#include <deform/sdk/model.h>

#include <array>
#include <functional>
#include <utility>
#include <vector>

namespace deform {

class Cache;

/// Corner pairs of the midside nodes 4..9 of a 10-node tet: edges (0,1), (0,2), (0,3), (1,2),
/// (1,3), (2,3).
inline constexpr int kQuadraticTetEdges[6][2] = {{0, 1}, {0, 2}, {0, 3}, {1, 2}, {1, 3}, {2, 3}};

struct OrganTetOptions {
  Real edgeLength = 0;              ///< target interior edge length, m; 0: from targetElements
  long long targetElements = 1000;  ///< target number of tets when edgeLength is 0
  bool refineSurface = true;        ///< split long surface edges first (TetMeshOptions)
  MeshGrading grading;              ///< finer near a point (TetMeshOptions)
  /// Mesh the organ minus the fixed boxes (the caps are clamped, the same at every refinement);
  /// false: the whole organ (the nodes inside the boxes are pinned by fixedNodeIndices).
  bool conformFixed = true;
  Real timeoutSeconds = 600;  ///< wall-clock limit of the Gmsh child process
};

/// A plugin's parameters with those of the organ's tet mesh inserted before position `at`: the
/// same in every plugin that meshes through organTets() (reference_fem, calculix: the same values
/// mesh the same tets): elements, edge_length, refine_surface, conform_fixed, mesh_timeout and
/// the grading's focus_x, focus_y, focus_z, focus_radius, focus_ratio, focus_growth.
std::vector<ParamSpec> withOrganTetParams(std::vector<ParamSpec> specs, size_t at);
/// The options those parameters give.
OrganTetOptions organTetOptions(const ParamValues& params);

/// A corner (4-node) tet mesh of an organ and where its surface vertices are.
struct OrganTets {
  TetMesh mesh;  ///< positively oriented tets (tetVolume > 0)
  /// #V: the node of each organ surface vertex; -1 for a vertex inside a clipped-off fixed box
  /// (no node: it is pinned and stays at rest).
  std::vector<int> surfaceNode;
};

/// The organ's tets: organ.volume when the mesh file had tetrahedra (reoriented where negative,
/// surface vertices found by position), otherwise Gmsh's tets of the surface with `options`,
/// kept in `cache` (entry "reference_fem.tets": reference_fem and calculix share it). Throws
/// InputError(organ.source, ...) when the organ cannot be meshed.
OrganTets organTets(const Organ& organ, const OrganTetOptions& options, Cache& cache);

/// 10-node tets from a corner mesh: the corner nodes keep their indices 0..N-1, one node per
/// unique edge follows at the edge's midpoint (straight sides), numbered in the order of the
/// sorted (lower, higher) corner pairs.
struct QuadraticTetNodes {
  MatX3 V;  ///< #N + #E by 3, m: the corners, then the midside nodes
  /// #T by 10: the corners of each tet, then its midside nodes in kQuadraticTetEdges order.
  Eigen::Matrix<int, Eigen::Dynamic, 10, Eigen::RowMajor> elements;
  std::vector<std::pair<int, int>> edges;  ///< #E sorted corner pairs (a < b) of the midside nodes
  int numCorners = 0;

  /// The midside node of the edge between corner nodes a and b; -1 when there is none.
  int edgeNode(int a, int b) const;
};

QuadraticTetNodes addMidsideNodes(const TetMesh& corners);

/// A surface load on 10-node tets, consistent with their quadratic faces. The harness hands a
/// load as shares on surface vertices, lumped the linear way: each loaded triangle gives a third
/// of its force to each corner. Put on the corner nodes of quadratic faces, those shares are not
/// the faces' load: a uniform traction loads a 6-node triangle's corners with nothing and each
/// midside node with a third of the force, and corner forces dent the surface where the answer is
/// smooth (Cook's membrane at nu 0.499 came out 4% too flexible, worse on finer meshes).
/// spread() reads the shares back as a traction that is linear on each boundary triangle whose
/// three corners are loaded (per node: its force over its lumped area on those triangles) and
/// integrates that traction against the six quadratic shape functions. The total force is kept
/// exactly; a loaded node on no such triangle keeps its force.
class QuadraticSurfaceLoad {
 public:
  /// corners: the tets by corner node (V may hold further nodes; only T's are read);
  /// edgeNode(a, b): the midside node of the edge between corner nodes a and b.
  QuadraticSurfaceLoad(const TetMesh& corners, std::function<int(int, int)> edgeNode);

  /// cornerForces: (corner node, force) pairs of one load, N (a node may appear more than once).
  /// Returns (node, force) pairs on corner and midside nodes with the same total.
  std::vector<std::pair<int, Vec3>> spread(
      const std::vector<std::pair<int, Vec3>>& cornerForces) const;

 private:
  MatX3 m_nodes;
  MatX3i m_faces;                             ///< boundary triangles by corner node
  std::vector<std::vector<int>> m_nodeFaces;  ///< boundary triangles around each corner node
  std::function<int(int, int)> m_edgeNode;
};

/// The nodes on a tet mesh's boundary, sorted: the corners of its boundary triangles and, with
/// edgeNode (corner nodes -> midside node or -1; empty for corner tets), their edges' midside
/// nodes.
std::vector<int> tetBoundaryNodes(const TetMesh& corners,
                                  const std::function<int(int, int)>& edgeNode = {});

/// The tet nodes a grasp holds besides the grasped vertices' own: the boundary nodes that lie on
/// an organ surface triangle whose three vertices are all grasped, or on a surface edge whose two
/// vertices are (a quadratic mesh's midside nodes, and the nodes Gmsh adds where it splits long
/// surface edges). Holding only the grasped
/// vertices' nodes would prescribe isolated points, which a 3D solid does not resist: the
/// surface between them would bulge by an amount that depends on the mesh, where every model
/// holds the whole triangles spanned by the grasped vertices (its surface follows them).
class GraspedPatchNodes {
 public:
  struct Held {
    int node = -1;
    std::array<int, 3> vertices{};  ///< the organ triangle's vertices
    Vec3 weights = Vec3::Zero();    ///< barycentric: its target is sum weights[k] * target(k)
  };

  /// surface: the organ's surface; surfaceNode: the node of each surface vertex (-1: none);
  /// nodes: every node's rest position; boundaryNodes: the candidates (the tet mesh's boundary
  /// nodes, corners and midside nodes).
  GraspedPatchNodes(const SurfaceMesh& surface, std::vector<int> surfaceNode, const MatX3& nodes,
                    std::vector<int> boundaryNodes);

  /// The nodes held by a grasp of these surface vertices (sorted or not), other than the
  /// vertices' own nodes; each once.
  std::vector<Held> held(const std::vector<int>& graspedVertices) const;

  /// Every node a grasp of these surface vertices holds: the vertices' own nodes (those that
  /// have one) and held()'s; each once, sorted. (A model leaves out those its support fixes.)
  std::vector<int> nodes(const std::vector<int>& graspedVertices) const;

 private:
  SurfaceMesh m_surface;
  std::vector<int> m_surfaceNode;
  MatX3 m_nodes;
  std::vector<int> m_boundaryNodes;
  std::vector<std::vector<int>> m_vertexFaces;
  std::vector<char> m_isVertexNode;
};

}  // namespace deform
