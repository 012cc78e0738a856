// Example out-of-tree deformbench plugin: "tethered", a deliberately simple model that shows the
// whole plugin interface (declared parameters, capabilities, init/step/reset, counts) without any
// tissue mechanics to get in the way. It is a toy, not a tissue model: its errors in a comparison
// say nothing about tissue.
//
// Each vertex i of the organ surface is a particle of mass m_i = rho * Vol / N (the organ's mass
// shared equally), tied to its rest position X_i by a zero-length spring of stiffness k and
// damped in proportion to its mass (coefficient c). With gravity g and a point force f_i:
//
//   m_i dv/dt = m_i g + f_i - k (x_i - X_i) - c m_i v_i,     dx/dt = v_i
//
// integrated by backward Euler, which for these independent linear particles is solved exactly
// per particle and is unconditionally stable:
//
//   v' = (v + dt (g + f_i/m_i - (k/m_i)(x - X))) / (1 + dt c + dt^2 k/m_i),   x' = x + dt v'
//
// Grasped particles follow their targets; pinned particles stay at rest. The model's nodes are
// the surface vertices themselves (identity mapping), so surface() is nodes(), and the harness's
// grasps and loads (given on the surface) act on the nodes directly.
#include <deform/sdk/registry.h>

#include <cmath>
#include <memory>
#include <utility>
#include <vector>

namespace {

using deform::MatX3;
using deform::Real;
using deform::Vec3;

class TetheredModel final : public deform::Model {
 public:
  void init(const deform::ModelSetup& setup) override {
    const deform::SurfaceMesh& s = setup.organ.surface;
    if (s.numVertices() == 0) {
      throw deform::InputError(setup.organ.source, "organ.mesh", "the surface has no vertices");
    }
    const Real volume = deform::signedVolume(s.V, s.F);
    if (!(volume > 0)) {
      throw deform::InputError(setup.organ.source, "organ.mesh",
                               "tethered needs a closed, outward-oriented surface (volume <= 0)");
    }
    m_stiffness = setup.params.real("stiffness");
    m_damping = setup.params.real("damping");
    m_mass = setup.organ.material.density * volume / s.numVertices();
    m_rest = s.V;
    // The fixed region (boxes, listed surface vertices) resolved against this model's nodes by
    // the SDK, the same way for every model.
    m_pinned.assign(s.numVertices(), false);
    for (int n : deform::fixedNodeIndices(m_rest, setup.organ.fixed, s)) m_pinned[n] = true;
    reset();
  }

  deform::StepStatus step(const deform::StepInput& in) override {
    const Real dt = in.dt;
    // The harness spreads each load over a patch of surface vertices (per-vertex shares of its
    // force); loadsOnNodes maps them to the nodes carrying those vertices (here: the same index).
    MatX3 force = MatX3::Zero(m_x.rows(), 3);
    deform::loadsOnNodes(in.loads, {}, m_loadShares);
    for (const auto& [n, f] : m_loadShares) {
      if (n >= 0 && n < m_x.rows()) force.row(n) += f.transpose();
    }
    const Real kOverM = m_stiffness / m_mass;
    const Real denom = 1.0 + dt * m_damping + dt * dt * kOverM;
    for (Eigen::Index i = 0; i < m_x.rows(); ++i) {
      if (m_pinned[i]) continue;
      const Vec3 x = m_x.row(i).transpose(), v = m_v.row(i).transpose();
      const Vec3 rest = m_rest.row(i).transpose();
      const Vec3 accel = in.gravity + force.row(i).transpose() / m_mass - kOverM * (x - rest);
      const Vec3 vNew = (v + dt * accel) / denom;
      m_v.row(i) = vNew.transpose();
      m_x.row(i) = (x + dt * vNew).transpose();
    }
    for (const deform::GraspInput& g : in.grasps) {
      for (size_t j = 0; j < g.vertices.size(); ++j) {
        const int n = g.vertices[j];
        if (n < 0 || n >= m_x.rows() || m_pinned[n]) continue;
        m_v.row(n) = (g.targets.row(Eigen::Index(j)) - m_x.row(n)) / dt;
        m_x.row(n) = g.targets.row(Eigen::Index(j));
      }
    }
    return m_x.allFinite() ? deform::StepStatus::Ok : deform::StepStatus::Diverged;
  }

  const MatX3& nodes() const override { return m_x; }
  const MatX3& surface() const override { return m_x; }

  void reset() override {
    m_x = m_rest;
    m_v = MatX3::Zero(m_rest.rows(), 3);
  }

  deform::Counts counts() const override {
    return {{"nodes", m_x.rows()}, {"springs", m_x.rows()}};
  }

 private:
  Real m_stiffness = 0, m_damping = 0, m_mass = 0;
  MatX3 m_rest, m_x, m_v;
  std::vector<bool> m_pinned;
  std::vector<std::pair<int, Vec3>> m_loadShares;  // kept between steps: no allocation per step
};

}  // namespace

DEFORM_PLUGIN(registry) {
  deform::ModelInfo info;
  info.name = "tethered";
  info.description =
      "toy example: surface particles tied to their rest positions by damped springs";
  info.citation = "none (deformbench example plugin)";
  info.version = "1.0";
  info.capabilities = {deform::Capability::Grasp, deform::Capability::PointForce,
                       deform::Capability::Gravity};
  info.params = {
      deform::ParamSpec::real("stiffness", "N/m", 50.0, 1e-6, 1e9,
                              "stiffness k of each particle's tether to its rest position"),
      deform::ParamSpec::real("damping", "1/s", 5.0, 0.0, 1e6,
                              "mass-proportional damping coefficient c"),
  };
  info.create = [] { return std::make_unique<TetheredModel>(); };
  registry.add(std::move(info));
}
