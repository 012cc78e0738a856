#include <deform/geometry/phantom.h>
#include <deform/sdk/error.h>

#include "phantom_builders.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>

namespace deform {

namespace {

using namespace phantom_detail;

constexpr Real kPi = std::numbers::pi_v<Real>;
constexpr Real kMaxResolution = 100;

// Smooth step from 1 (x << x0) to 0 (x >> x0) of width about 1/k.
Real fallOff(Real x, Real x0, Real k) {
  return 0.5 * (1 - std::tanh(k * (x - x0)));
}

void recentre(SurfaceMesh* m) {
  const Vec3 c = boundingBox(m->V).center();
  m->V.rowwise() -= c.transpose();
}

int targetCount(int defaultCount, Real resolution) {
  return static_cast<int>(std::lround(defaultCount * resolution));
}

SurfaceMesh capsuleMesh(const CapsuleShape& shape, int defaultCount, Real resolution) {
  int n = 0, K = 0;
  chooseCapsuleFrequency(shape.conformalTubeLength, targetCount(defaultCount, resolution), 100, &n,
                         &K);
  return buildCapsule(shape, n, K);
}

// Liver: the unit direction d (polar axis x) is mapped to a wedge. x = 0.1 d_x runs from the
// thick right lobe (-x) to the thin left lobe (+x); the depth in y narrows from 0.084 to 0.038
// and the ends swing forward (+y) so the posterior side is concave. Vertically, the top half-
// thickness ht and bottom half-thickness hb shrink toward the left lobe, and a midsurface that
// rises toward the middle (c d_z^2, c > hb / 2 over the right lobe) makes the underside shallowly
// concave. z is monotone in d_z
// (C1 blend of ht and hb), so the surface is the union of two graphs over the outline and is
// embedded.
Vec3 liverPoint(const Vec3& d) {
  const Real xi = d.x(), eta = d.y(), zeta = d.z();
  const Real right = fallOff(xi, 0.15, 2.2);  // ~1 over the right lobe, ~0 at the left tip
  const Real x = 0.100 * xi;
  const Real depth = 0.038 + 0.046 * right;
  const Real y = depth * eta + 0.012 * xi * xi;
  const Real thin = 1 - 0.2 * eta;  // thinner toward the anterior border
  const Real ht = (0.013 + 0.036 * right) * thin;
  const Real hb = (0.009 + 0.027 * right) * thin;
  const Real mid = (0.014 + 0.016 * right) * zeta * zeta + 0.012 * (1 - right);
  const Real z = mid + 0.5 * (ht + hb) * zeta + 0.5 * (ht - hb) * zeta * std::abs(zeta);
  return Vec3(x, y, z);
}

// A flattened bag swept along spec.path: half-width width(s), half-thickness flatten x width(s)
// (front to back), meshed from defaultCount vertices at the resolution, recentred.
SurfaceMesh flattenedSweep(SweepSpec spec, const std::function<Real(Real)>& width, Real flatten,
                           int defaultCount, Real res) {
  spec.halfWidth = width;
  spec.halfThickness = [width, flatten](Real s) { return flatten * width(s); };
  SurfaceMesh m = capsuleMesh(sweepShape(spec), defaultCount, res);
  recentre(&m);
  return m;
}

SurfaceMesh makeLiver(Real res) {
  // Mapping the uniform sphere straight through liverPoint stretches triangles up to 8:1 along
  // the thin rim of the left lobe. Pre-warping the directions by diag(A, B, C)^-0.7, (A, B, C)
  // the wedge's rough semi-axes, moves sphere area from the broad faces to the rim (at exponent
  // -1 it would be a radial projection, which overcorrects at grazing angles).
  const Vec3 pre(std::pow(0.1, -0.7), std::pow(0.06, -0.7), std::pow(0.025, -0.7));
  SurfaceMesh m = capsuleMesh(
      radialShape([pre](const Vec3& d) { return liverPoint(pre.cwiseProduct(d).normalized()); }),
      8128, res);
  recentre(&m);
  return m;
}

SurfaceMesh makeSphere(Real res) {
  return capsuleMesh(radialShape([](const Vec3& d) { return Vec3(0.05 * d); }), 1442, res);
}

// Gallbladder: pear along a gently bent axis, fundus radius 17 mm (at s = 0) tapering with zero
// slope at both ends to a 5.5 mm neck; slightly flattened (b = 0.85 a).
SurfaceMesh makeGallbladder(Real res) {
  constexpr Real kFundus = 0.017, kNeck = 0.0055, kLength = 0.069;
  SweepSpec spec{PlanarPath(Vec3::Zero(), 0).arc(0.12, kLength / 0.12), {}, {}};
  auto width = [](Real s) {
    const Real t = std::clamp(s / kLength, Real(0), Real(1));
    return kNeck + (kFundus - kNeck) * 0.5 * (1 + std::cos(kPi * std::pow(t, 1.3)));
  };
  return flattenedSweep(spec, width, 0.85, 1461, res);
}

// Stomach: J-shaped bag. The centreline runs down 40 mm from the fundus, then turns 150 degrees
// to the left on a 60 mm radius toward the pylorus; the half-width falls from 48 mm at the
// fundus to 11 mm at the pylorus and the bag is flattened front to back (b = 0.62 a).
SurfaceMesh makeStomach(Real res) {
  SweepSpec spec{
      PlanarPath(Vec3::Zero(), -kPi / 2).straight(0.04).arc(0.06, 150 * kPi / 180), {}, {}};
  const Real L = spec.path.length();
  auto width = [L](Real s) {
    const Real t = std::clamp(s / L, Real(0), Real(1));
    return 0.011 + 0.031 * 0.5 * (1 + std::cos(kPi * std::pow(t, 1.5))) +
           0.006 * std::exp(-(t / 0.12) * (t / 0.12));
  };
  return flattenedSweep(spec, width, 0.62, 3349, res);
}

// Intestine: a round tube of radius 13.5 mm along an S of two 45 mm-radius arcs of 100 degrees.
SurfaceMesh makeIntestine(Real res) {
  const Real turn = 100 * kPi / 180;
  SweepSpec spec{PlanarPath(Vec3::Zero(), 0).arc(0.045, turn).arc(0.045, -turn),
                 [](Real) { return Real(0.0135); }, [](Real) { return Real(0.0135); }};
  SurfaceMesh m = capsuleMesh(sweepShape(spec), 887, res);
  recentre(&m);
  return m;
}

// Smallest parameter p >= pMin whose count is closest to the target (counts grow with p).
template <class Count>
int chooseLattice(int target, int pMin, Count count) {
  int best = pMin;
  for (int p = pMin; p < 100000; ++p) {
    if (std::abs(std::log(Real(count(p)) / target)) <
        std::abs(std::log(Real(count(best)) / target))) {
      best = p;
    }
    if (count(p) > 2 * target) break;
  }
  return best;
}

SurfaceMesh makeCube(Real res) {
  const int m =
      chooseLattice(targetCount(866, res), 4, [](int p) { return latticeBoxVertexCount(p, p, p); });
  const Real h = 0.1 / m;
  return buildLatticeBox(m, m, m, [m, h](int i, int j, int k) {
    // Integer offsets keep the vertex coordinates exactly symmetric about the origin.
    return Vec3((2 * i - m) * 0.5 * h, (2 * j - m) * 0.5 * h, (2 * k - m) * 0.5 * h);
  });
}

SurfaceMesh makeBeam(Real res) {
  const int c = chooseLattice(targetCount(674, res), 2,
                              [](int p) { return latticeBoxVertexCount(10 * p, p, p); });
  const Real h = 0.01 / c;
  return buildLatticeBox(10 * c, c, c, [c, h](int i, int j, int k) {
    return Vec3(i == 10 * c ? 0.1 : i * h, (2 * j - c) * 0.5 * h, (2 * k - c) * 0.5 * h);
  });
}

// Cook's membrane (Cook 1974): the tapered panel with corners (0, 0), (48, 44), (48, 60) and
// (0, 44) mm in x-y, extruded 8 mm along z from z = 0 (a plane-strain benchmark once both z faces
// are on rollers: the thickness does not change the answer). Lattice 4p x 2p x layers, the x-y
// cells following the taper; with 2p rows the midpoint (48, 52) mm of the loaded edge is a vertex.
SurfaceMesh makeCooksMembrane(Real res) {
  auto layers = [](int p) { return std::max(1, static_cast<int>(std::lround(p / 3.0))); };
  const int p = chooseLattice(targetCount(706, res), 2, [layers](int q) {
    return latticeBoxVertexCount(4 * q, 2 * q, layers(q));
  });
  const int n = 2 * p, nx = 2 * n, nz = layers(p);
  return buildLatticeBox(nx, n, nz, [n, nx, nz](int i, int j, int k) {
    const Real x = 0.048 * i / nx;
    const Real lower = 0.044 / 0.048 * x, upper = 0.044 + 0.016 / 0.048 * x;
    return Vec3(x, lower + (upper - lower) * j / n, 0.008 * k / nz);
  });
}

// Steak: a 0.12 x 0.12 x 0.02 m slab whose square outline is blended 40% toward a disc (rounded
// corners) and gently, smoothly irregular, with a slightly domed, uneven top.
SurfaceMesh makeSteak(Real res) {
  auto layers = [](int p) { return std::max(2, static_cast<int>(std::lround(p / 6.0))); };
  const int m = chooseLattice(targetCount(706, res), 6,
                              [layers](int p) { return latticeBoxVertexCount(p, p, layers(p)); });
  const int nz = layers(m);
  SurfaceMesh mesh = buildLatticeBox(m, m, nz, [m, nz](int i, int j, int k) {
    const Real u = 2.0 * i / m - 1, v = 2.0 * j / m - 1, w = Real(k) / nz - 0.5;
    const Real du = u * std::sqrt(1 - 0.5 * v * v), dv = v * std::sqrt(1 - 0.5 * u * u);
    Real x = 0.6 * u + 0.4 * du, y = 0.6 * v + 0.4 * dv;
    const Real wobble = 1 + 0.04 * x * y + 0.03 * (x * x * x - 0.5 * y) - 0.02 * y * y;
    x *= wobble;
    y *= wobble;
    const Real thick = 0.019 * (1 + 0.06 * (1 - x * x) * (1 - y * y) - 0.04 * x + 0.03 * y);
    const Real lift = 0.001 * x * y;
    return Vec3(0.06 * x, 0.06 * y, thick * w + lift);
  });
  recentre(&mesh);
  return mesh;
}

struct PhantomEntry {
  const char* name;
  const char* what;
  SurfaceMesh (*make)(Real);
};

const PhantomEntry kPhantoms[] = {
    {"liver",
     "organ-like wedge: thick right lobe (-x) tapering to a thin left lobe (+x), domed top, "
     "shallow concave underside",
     makeLiver},
    {"gallbladder",
     "pear 0.090 m along a gently bent axis: 17 mm fundus radius tapering to a 5.5 mm neck",
     makeGallbladder},
    {"stomach",
     "J-shaped bag 0.245 m along its curve: fundus at the top, body down, antrum turning 150 "
     "degrees up to the pylorus, flattened front to back",
     makeStomach},
    {"intestine",
     "tubular segment of radius 13.5 mm, 0.184 m along an S-curve (two 45 mm-radius arcs of 100 "
     "degrees), rounded closed ends",
     makeIntestine},
    {"cube", "0.1 m cube centred at the origin, uniform grid on every face", makeCube},
    {"sphere", "sphere of radius 0.05 m centred at the origin, geodesic-like triangulation",
     makeSphere},
    {"steak",
     "flat tissue slab with a rounded, slightly irregular outline and uneven top, lattice "
     "triangulation",
     makeSteak},
    {"beam",
     "cantilever box x in [0, 0.1], y and z in [-0.005, 0.005] m, square cells (10c x c x c)",
     makeBeam},
    {"cooks_membrane",
     "Cook's membrane: the tapered panel (0, 0), (48, 44), (48, 60), (0, 44) mm in x-y, 8 mm "
     "thick along z from z = 0 (plane strain with z-rollers on both faces)",
     makeCooksMembrane},
};

const PhantomEntry& findPhantom(const std::string& name) {
  for (const PhantomEntry& e : kPhantoms) {
    if (name == e.name) return e;
  }
  std::string known;
  for (const PhantomEntry& e : kPhantoms)
    known += (known.empty() ? "" : ", ") + std::string(e.name);
  throw InputError("phantom:" + name, "", "unknown phantom (known: " + known + ")");
}

}  // namespace

std::vector<std::string> phantomNames() {
  std::vector<std::string> names;
  for (const PhantomEntry& e : kPhantoms) names.emplace_back(e.name);
  return names;
}

std::string phantomDescription(const std::string& name) {
  const PhantomEntry& e = findPhantom(name);
  const SurfaceMesh m = e.make(1.0);
  const Vec3 size = boundingBox(m.V).size();
  char buf[160];
  std::snprintf(buf, sizeof buf,
                "; %.3f x %.3f x %.3f m; %d vertices, %d triangles at resolution 1", size.x(),
                size.y(), size.z(), m.numVertices(), m.numFaces());
  return std::string(e.name) + ": " + e.what + buf;
}

SurfaceMesh makePhantom(const std::string& name, Real resolution) {
  const PhantomEntry& e = findPhantom(name);
  if (!(resolution > 0) || !(resolution <= kMaxResolution)) {
    char buf[64];
    std::snprintf(buf, sizeof buf, "%g", resolution);
    throw InputError("phantom:" + name, "resolution",
                     std::string("resolution must be in (0, 100], got ") + buf);
  }
  return e.make(resolution);
}

}  // namespace deform
