// Fixture model: rigid "follow the grasp". The surface translates rigidly by gain times the mean
// displacement that the grasps ask for (their targets minus the grasped nodes' current
// positions); with no grasp it stays where it is. Enough to check that a loaded factory builds a
// working Model.
#pragma once

#include <deform/sdk/registry.h>

#include <limits>
#include <memory>
#include <string>

namespace deform::fixture {

/// A model whose nodes (its organ's surface vertices) stay at rest: the base of the fixtures,
/// which add what they do (follow the grasp, crash, hang).
class StillModel : public Model {
 public:
  void init(const ModelSetup& setup) override { m_x = m_rest = setup.organ.surface.V; }
  StepStatus step(const StepInput&) override { return StepStatus::Ok; }
  const MatX3& nodes() const override { return m_x; }
  const MatX3& surface() const override { return m_x; }
  void reset() override { m_x = m_rest; }
  Counts counts() const override { return {{"nodes", m_x.rows()}}; }

 protected:
  MatX3 m_x, m_rest;
};

/// The toy: rigid follow-the-grasp (see the file comment).
class RigidFollowModel final : public StillModel {
 public:
  void init(const ModelSetup& setup) override {
    StillModel::init(setup);
    m_gain = setup.params.real("gain");
    m_divergeBelow = setup.params.real("diverge_below");
    m_unconvergedBelow = setup.params.real("unconverged_below");
  }
  StepStatus step(const StepInput& in) override {
    Vec3 sum = Vec3::Zero();
    long long n = 0;
    for (const GraspInput& g : in.grasps) {
      for (size_t j = 0; j < g.vertices.size(); ++j) {
        sum += (g.targets.row(Eigen::Index(j)) - m_x.row(g.vertices[j])).transpose();
        ++n;
      }
    }
    if (n > 0) m_x.rowwise() += (m_gain * sum / Real(n)).transpose();
    // A stand-in for an unstable parameter region (calibration tests): NaN positions.
    if (m_gain < m_divergeBelow) m_x(0, 0) = std::numeric_limits<Real>::quiet_NaN();
    return StepStatus::Ok;
  }
  // A stand-in for a solver that gives up (calibration tests): the run is invalid.
  NumericCounters numericCounters() const override {
    return {{"unconverged_steps", m_gain < m_unconvergedBelow ? 1 : 0}};
  }

 private:
  Real m_gain = 1;
  Real m_divergeBelow = 0;
  Real m_unconvergedBelow = 0;
};

inline ModelInfo toyInfo(const std::string& name) {
  ModelInfo info;
  info.name = name;
  info.description = "loader test fixture: rigid follow-the-grasp";
  info.citation = "none";
  info.version = "0.1";
  info.capabilities = {Capability::Grasp};
  ParamSpec gain = ParamSpec::real("gain", "1", 1.0, 0.0, 1.0, "fraction of the grasp motion");
  // "toy" has a calibratable parameter (calibration tests), the others none.
  if (name == "toy") gain = gain.calibrate(0.05, 1.0, ParamScale::Linear);
  info.params = {gain, ParamSpec::integer("iterations", 20, 1, 1000, "unused"),
                 ParamSpec::choice("mode", "rigid", {"rigid", "none"}, "unused"),
                 ParamSpec::real("diverge_below", "1", 0.0, 0.0, 1.0,
                                 "NaN positions when gain is below this (calibration tests)"),
                 ParamSpec::real("unconverged_below", "1", 0.0, 0.0, 1.0,
                                 "reports a solve that did not converge when gain is below this "
                                 "(calibration tests: the run is invalid)")};
  info.create = [] { return std::make_unique<RigidFollowModel>(); };
  return info;
}

}  // namespace deform::fixture
