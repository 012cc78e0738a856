#include <deform/geometry/surface_mass.h>

#include <cmath>

namespace deform {

namespace {

Real triangleArea(const MatX3& V, const MatX3i& F, Eigen::Index f) {
  const Vec3 a = V.row(F(f, 0)), b = V.row(F(f, 1)), c = V.row(F(f, 2));
  return 0.5 * (b - a).cross(c - a).norm();
}

}  // namespace

LumpedSurface lumpSurface(const SurfaceMesh& S, Real density, Real thickness) {
  LumpedSurface out;
  const int N = S.numVertices();
  VecX area = VecX::Zero(N);
  out.faceArea.resize(S.numFaces());
  for (int f = 0; f < S.numFaces(); ++f) {
    out.faceArea[f] = triangleArea(S.V, S.F, f);
    for (int k = 0; k < 3; ++k) area[S.F(f, k)] += out.faceArea[f] / 3.0;
  }
  out.totalArea = out.faceArea.sum();
  out.edges = uniqueEdges(S.F);
  out.edgeFaces = edgeFaces(S.F, out.edges);
  out.closed = (out.edgeFaces.array() >= 0).all();
  const Real enclosed = std::abs(signedVolume(S.V, S.F));
  // An open surface has no enclosed volume: give it the shell's mass instead.
  const Real totalMass =
      density * (out.closed && enclosed > 0 ? enclosed : out.totalArea * thickness);
  out.mass = area * (totalMass / out.totalArea);
  return out;
}

}  // namespace deform
