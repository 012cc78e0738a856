// Fixture model: rigid "follow the grasp". The surface translates rigidly by gain times the mean
// displacement that the grasps ask for (their targets minus the grasped nodes' current
// positions); with no grasp it stays where it is. Enough to check that a loaded factory builds a
// working Model.
#pragma once

#include <deform/registry.h>

#include <memory>
#include <string>

namespace deform::fixture {

class RigidFollowModel final : public Model {
 public:
  void init(const ModelSetup& setup) override {
    m_rest = setup.organ.surface.V;
    m_gain = setup.params.real("gain");
    reset();
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
    return StepStatus::Ok;
  }
  const MatX3& nodes() const override { return m_x; }
  const MatX3& surface() const override { return m_x; }
  void reset() override { m_x = m_rest; }
  Counts counts() const override { return {{"nodes", m_x.rows()}}; }

 private:
  MatX3 m_rest, m_x;
  Real m_gain = 1;
};

inline ModelInfo toyInfo(const std::string& name) {
  ModelInfo info;
  info.name = name;
  info.description = "loader test fixture: rigid follow-the-grasp";
  info.citation = "none";
  info.version = "0.1";
  info.capabilities = {Capability::Grasp};
  info.params = {ParamSpec::real("gain", "1", 1.0, 0.0, 1.0, "fraction of the grasp motion"),
                 ParamSpec::integer("iterations", 20, 1, 1000, "unused"),
                 ParamSpec::choice("mode", "rigid", {"rigid", "none"}, "unused")};
  info.create = [] { return std::make_unique<RigidFollowModel>(); };
  return info;
}

}  // namespace deform::fixture
