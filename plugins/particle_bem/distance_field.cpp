#include "distance_field.h"

#include <algorithm>
#include <cmath>

namespace deform::particle_bem {

SignedDistanceField::SignedDistanceField(const TriangleGrid& surface, int cells, Real margin) {
  const Box box = boundingBox(surface.vertices());
  const Vec3 lo = box.lo - Vec3::Constant(margin), hi = box.hi + Vec3::Constant(margin);
  m_h = (hi - lo).maxCoeff() / std::max(1, cells);
  m_lo = lo;
  for (int k = 0; k < 3; ++k) m_n[k] = int(std::ceil((hi[k] - lo[k]) / m_h)) + 1;
  m_phi.resize(size_t(m_n[0]) * m_n[1] * m_n[2]);
  for (int k = 0; k < m_n[2]; ++k)
    for (int j = 0; j < m_n[1]; ++j)
      for (int i = 0; i < m_n[0]; ++i)
        m_phi[(size_t(k) * m_n[1] + j) * m_n[0] + i] =
            surface.signedDistance(m_lo + m_h * Vec3(i, j, k));
}

Real SignedDistanceField::value(const Vec3& p) const {
  const Vec3 g = (p - m_lo) / m_h;
  int idx[3];
  Real t[3];
  Real outside = 0;
  for (int a = 0; a < 3; ++a) {
    const Real c = std::clamp(g[a], Real(0), Real(m_n[a] - 1));
    outside += (g[a] - c) * (g[a] - c);
    idx[a] = std::min(int(std::floor(c)), m_n[a] - 2);
    idx[a] = std::max(idx[a], 0);
    t[a] = c - idx[a];
  }
  Real v = 0;
  for (int c = 0; c < 8; ++c) {
    const int di = c & 1, dj = (c >> 1) & 1, dk = (c >> 2) & 1;
    const Real w = (di ? t[0] : 1 - t[0]) * (dj ? t[1] : 1 - t[1]) * (dk ? t[2] : 1 - t[2]);
    v += w * node(std::min(idx[0] + di, m_n[0] - 1), std::min(idx[1] + dj, m_n[1] - 1),
                  std::min(idx[2] + dk, m_n[2] - 1));
  }
  return v + std::sqrt(outside) * m_h;
}

Vec3 SignedDistanceField::gradient(const Vec3& p) const {
  // Central difference of the trilinear interpolant over a fraction of a cell: the derivative
  // of the interpolant itself, smoothed across cell faces.
  const Real e = 0.25 * m_h;
  Vec3 g;
  for (int a = 0; a < 3; ++a) {
    Vec3 d = Vec3::Zero();
    d[a] = e;
    g[a] = (value(p + d) - value(p - d)) / (2 * e);
  }
  return g;
}

bool SignedDistanceField::pushOut(Vec3& p, Real clearance) const {
  const Real phi = value(p);
  if (phi >= clearance) return false;
  const Vec3 g = gradient(p);
  const Real len = g.norm();
  if (!(len > 0)) return false;
  p += (clearance - phi) * g / len;
  return true;
}

}  // namespace deform::particle_bem
