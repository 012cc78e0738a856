// PbdModel's tet volume constraints (deform/kernels/tet_volume_batch.h): the tets in colour order
// as structure of arrays, projected colour by colour on the solver's packed positions (float or
// double, like the distance constraints and the hinges), so a sweep needs no unpacking for them.
#include "pbd_model.h"

#include <array>

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
  const TetVolumeBatch<float> b{
      {m_tetP[0].data(), m_tetP[1].data(), m_tetP[2].data(), m_tetP[3].data()},
      {m_tetWF[0].data(), m_tetWF[1].data(), m_tetWF[2].data(), m_tetWF[3].data()},
      m_tetRestF.data(),
      m_tetFloorF.data(),
      m_tetAlphaTildeF.data(),
      m_lambdaTetF.data(),
      1.0f};
  for (size_t c = 0; c + 1 < m_tetColours.size(); ++c) {
    const size_t b0 = m_tetColours[c], e = m_tetColours[c + 1];
    for (size_t i = b0; i < e; i = (c == 63 ? i + 1 : e))
      tetVolumesColour(p4f(), b, i, c == 63 ? i + 1 : e, m_tetRestF.data());
  }
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
  const size_t nColours = m_tetColours.size() - 1;
  const auto sweep = [&](auto* x4, const auto& b) {
    for (size_t c = 0; c < nColours; ++c) {
      const size_t b0 = m_tetColours[c], e = m_tetColours[c + 1];
      if (c == 63) {  // overflow colour: not independent, one at a time
        for (size_t i = b0; i < e; ++i) m_degenerate += projectTetVolumeColour(x4, b, i, i + 1);
      } else {
        m_degenerate += projectTetVolumeColour(x4, b, b0, e);
      }
    }
  };
  const auto ptrs = [](auto& v) {
    return std::array{v[0].data(), v[1].data(), v[2].data(), v[3].data()};
  };
  const auto p = ptrs(m_tetP);
  if (m_f32) {
    const auto w = ptrs(m_tetWF);
    sweep(p4f(), TetVolumeBatch<float>{{p[0], p[1], p[2], p[3]},
                                       {w[0], w[1], w[2], w[3]},
                                       m_tetRestF.data(),
                                       m_tetFloorF.data(),
                                       m_tetAlphaTildeF.data(),
                                       m_lambdaTetF.data(),
                                       static_cast<float>(m_kVolume)});
  } else {
    const auto w = ptrs(m_tetW);
    sweep(p4(), TetVolumeBatch<Real>{{p[0], p[1], p[2], p[3]},
                                     {w[0], w[1], w[2], w[3]},
                                     m_tetRest.data(),
                                     m_tetFloor.data(),
                                     m_tetAlphaTilde.data(),
                                     m_lambdaTet.data(),
                                     m_kVolume});
  }
}

}  // namespace deform::pbd
