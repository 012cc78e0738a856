// PbdModel's tet volume constraints (deform/kernels/tet_volume_batch.h): the tets in colour order
// as structure of arrays, projected colour by colour on the solver's packed positions (float or
// double, like the distance constraints and the hinges), so a sweep needs no unpacking for them.
#include "pbd_model.h"

namespace deform::pbd {

void PbdModel::initTets() {
  const size_t n = m_tet.size();
  for (int k = 0; k < 4; ++k) {
    m_tetP[k].resize(n);
    for (size_t i = 0; i < n; ++i) m_tetP[k][i] = 4 * m_tet[i].p[k];
    m_tetW[k].assign(n, 0.0);
    m_tetWF[k].clear();
  }
  m_tetRest.resize(n);
  m_tetFloor.resize(n);
  for (size_t i = 0; i < n; ++i) {
    m_tetRest[i] = m_tet[i].restVolume;
    m_tetFloor[i] = tetVolumeGradientFloor(m_tet[i].restVolume);
  }
  m_tetAlphaTilde.assign(n, 0.0);
  m_lambdaTet.assign(n, 0.0);
  m_tetRestF.clear();
  m_tetFloorF.clear();
  m_tetAlphaTildeF.clear();
  m_lambdaTetF.clear();
  if (!m_f32 || n == 0) return;
  for (int k = 0; k < 4; ++k) m_tetWF[k].assign(n, 0.0f);
  m_tetFloorF.assign(m_tetFloor.begin(), m_tetFloor.end());
  m_tetAlphaTildeF.assign(n, 0.0f);
  m_lambdaTetF.assign(n, 0.0f);
  m_tetRestF.assign(n, 0.0f);
  // Rest volumes measured in float from the packed rest positions, colour by colour as
  // projectTets() projects them: C = 0 exactly at rest.
  m_p = m_rest;
  packPositions();
  const TetVolumeBatch<float> b = tetVolumeBatch(m_tetP, m_tetWF, m_tetRestF, m_tetFloorF,
                                                 m_tetAlphaTildeF, m_lambdaTetF, 1.0f);
  forEachIndependentRun(m_tetColours, [&](size_t i, size_t e) {
    tetVolumesColour(p4f(), b, i, e, m_tetRestF.data());
  });
}

void PbdModel::refreshTetHotData(Real dt) {
  const Real invDt2 = 1.0 / (dt * dt);
  for (size_t i = 0; i < m_tet.size(); ++i) {
    m_tetAlphaTilde[i] = m_tet[i].compliance * invDt2;
    for (int k = 0; k < 4; ++k) m_tetW[k][i] = m_w[m_tet[i].p[k]];
  }
  if (!m_f32) return;
  for (size_t i = 0; i < m_tet.size(); ++i) {
    m_tetAlphaTildeF[i] = static_cast<float>(m_tetAlphaTilde[i]);
    for (int k = 0; k < 4; ++k) m_tetWF[k][i] = static_cast<float>(m_tetW[k][i]);
  }
}

void PbdModel::projectTets() {
  const auto sweep = [&](auto* x4, const auto& b) {
    forEachIndependentRun(m_tetColours, [&](size_t i, size_t e) {
      m_degenerate += projectTetVolumeColour(x4, b, i, e);
    });
  };
  if (m_f32)
    sweep(p4f(), tetVolumeBatch(m_tetP, m_tetWF, m_tetRestF, m_tetFloorF, m_tetAlphaTildeF,
                                m_lambdaTetF, static_cast<float>(m_kVolume)));
  else
    sweep(p4(), tetVolumeBatch(m_tetP, m_tetW, m_tetRest, m_tetFloor, m_tetAlphaTilde, m_lambdaTet,
                               m_kVolume));
}

}  // namespace deform::pbd
