// PbdModel's isometric bending (deform/kernels/isometric_bending.h): the hinges in colour order as
// structure of arrays, projected colour by colour on the solver's packed positions (float or
// double, like the distance constraints), so a sweep needs no unpacking for them.
#include "pbd_model.h"

#include <algorithm>

namespace deform::pbd {

void PbdModel::initIsometric() {
  const size_t n = m_iso.size();
  for (int k = 0; k < 4; ++k) {
    m_isoP[k].resize(n);
    m_isoK[k].resize(n);
    m_isoWK[k].assign(n, 0.0);
    for (size_t i = 0; i < n; ++i) {
      m_isoP[k][i] = 4 * m_iso[i].p[k];
      m_isoK[k][i] = m_iso[i].K[k];
    }
  }
  m_isoRest.resize(n);
  for (size_t i = 0; i < n; ++i) m_isoRest[i] = m_iso[i].rest;
  m_isoAlphaTilde.assign(n, 0.0);
  m_isoScale.assign(n, 0.0);
  m_lambdaIso.assign(n, 0.0);
  for (int k = 0; k < 4; ++k) {
    m_isoKF[k].clear();
    m_isoWKF[k].clear();
  }
  m_isoRestF.clear();
  if (!m_f32 && n > 0) {
    // Rest values measured by the batch kernel itself (as projectIsometric() will evaluate C).
    m_p = m_rest;
    packPositions();
    const IsometricBatch<Real> b = isometricBatch(m_isoP, m_isoK, m_isoWK, m_isoRest,
                                                  m_isoAlphaTilde, m_isoScale, m_lambdaIso);
    std::vector<Real> rest(n);
    forEachIndependentRun(m_isoColours, [&](size_t i, size_t e) {
      isometricLengthsColour(p4(), b, i, e, rest.data());
    });
    m_isoRest = rest;
  }
  if (m_f32 && n > 0) {
    for (int k = 0; k < 4; ++k) {
      m_isoKF[k].assign(m_isoK[k].begin(), m_isoK[k].end());
      m_isoWKF[k].assign(n, 0.0f);
    }
    m_isoAlphaTildeF.assign(n, 0.0f);
    m_isoScaleF.assign(n, 0.0f);
    m_lambdaIsoF.assign(n, 0.0f);
    m_isoRestF.assign(n, 0.0f);
    // Rest values measured in float from the packed rest positions, colour by colour as
    // projectIsometric() projects them: C = 0 exactly at rest.
    m_p = m_rest;
    packPositions();
    const IsometricBatch<float> b = isometricBatch(m_isoP, m_isoKF, m_isoWKF, m_isoRestF,
                                                   m_isoAlphaTildeF, m_isoScaleF, m_lambdaIsoF);
    forEachIndependentRun(m_isoColours, [&](size_t i, size_t e) {
      isometricLengthsColour(p4f(), b, i, e, m_isoRestF.data());
    });
  }
}

void PbdModel::refreshIsometricHotData(Real dt) {
  const Real invDt2 = 1.0 / (dt * dt);
  for (size_t i = 0; i < m_iso.size(); ++i) {
    const IsometricHinge& h = m_iso[i];
    Real denom = m_iso[i].compliance * invDt2;
    m_isoAlphaTilde[i] = denom;
    for (int k = 0; k < 4; ++k) {
      const Real w = m_w[h.p[k]];
      m_isoWK[k][i] = w * h.K[k];
      denom += w * h.K[k] * h.K[k];
    }
    m_isoScale[i] = denom > 0 ? m_kBend / denom : 0.0;
  }
  if (m_f32 && !m_iso.empty()) {
    for (size_t i = 0; i < m_iso.size(); ++i) {
      for (int k = 0; k < 4; ++k) m_isoWKF[k][i] = static_cast<float>(m_isoWK[k][i]);
      m_isoAlphaTildeF[i] = static_cast<float>(m_isoAlphaTilde[i]);
      m_isoScaleF[i] = static_cast<float>(m_isoScale[i]);
    }
  }
}

void PbdModel::projectIsometric() {
  const auto sweep = [&](auto* x4, const auto& b) {
    forEachIndependentRun(m_isoColours, [&](size_t i, size_t e) {
      m_degenerate += projectIsometricColour(x4, b, i, e);
    });
  };
  if (m_f32)
    sweep(p4f(), isometricBatch(m_isoP, m_isoKF, m_isoWKF, m_isoRestF, m_isoAlphaTildeF,
                                m_isoScaleF, m_lambdaIsoF));
  else
    sweep(p4(), isometricBatch(m_isoP, m_isoK, m_isoWK, m_isoRest, m_isoAlphaTilde, m_isoScale,
                               m_lambdaIso));
}

// g_k lambda / dt^2 on the grasped nodes of the hinges that touch one (as for the other
// constraints, see computeGraspForces()).
void PbdModel::addIsometricGraspForces(Real invDt2, MatX3& nodeForce) {
  for (int i : m_graspIso) {
    const IsometricHinge& h = m_iso[i];
    Vec3 x[4], g[4];
    for (int k = 0; k < 4; ++k) x[k] = m_x.row(h.p[k]);
    Real C;
    if (!isometricBendingConstraint(x, h.K, h.rest, C, g)) continue;
    const Real lambda = m_f32 ? static_cast<Real>(m_lambdaIsoF[i]) : m_lambdaIso[i];
    for (int k = 0; k < 4; ++k)
      if (m_graspMask[h.p[k]]) nodeForce.row(h.p[k]) += (lambda * invDt2) * g[k].transpose();
  }
}

}  // namespace deform::pbd
