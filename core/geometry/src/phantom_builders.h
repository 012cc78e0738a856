// Internal to deform_core: the two mesh families the built-in phantoms (phantom.cpp) are made of.
//
// 1. Capsule meshes: a sphere-like triangulation, two polar caps joined by a band of rings,
//    mapped through a shape function. It covers spheres, star-shaped blobs (liver) and tubes
//    swept along a planar centreline (gallbladder, stomach, intestine) with the same topology
//    and no pole slivers.
// 2. Lattice boxes: the boundary of an nx by ny by nz grid of cells, every boundary quad split
//    into two right triangles, mapped through a point function (cube, beam, steak).
#pragma once

#include <deform/sdk/mesh.h>

#include <functional>
#include <vector>

namespace deform::phantom_detail {

/// Where a capsule vertex sits along its meridian: on the South or North polar hemisphere at
/// polar angle `value` from that pole (rad, in [0, pi/2]), or on the Tube at arc length `value`
/// along the centreline (m, in [0, tubeLength]).
enum class MeridianPart { South, Tube, North };

/// A capsule-shaped surface: point(part, value, phi) for azimuth phi (rad). The canonical frame
/// is right-handed (cos phi, sin phi, axis from South to North); the map must preserve that
/// orientation so that the mesh comes out outward oriented.
struct CapsuleShape {
  /// lambda = integral over the tube of ds / rho(s), rho the tube's mean radius: the tube's
  /// length in the conformal (Mercator) meridian coordinate, 0 for sphere-like shapes.
  Real conformalTubeLength = 0;
  /// Inverse of w(s) = integral_0^s ds'/rho(s'): arc length s for w in [0, lambda].
  std::function<Real(Real w)> arcLengthAt;
  std::function<Vec3(MeridianPart part, Real value, Real phi)> point;
};

/// Topology. Polar caps are pentagonal pyramids subdivided at frequency n (ring r = 0..n has 5r
/// vertices, uniform in azimuth, at polar angle r * atan(2) / n); the band between them has K
/// antiprism strips of rings with 5n vertices, each ring turned half a step from the previous
/// one, evenly spaced in the conformal meridian coordinate (so the band's triangles are nearly
/// equilateral whatever the tube radius). With K near n this is the frequency-n geodesic sphere.
/// #V = 2 + 5n(n+1) + 5n(K-1), #F = 2 #V - 4.
int capsuleVertexCount(int n, int K);

/// Picks (n, K) so that #V is close to max(targetVertices, minVertices) while the band's rows
/// stay within [0.8, 1.25] of their equilateral spacing.
void chooseCapsuleFrequency(Real conformalTubeLength, int targetVertices, int minVertices, int* n,
                            int* K);

/// Builds the capsule mesh for shape at frequency (n, K).
SurfaceMesh buildCapsule(const CapsuleShape& shape, int n, int K);

/// A planar centreline in the xy plane made of straight pieces and circular arcs, parameterised
/// by arc length s (m) from its start.
class PlanarPath {
 public:
  PlanarPath(Vec3 start, Real headingRad) : m_start(start), m_heading(headingRad) {}
  /// Appends a straight piece of the given length (m).
  PlanarPath& straight(Real length);
  /// Appends a circular arc of the given radius (m) turning by angleRad (positive = to the
  /// left, counter-clockwise seen from +z).
  PlanarPath& arc(Real radius, Real angleRad);
  Real length() const { return m_length; }
  /// Position and unit tangent at arc length s (clamped to [0, length]).
  void eval(Real s, Vec3* position, Vec3* tangent) const;
  /// Largest curvature along the path (1/m).
  Real maxCurvature() const;

 private:
  struct Piece {
    Real s0, length, curvature;  // curvature 0 for straight pieces, signed otherwise
    Vec3 p0;
    Real heading0;
  };
  Vec3 m_start;
  Real m_heading;
  Real m_length = 0;
  std::vector<Piece> m_pieces;
};

/// A tube swept along a planar path with an elliptic cross-section: half-width a(s) in the plane
/// of the path and half-thickness b(s) along z, closed by half-ellipsoid caps whose axial extent
/// is (a+b)/2 of the end section. Point at (s, phi) on the tube: C(s) + a cos(phi) N(s) +
/// b sin(phi) z, with N = z x T. Requires max(a) * maxCurvature < 1 (checked with an assert).
struct SweepSpec {
  PlanarPath path;
  std::function<Real(Real s)> halfWidth;
  std::function<Real(Real s)> halfThickness;
};
CapsuleShape sweepShape(const SweepSpec& spec);

/// A sphere-like shape: point = f(unit direction d), where the polar axis of the triangulation
/// is d = +x (South pole at -x). f must be an orientation-preserving embedding of the sphere.
CapsuleShape radialShape(std::function<Vec3(const Vec3& d)> f);

/// Boundary of an nx by ny by nz lattice of cells (each >= 1). Vertices are the boundary
/// lattice points (i, j, k), in lexicographic (i, j, k) order, mapped through point(i, j, k);
/// faces are outward oriented for an orientation-preserving map, the diagonal of each quad
/// alternating in a checkerboard so the triangulation has no preferred direction.
SurfaceMesh buildLatticeBox(int nx, int ny, int nz,
                            const std::function<Vec3(int i, int j, int k)>& point);

/// Number of boundary lattice points of an nx by ny by nz cell box.
int latticeBoxVertexCount(int nx, int ny, int nz);

}  // namespace deform::phantom_detail
