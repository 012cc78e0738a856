// Contact for the hybrid model (deform/sdk/contact.h): surface vertices that penetrate an
// instrument are prescribed onto its surface like grasped vertices (the coarse FEM and the surface
// PBD both see them). The step is re-run from the same start state up to 3 times, adding the
// vertices the previous run left inside (control vertices follow the coarse FEM and can be carried
// in by it); then the surface triangles still within the contact thickness are projected out (their
// inward normal velocity removed, Coulomb friction from the step's start): this also catches a tool
// thinner than the vertex spacing, which no vertex would report.
#include "hybrid_model.h"

#include <deform/sdk/contact.h>

namespace deform::hybrid_fem_pbd {

StepStatus HybridModel::stepWithContact(const StepInput& in) {
  const MatX3 x0 = m_surf.x, v0 = m_v;
  m_inContactStep = true;
  ContactProxy proxy;
  proxy.nodes = &m_surf.x;
  ContactConstraintSolver solver;
  solver.solve = [&](const StepInput& x) {
    m_surf.x = x0;
    m_v = v0;
    return step(x);
  };
  solver.immovable = m_fixedFine;
  solver.maxRounds = 3;
  StepStatus status = StepStatus::Ok;
  try {
    status = solveWithContactConstraints(*in.contact, proxy, in, solver);
  } catch (...) {
    m_inContactStep = false;
    throw;
  }
  m_inContactStep = false;
  if (status != StepStatus::Ok) return status;
  if (m_w.size() == m_surf.x.rows()) {
    const MatX3i& faces = m_surf.faces();
    proxy.invMass = &m_w;
    proxy.velocity = m_v.data();
    proxy.atStepStart = &x0;
    proxy.faces = &faces;
    respondToContact(*in.contact, proxy, ContactResponse::Project, in.dt);
  }
  return m_surf.x.allFinite() ? StepStatus::Ok : StepStatus::Diverged;
}

}  // namespace deform::hybrid_fem_pbd
