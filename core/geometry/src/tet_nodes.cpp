#include <deform/geometry/kdtree.h>
#include <deform/geometry/tet_nodes.h>
#include <deform/sdk/error.h>

#include <algorithm>
#include <map>
#include <utility>

namespace deform {

std::vector<int> surfaceVertexNodes(const Organ& organ, const MatX3& nodes) {
  const SurfaceMesh& s = organ.surface;
  const Eigen::Index nv = s.numVertices();
  std::vector<int> map(static_cast<size_t>(nv));
  if (nv == 0) return map;
  const Real tol = tol::kRelativeWeld * std::max<Real>(boundingBox(nodes).diagonal(), 1e-300);
  const bool prefix = nv <= nodes.rows() && (s.V - nodes.topRows(nv)).cwiseAbs().maxCoeff() <= tol;
  KdTree3 tree;
  if (!prefix) tree.build(nodes);
  for (Eigen::Index i = 0; i < nv; ++i) {
    const Vec3 p = s.V.row(i).transpose();
    const int n = prefix ? static_cast<int>(i) : tree.nearest(p);
    if (n < 0 || (nodes.row(n).transpose() - p).norm() > tol)
      throw InputError(organ.source, "organ.surface vertex " + std::to_string(i),
                       "surface vertex is not a node of the tetrahedral mesh");
    map[static_cast<size_t>(i)] = n;
  }
  return map;
}

TetMeasures measureTets(const TetMesh& T, Real density, const std::string& source) {
  const int N = T.numVertices();
  TetMeasures m;
  m.tetVolume.resize(T.numTets());
  m.nodeMass = VecX::Zero(N);
  std::map<std::pair<int, int>, Real> edgeVolume;
  for (int t = 0; t < T.numTets(); ++t) {
    int p[4];
    for (int i = 0; i < 4; ++i) {
      p[i] = T.T(t, i);
      if (p[i] < 0 || p[i] >= N)
        throw InputError(source, "organ.volume tet " + std::to_string(t),
                         "node index out of range");
    }
    const Real vol = tetVolume(T.V.row(p[0]), T.V.row(p[1]), T.V.row(p[2]), T.V.row(p[3]));
    if (!(vol > 0))
      throw InputError(source, "organ.volume tet " + std::to_string(t),
                       "tetrahedron is degenerate or inverted at rest");
    m.tetVolume[t] = vol;
    for (int i = 0; i < 4; ++i) m.nodeMass[p[i]] += density * vol / 4.0;
    for (int i = 0; i < 4; ++i)
      for (int j = i + 1; j < 4; ++j)
        edgeVolume[{std::min(p[i], p[j]), std::max(p[i], p[j])}] += vol;
  }
  m.edges.resize(static_cast<Eigen::Index>(edgeVolume.size()), 2);
  m.edgeVolume.resize(static_cast<Eigen::Index>(edgeVolume.size()));
  Eigen::Index e = 0;
  for (const auto& [ab, vol] : edgeVolume) {
    m.edges(e, 0) = ab.first;
    m.edges(e, 1) = ab.second;
    m.edgeVolume[e++] = vol;
  }
  return m;
}

long long invertedTets(const MatX4i& T, const MatX3& x) {
  long long n = 0;
  for (Eigen::Index t = 0; t < T.rows(); ++t)
    if (!(tetVolume(x.row(T(t, 0)), x.row(T(t, 1)), x.row(T(t, 2)), x.row(T(t, 3))) > 0)) ++n;
  return n;
}

}  // namespace deform
