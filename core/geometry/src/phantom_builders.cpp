#include "phantom_builders.h"

#include <algorithm>
#include <array>
#include <cassert>
#include <cmath>
#include <memory>
#include <numbers>
#include <stdexcept>

namespace deform::phantom_detail {

namespace {

constexpr Real kPi = std::numbers::pi_v<Real>;

// Polar angle of the caps' boundary ring: the icosahedron's, so that with K near n the capsule
// is the geodesic sphere and the cap triangles are close to equilateral.
const Real kCapAngle = std::atan(Real(2));

// Conformal meridian coordinate w = ln tan(alpha/2) of the cap boundary (negative).
Real capConformal() {
  return std::log(std::tan(0.5 * kCapAngle));
}

// Ideal number of band rows: ring spacing sqrt(3)/2 of the azimuthal step 2 pi / (5n).
Real idealRows(Real conformalTubeLength, int n) {
  const Real band = conformalTubeLength - 2 * capConformal();
  const Real rowStep = (2 * kPi / (5.0 * n)) * (std::sqrt(Real(3)) / 2);
  return band / rowStep;
}

struct RingVertex {
  MeridianPart part;
  Real value;
  Real phi;
  Vec3 canonical;  // on the unit capsule of conformal tube length lambda, for orientation
};

Vec3 canonicalCap(MeridianPart part, Real alpha, Real phi, Real lambda) {
  const Real r = std::sin(alpha);
  if (part == MeridianPart::South)
    return Vec3(r * std::cos(phi), r * std::sin(phi), -std::cos(alpha));
  return Vec3(r * std::cos(phi), r * std::sin(phi), lambda + std::cos(alpha));
}

}  // namespace

int capsuleVertexCount(int n, int K) {
  return 2 + 5 * n * (n + 1) + 5 * n * (K - 1);
}

void chooseCapsuleFrequency(Real conformalTubeLength, int targetVertices, int minVertices, int* n,
                            int* K) {
  const int target = std::max(targetVertices, minVertices);
  Real bestCost = 1e300;
  *n = 2;
  *K = std::max(1, static_cast<int>(std::lround(idealRows(conformalTubeLength, 2))));
  for (int nn = 2; nn <= 2000; ++nn) {
    const Real ideal = idealRows(conformalTubeLength, nn);
    const int klo = std::max(1, static_cast<int>(std::ceil(0.8 * ideal)));
    const int khi = std::max(klo, static_cast<int>(std::floor(1.25 * ideal)));
    if (capsuleVertexCount(nn, klo) > 2 * target && bestCost < 1e300) break;
    const Real kTarget =
        static_cast<Real>(target - 2 - 5 * nn * (nn + 1)) / static_cast<Real>(5 * nn) + 1;
    const int kk = std::clamp(static_cast<int>(std::lround(kTarget)), klo, khi);
    const int v = capsuleVertexCount(nn, kk);
    if (v < minVertices) continue;
    const Real cost = std::abs(std::log(static_cast<Real>(v) / target)) +
                      0.25 * std::abs(std::log(static_cast<Real>(kk) / ideal));
    if (cost < bestCost) {
      bestCost = cost;
      *n = nn;
      *K = kk;
    }
  }
}

SurfaceMesh buildCapsule(const CapsuleShape& shape, int n, int K) {
  assert(n >= 1 && K >= 1);
  const Real lambda = shape.conformalTubeLength;
  const int ringSize = 5 * n;
  const Real halfStep = kPi / ringSize;
  const Real northPhase = K * halfStep;

  // Rings in vertex order: South r = 0..n, band k = 1..K-1, North r = n..0. ringStart maps
  // (south r), (band k) and (north r) to the first vertex of that ring.
  std::vector<RingVertex> verts;
  verts.reserve(capsuleVertexCount(n, K));
  std::vector<int> southStart(n + 1), northStart(n + 1), bandStart(K + 1);
  auto addCapRing = [&](MeridianPart part, int r, Real phase) {
    const int m = (r == 0) ? 1 : 5 * r;
    const Real alpha = kCapAngle * r / n;
    for (int q = 0; q < m; ++q) {
      const Real phi = phase + 2 * kPi * q / m;
      verts.push_back({part, alpha, phi, canonicalCap(part, alpha, phi, lambda)});
    }
  };
  for (int r = 0; r <= n; ++r) {
    southStart[r] = static_cast<int>(verts.size());
    addCapRing(MeridianPart::South, r, 0);
  }
  bandStart[0] = southStart[n];
  const Real w0 = capConformal();
  const Real bandLength = lambda - 2 * w0;
  for (int k = 1; k < K; ++k) {
    bandStart[k] = static_cast<int>(verts.size());
    const Real w = w0 + bandLength * k / K;
    for (int q = 0; q < ringSize; ++q) {
      const Real phi = k * halfStep + 2 * kPi * q / ringSize;
      RingVertex v;
      v.phi = phi;
      if (w < 0) {
        v.part = MeridianPart::South;
        v.value = 2 * std::atan(std::exp(w));
        v.canonical = canonicalCap(v.part, v.value, phi, lambda);
      } else if (w > lambda) {
        v.part = MeridianPart::North;
        v.value = 2 * std::atan(std::exp(lambda - w));
        v.canonical = canonicalCap(v.part, v.value, phi, lambda);
      } else {
        v.part = MeridianPart::Tube;
        v.value = shape.arcLengthAt(w);
        v.canonical = Vec3(std::cos(phi), std::sin(phi), w);
      }
      verts.push_back(v);
    }
  }
  for (int r = n; r >= 0; --r) {
    northStart[r] = static_cast<int>(verts.size());
    addCapRing(MeridianPart::North, r, northPhase);
  }
  bandStart[K] = northStart[n];
  assert(static_cast<int>(verts.size()) == capsuleVertexCount(n, K));

  std::vector<std::array<int, 3>> tris;
  tris.reserve(2 * verts.size());
  auto capStrips = [&](const std::vector<int>& start) {
    for (int r = 0; r < n; ++r) {
      const int mi = (r == 0) ? 1 : 5 * r, mo = 5 * (r + 1);
      for (int c = 0; c < 5; ++c) {
        auto inner = [&](int j) { return start[r] + (r == 0 ? 0 : (c * r + j) % mi); };
        auto outer = [&](int j) { return start[r + 1] + (c * (r + 1) + j) % mo; };
        for (int j = 0; j <= r; ++j) tris.push_back({inner(j), outer(j), outer(j + 1)});
        for (int j = 0; j < r; ++j) tris.push_back({inner(j), outer(j + 1), inner(j + 1)});
      }
    }
  };
  capStrips(southStart);
  capStrips(northStart);
  for (int k = 0; k < K; ++k) {
    for (int q = 0; q < ringSize; ++q) {
      const int a0 = bandStart[k] + q, a1 = bandStart[k] + (q + 1) % ringSize;
      const int b0 = bandStart[k + 1] + q, b1 = bandStart[k + 1] + (q + 1) % ringSize;
      tris.push_back({a0, a1, b0});
      tris.push_back({b0, a1, b1});
    }
  }

  // Orientation from the canonical capsule, where "outward" is unambiguous: away from the
  // nearest point of the axis segment [0, lambda].
  SurfaceMesh mesh;
  mesh.F.resize(static_cast<Eigen::Index>(tris.size()), 3);
  for (size_t t = 0; t < tris.size(); ++t) {
    auto& f = tris[t];
    const Vec3& p0 = verts[f[0]].canonical;
    const Vec3& p1 = verts[f[1]].canonical;
    const Vec3& p2 = verts[f[2]].canonical;
    const Vec3 c = (p0 + p1 + p2) / 3;
    const Vec3 out = c - Vec3(0, 0, std::clamp(c.z(), Real(0), lambda));
    if ((p1 - p0).cross(p2 - p0).dot(out) < 0) std::swap(f[1], f[2]);
    mesh.F.row(static_cast<Eigen::Index>(t)) << f[0], f[1], f[2];
  }
  mesh.V.resize(static_cast<Eigen::Index>(verts.size()), 3);
  for (size_t i = 0; i < verts.size(); ++i) {
    mesh.V.row(static_cast<Eigen::Index>(i)) =
        shape.point(verts[i].part, verts[i].value, verts[i].phi).transpose();
  }
  return mesh;
}

PlanarPath& PlanarPath::straight(Real length) {
  Vec3 p;
  Vec3 t;
  eval(m_length, &p, &t);
  m_pieces.push_back(
      {m_length, length, 0, p, m_pieces.empty() ? m_heading : std::atan2(t.y(), t.x())});
  m_length += length;
  return *this;
}

PlanarPath& PlanarPath::arc(Real radius, Real angleRad) {
  Vec3 p;
  Vec3 t;
  eval(m_length, &p, &t);
  const Real len = radius * std::abs(angleRad);
  const Real curvature = (angleRad >= 0 ? 1 : -1) / radius;
  m_pieces.push_back(
      {m_length, len, curvature, p, m_pieces.empty() ? m_heading : std::atan2(t.y(), t.x())});
  m_length += len;
  return *this;
}

void PlanarPath::eval(Real s, Vec3* position, Vec3* tangent) const {
  if (m_pieces.empty()) {
    *position = m_start;
    *tangent = Vec3(std::cos(m_heading), std::sin(m_heading), 0);
    return;
  }
  s = std::clamp(s, Real(0), m_length);
  size_t i = 0;
  while (i + 1 < m_pieces.size() && s > m_pieces[i].s0 + m_pieces[i].length) ++i;
  const Piece& pc = m_pieces[i];
  const Real ds = std::clamp(s - pc.s0, Real(0), pc.length);
  if (pc.curvature == 0) {
    const Vec3 dir(std::cos(pc.heading0), std::sin(pc.heading0), 0);
    *position = pc.p0 + ds * dir;
    *tangent = dir;
  } else {
    const Real h = pc.heading0 + pc.curvature * ds;
    *position =
        pc.p0 + Vec3(std::sin(h) - std::sin(pc.heading0), std::cos(pc.heading0) - std::cos(h), 0) /
                    pc.curvature;
    *tangent = Vec3(std::cos(h), std::sin(h), 0);
  }
}

Real PlanarPath::maxCurvature() const {
  Real k = 0;
  for (const Piece& p : m_pieces) k = std::max(k, std::abs(p.curvature));
  return k;
}

CapsuleShape sweepShape(const SweepSpec& specIn) {
  auto spec = std::make_shared<const SweepSpec>(specIn);
  const Real L = spec->path.length();
  // w(s) = integral ds / rho on a fine uniform grid (trapezoid rule), inverted by interpolation.
  constexpr int kSteps = 4096;
  auto table = std::make_shared<std::vector<Real>>(kSteps + 1, 0.0);
  auto rho = [spec](Real s) { return 0.5 * (spec->halfWidth(s) + spec->halfThickness(s)); };
  const Real h = L / kSteps;
  Real maxHalfWidth = 0;
  for (int i = 1; i <= kSteps; ++i) {
    (*table)[i] = (*table)[i - 1] + 0.5 * h * (1 / rho((i - 1) * h) + 1 / rho(i * h));
    maxHalfWidth = std::max(maxHalfWidth, spec->halfWidth(i * h));
  }
  if (maxHalfWidth * spec->path.maxCurvature() >= 0.95) {
    throw std::logic_error("phantom sweep: tube wider than the centreline's radius of curvature");
  }
  CapsuleShape shape;
  shape.conformalTubeLength = table->back();
  shape.arcLengthAt = [table, h](Real w) {
    const auto& t = *table;
    if (w <= 0) return Real(0);
    if (w >= t.back()) return h * kSteps;
    const size_t i = static_cast<size_t>(std::upper_bound(t.begin(), t.end(), w) - t.begin());
    const Real f = (w - t[i - 1]) / (t[i] - t[i - 1]);
    return h * (static_cast<Real>(i - 1) + f);
  };
  shape.point = [spec, L](MeridianPart part, Real value, Real phi) {
    const Vec3 z(0, 0, 1);
    Vec3 c;
    Vec3 t;
    const Real s = (part == MeridianPart::South) ? 0 : (part == MeridianPart::North ? L : value);
    spec->path.eval(s, &c, &t);
    const Vec3 nrm = z.cross(t);
    const Real a = spec->halfWidth(s), b = spec->halfThickness(s);
    const Vec3 radial = a * std::cos(phi) * nrm + b * std::sin(phi) * z;
    if (part == MeridianPart::Tube) return Vec3(c + radial);
    const Real capLength = 0.5 * (a + b);
    const Real sign = (part == MeridianPart::South) ? -1 : 1;
    return Vec3(c + sign * capLength * std::cos(value) * t + std::sin(value) * radial);
  };
  return shape;
}

CapsuleShape radialShape(std::function<Vec3(const Vec3& d)> f) {
  CapsuleShape shape;
  shape.conformalTubeLength = 0;
  shape.arcLengthAt = [](Real) { return Real(0); };
  shape.point = [f = std::move(f)](MeridianPart part, Real value, Real phi) {
    const Real alpha = (part == MeridianPart::Tube) ? kPi / 2 : value;
    const Real r = std::sin(alpha);
    const Real axial = (part == MeridianPart::South ? -1 : 1) * std::cos(alpha);
    // Canonical (cos phi, sin phi, axial) -> (x, y, z) = (axial, r cos phi, r sin phi): a cyclic
    // permutation, so orientation is preserved.
    return f(Vec3(axial, r * std::cos(phi), r * std::sin(phi)));
  };
  return shape;
}

int latticeBoxVertexCount(int nx, int ny, int nz) {
  const long all = static_cast<long>(nx + 1) * (ny + 1) * (nz + 1);
  const long inner =
      static_cast<long>(std::max(nx - 1, 0)) * std::max(ny - 1, 0) * std::max(nz - 1, 0);
  return static_cast<int>(all - inner);
}

SurfaceMesh buildLatticeBox(int nx, int ny, int nz,
                            const std::function<Vec3(int i, int j, int k)>& point) {
  assert(nx >= 1 && ny >= 1 && nz >= 1);
  const std::array<int, 3> dims{nx, ny, nz};
  auto lin = [&](int i, int j, int k) {
    return (static_cast<long>(i) * (ny + 1) + j) * (nz + 1) + k;
  };
  std::vector<int> index(static_cast<size_t>((nx + 1)) * (ny + 1) * (nz + 1), -1);
  SurfaceMesh mesh;
  mesh.V.resize(latticeBoxVertexCount(nx, ny, nz), 3);
  int nv = 0;
  for (int i = 0; i <= nx; ++i) {
    for (int j = 0; j <= ny; ++j) {
      for (int k = 0; k <= nz; ++k) {
        if (i > 0 && i < nx && j > 0 && j < ny && k > 0 && k < nz) continue;
        index[lin(i, j, k)] = nv;
        mesh.V.row(nv++) = point(i, j, k).transpose();
      }
    }
  }
  std::vector<std::array<int, 3>> tris;
  using L3 = std::array<int, 3>;
  auto cross = [](const L3& a, const L3& b, const L3& c) {
    const L3 u{b[0] - a[0], b[1] - a[1], b[2] - a[2]}, v{c[0] - a[0], c[1] - a[1], c[2] - a[2]};
    return L3{u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
  };
  auto addTri = [&](const L3& a, const L3& b, const L3& c, int axis, int outward) {
    const L3 nrm = cross(a, b, c);
    const int id[3] = {index[lin(a[0], a[1], a[2])], index[lin(b[0], b[1], b[2])],
                       index[lin(c[0], c[1], c[2])]};
    if (nrm[axis] * outward > 0) {
      tris.push_back({id[0], id[1], id[2]});
    } else {
      tris.push_back({id[0], id[2], id[1]});
    }
  };
  for (int axis = 0; axis < 3; ++axis) {
    const int u = (axis + 1) % 3, v = (axis + 2) % 3;
    for (int side = 0; side < 2; ++side) {
      const int outward = side ? 1 : -1;
      for (int p = 0; p < dims[u]; ++p) {
        for (int q = 0; q < dims[v]; ++q) {
          auto corner = [&](int dp, int dq) {
            L3 c{};
            c[axis] = side ? dims[axis] : 0;
            c[u] = p + dp;
            c[v] = q + dq;
            return c;
          };
          const L3 c00 = corner(0, 0), c10 = corner(1, 0), c11 = corner(1, 1), c01 = corner(0, 1);
          if ((p + q) % 2 == 0) {
            addTri(c00, c10, c11, axis, outward);
            addTri(c00, c11, c01, axis, outward);
          } else {
            addTri(c00, c10, c01, axis, outward);
            addTri(c10, c11, c01, axis, outward);
          }
        }
      }
    }
  }
  mesh.F.resize(static_cast<Eigen::Index>(tris.size()), 3);
  for (size_t t = 0; t < tris.size(); ++t) {
    mesh.F.row(static_cast<Eigen::Index>(t)) << tris[t][0], tris[t][1], tris[t][2];
  }
  return mesh;
}

}  // namespace deform::phantom_detail
