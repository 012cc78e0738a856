#include "bem_kelvin.h"

#include <cmath>

namespace deform::particle_bem {

KelvinKernel::KelvinKernel(Real young, Real poisson) : m_nu(poisson) {
  m_mu = young / (2 * (1 + poisson));
  m_cu = 1 / (16 * M_PI * m_mu * (1 - m_nu));
  m_cu34 = 3 - 4 * m_nu;
  m_ct = -1 / (8 * M_PI * (1 - m_nu));
  m_ct12 = 1 - 2 * m_nu;
}

Mat3 KelvinKernel::displacement(const Vec3& r) const {
  const Real len = r.norm();
  const Vec3 e = r / len;
  return (m_cu / len) * (m_cu34 * Mat3::Identity() + e * e.transpose());
}

Mat3 KelvinKernel::traction(const Vec3& r, const Vec3& n) const {
  const Real len = r.norm();
  const Vec3 e = r / len;
  const Real drdn = e.dot(n);
  const Mat3 en = e * n.transpose();  // (e n^T)_ij = r_,i n_j
  return (m_ct / (len * len)) * (drdn * (m_ct12 * Mat3::Identity() + 3 * e * e.transpose()) -
                                 m_ct12 * (en - en.transpose()));
}

void KelvinKernel::both(const Vec3& r, const Vec3& n, Mat3& U, Mat3& T) const {
  const Real len = r.norm(), inv = 1 / len;
  const Vec3 e = r * inv;
  const Mat3 ee = e * e.transpose();
  U = (m_cu * inv) * (m_cu34 * Mat3::Identity() + ee);
  const Real drdn = e.dot(n);
  const Mat3 en = e * n.transpose();
  T = (m_ct * inv * inv) *
      (drdn * (m_ct12 * Mat3::Identity() + 3 * ee) - m_ct12 * (en - en.transpose()));
}

const std::array<TrianglePoint, 7>& gaussTriangle7() {
  static const std::array<TrianglePoint, 7> rule = [] {
    const Real s15 = std::sqrt(15.0);
    const Real a1 = (6 - s15) / 21, w1 = (155 - s15) / 1200;
    const Real a2 = (6 + s15) / 21, w2 = (155 + s15) / 1200;
    return std::array<TrianglePoint, 7>{{{1.0 / 3, 1.0 / 3, 1.0 / 3, 9.0 / 40},
                                         {1 - 2 * a1, a1, a1, w1},
                                         {a1, 1 - 2 * a1, a1, w1},
                                         {a1, a1, 1 - 2 * a1, w1},
                                         {1 - 2 * a2, a2, a2, w2},
                                         {a2, 1 - 2 * a2, a2, w2},
                                         {a2, a2, 1 - 2 * a2, w2}}};
  }();
  return rule;
}

void gaussLegendre01(int order, std::vector<Real>& x, std::vector<Real>& w) {
  // Newton on the Legendre polynomial from the Chebyshev-like initial guesses.
  x.assign(order, 0);
  w.assign(order, 0);
  for (int i = 0; i < order; ++i) {
    Real z = std::cos(M_PI * (i + 0.75) / (order + 0.5)), dp = 1;
    for (int it = 0; it < 100; ++it) {
      Real p0 = 1, p1 = z;
      for (int k = 2; k <= order; ++k) {
        const Real p2 = ((2 * k - 1) * z * p1 - (k - 1) * p0) / k;
        p0 = p1;
        p1 = p2;
      }
      if (order == 1) p0 = 1;
      const Real pn = order == 1 ? z : p1;
      dp = order * (z * pn - p0) / (z * z - 1);
      const Real dz = pn / dp;
      z -= dz;
      if (std::abs(dz) < 1e-15) break;
    }
    x[i] = 0.5 * (1 - z);
    w[i] = 1.0 / ((1 - z * z) * dp * dp);  // = (2 / ((1 - z^2) P'^2)) / 2 on [0, 1]
  }
}

std::vector<TrianglePoint> duffyTriangle(int order) {
  std::vector<Real> x, w;
  gaussLegendre01(order, x, w);
  std::vector<TrianglePoint> rule;
  rule.reserve(order * order);
  for (int i = 0; i < order; ++i)
    for (int j = 0; j < order; ++j) {
      const Real s = x[i], t = x[j];
      // dA = 2 Area s ds dt; weights are relative to the area.
      rule.push_back({1 - s, s * (1 - t), s * t, 2 * s * w[i] * w[j]});
    }
  return rule;
}

}  // namespace deform::particle_bem
