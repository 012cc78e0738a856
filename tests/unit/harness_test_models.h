// Tiny in-test models for the interaction and runner tests (no plugin involved).
#pragma once

#include <deform/sdk/model.h>
#include <deform/sdk/registry.h>

#include <limits>
#include <stdexcept>
#include <vector>

namespace deform::testing {

/// Identity-mapped rigid body: its nodes are the organ's surface vertices; each step it
/// translates as a whole by the mean of (target - current) over every grasped node, ignores
/// gravity and loads. Faults can be injected at a given step (1-based count of steps taken).
class RigidTestModel : public Model {
 public:
  int nanAtStep = -1;      ///< surface becomes NaN at this step
  int throwAtStep = -1;    ///< step() throws at this step
  int runawayAtStep = -1;  ///< moves 1000 m at this step
  int reportDivergedAtStep = -1;
  bool throwInInit = false;
  bool ignoreGrasps = false;      ///< a model that holds nothing
  Vec3 drift = Vec3::Zero();      ///< m per step, always (a model that never settles)
  long long unconverged = 0;      ///< reported as numeric "unconverged_steps"
  NumericCounters extraNumeric;   ///< reported beside those
  long long inverted = -1;        ///< >= 0: reported as numeric "inverted_tets"
  long long elements = 0;         ///< > 0: reported as counts "elements"
  long long fixedNodes = -1;      ///< >= 0: reported as counts "fixed_nodes" (its own rule)
  bool shortSurface = false;      ///< surface() has one row too few (a broken mapping)
  bool graspForce = false;        ///< graspForces(): a zero force per grasp (else none)
  std::vector<StepInput> inputs;  ///< every input received
  std::vector<StepInput>* recordInto = nullptr;  ///< also appended here when set (outlives runs)

  void init(const ModelSetup& setup) override {
    if (throwInInit) throw InputError("test", "", "cannot handle this organ");
    m_rest = setup.organ.surface.V;
    m_x = m_rest;
    m_short = m_rest.topRows(m_rest.rows() - 1);
  }
  StepStatus step(const StepInput& in) override {
    inputs.push_back(in);
    if (recordInto) recordInto->push_back(in);
    ++m_steps;
    if (m_steps == throwAtStep) throw std::runtime_error("injected failure");
    Vec3 shift = Vec3::Zero();
    int n = 0;
    for (const GraspInput& g : in.grasps) {
      if (ignoreGrasps) break;
      for (size_t k = 0; k < g.vertices.size(); ++k) {
        shift += g.targets.row(k).transpose() - m_x.row(g.vertices[k]).transpose();
        ++n;
      }
    }
    if (n > 0) m_x.rowwise() += (shift / n).transpose();
    m_x.rowwise() += drift.transpose();
    if (m_steps == nanAtStep) m_x(0, 0) = std::numeric_limits<Real>::quiet_NaN();
    if (m_steps == runawayAtStep) m_x.rowwise() += Vec3(1000, 0, 0).transpose();
    m_phase["solve"] = 0.5;
    return m_steps == reportDivergedAtStep ? StepStatus::Diverged : StepStatus::Ok;
  }
  const MatX3& nodes() const override { return m_x; }
  std::vector<Vec3> graspForces() const override {
    return std::vector<Vec3>(graspForce && !inputs.empty() ? inputs.back().grasps.size() : 0,
                             Vec3::Zero());
  }
  const MatX3& surface() const override { return shortSurface ? m_short : m_x; }
  void reset() override {
    m_x = m_rest;
    m_steps = 0;
  }
  Counts counts() const override {
    Counts c{{"nodes", m_x.rows()}};
    if (elements > 0) c["elements"] = elements;
    if (fixedNodes >= 0) c["fixed_nodes"] = fixedNodes;
    return c;
  }
  PhaseTimes phaseTimes() const override { return m_phase; }
  NumericCounters numericCounters() const override {
    NumericCounters c{{"degenerate", 0}, {"unconverged_steps", unconverged}};
    if (inverted >= 0) c["inverted_tets"] = inverted;
    c.insert(extraNumeric.begin(), extraNumeric.end());
    return c;
  }

 private:
  MatX3 m_rest, m_x, m_short;
  int m_steps = 0;
  PhaseTimes m_phase;
};

/// A model whose nodes are a fixed given set (for attachment tests).
class FixedNodesModel : public Model {
 public:
  explicit FixedNodesModel(MatX3 nodes) : m_x(std::move(nodes)) {}
  void init(const ModelSetup&) override {}
  StepStatus step(const StepInput&) override { return StepStatus::Ok; }
  const MatX3& nodes() const override { return m_x; }
  const MatX3& surface() const override { return m_x; }
  void reset() override {}
  Counts counts() const override { return {{"nodes", m_x.rows()}}; }
  MatX3 m_x;
};

/// Closed outward tetrahedron of edge `a` with one corner at the origin.
inline SurfaceMesh tetSurface(Real a = 0.1) {
  SurfaceMesh m;
  m.V.resize(4, 3);
  m.V << 0, 0, 0, a, 0, 0, 0, a, 0, 0, 0, a;
  m.F.resize(4, 3);
  m.F << 0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3;
  return m;
}

}  // namespace deform::testing
