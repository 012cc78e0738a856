// deformbench SDK: what every model built on an organ's tetrahedral mesh (a .msh or .vtk file with
// tetrahedra) derives from it the same way: which node carries each surface vertex, and the
// element volumes, lumped node masses and per-edge volume shares its elastic elements are
// weighted by.
#pragma once

#include <deform/sdk/model.h>

#include <string>
#include <vector>

namespace deform {

/// The node of `nodes` (#N by 3, m) at each vertex of organ.surface, by position: the loader's
/// surface of a tet file is the volume's boundary over the same nodes, so every vertex must sit
/// on a node (within 1e-9 of the nodes' bounding-box diagonal, tol::kRelativeWeld). When the
/// surface is the first rows of `nodes` the map is the identity prefix. Throws InputError naming
/// organ.source and the first vertex without a node.
std::vector<int> surfaceVertexNodes(const Organ& organ, const MatX3& nodes);

/// Element and edge measures of a tet mesh at rest.
struct TetMeasures {
  VecX tetVolume;   ///< #T, m^3, each > 0
  VecX nodeMass;    ///< #N, kg: density V / 4 lumped to each tet's four nodes
  MatX2i edges;     ///< #E unique edges (a < b), sorted by (a, b)
  VecX edgeVolume;  ///< #E, m^3: sum of the volumes of the tets containing the edge
};

/// Measures of T for a material of density rho (kg/m^3). Throws InputError naming `source` and
/// the tet ("organ.volume tet i") for a node index out of range or a tet degenerate or inverted
/// at rest (volume <= 0 with the file's orientation).
TetMeasures measureTets(const TetMesh& T, Real density, const std::string& source);

/// Tets of T (positively oriented at rest, as measureTets() requires) whose signed volume at the
/// node positions x (#N by 3) is zero or negative: the elements a deformation turned inside out.
long long invertedTets(const MatX4i& T, const MatX3& x);

}  // namespace deform
