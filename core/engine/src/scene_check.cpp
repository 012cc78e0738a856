#include <deform/engine/scene.h>
#include <deform/geometry/distance.h>
#include <deform/sdk/error.h>

#include <cmath>
#include <cstdio>

namespace deform {

void checkGraspsReachOrgan(const Scene& scene, const Organ& organ) {
  bool anyGrasp = false;
  for (const ToolSpec& tool : scene.tools) anyGrasp |= tool.type == ToolType::Grasper;
  if (!anyGrasp || organ.surface.numFaces() == 0) return;
  const MeshDistance distance(organ.surface);
  for (size_t i = 0; i < scene.tools.size(); ++i) {
    const ToolSpec& tool = scene.tools[i];
    if (tool.type != ToolType::Grasper) continue;
    bool wasClosed = false;
    for (size_t k = 0; k < tool.trajectory.size(); ++k) {
      const KeyFrame& frame = tool.trajectory[k];
      const bool closes = frame.jawClosed && !wasClosed;
      wasClosed = frame.jawClosed;
      if (!closes) continue;
      // Inside the organ is a grasp of the volume's nodes; outside it must reach the surface.
      const Real d = distance.signedDistance(frame.pos);
      if (d <= tool.radius * (1 + 1e-9)) continue;
      char buf[160];
      std::snprintf(buf, sizeof buf,
                    "the grasper closes %.4g m outside the organ's surface, beyond its radius "
                    "%.4g m: it would grasp nothing",
                    d, tool.radius);
      throw InputError(scene.file,
                       "/tools/" + std::to_string(i) + "/trajectory/" + std::to_string(k) + "/pos",
                       buf);
    }
  }
}

void checkLoadsReachOrgan(const Scene& scene, const Organ& organ) {
  if (scene.loads.empty() || organ.surface.numFaces() == 0) return;
  const MeshDistance distance(organ.surface);
  for (size_t i = 0; i < scene.loads.size(); ++i) {
    const LoadSpec& load = scene.loads[i];
    if (load.type == LoadType::Traction) continue;  // a region, no point (parseScene checks it)
    // The harness spreads the load over the patch around the surface vertex nearest `at`: a
    // point farther than the patch's radius from the surface (outside or deep inside) would be
    // moved there in silence.
    const Real d = std::abs(distance.signedDistance(load.at));
    if (d <= load.radius * (1 + 1e-9)) continue;
    char buf[200];
    std::snprintf(buf, sizeof buf,
                  "the load is %.4g m %s the organ's surface, beyond its radius %.4g m: it would "
                  "be applied at the nearest surface vertex instead",
                  d, distance.signedDistance(load.at) > 0 ? "outside" : "inside", load.radius);
    throw InputError(scene.file, "/loads/" + std::to_string(i) + "/at", buf);
  }
}

Real couplingStabilityNumber(const CouplingParams& coupling, Real mass, Real dt) {
  return (coupling.stiffness * dt * dt + 2 * coupling.damping * dt) / mass;
}

void checkCouplingStability(const Scene& scene) {
  const auto check = [&](const CouplingParams& k, Real mass, const std::string& where) {
    const Real number = couplingStabilityNumber(k, mass, scene.dt);
    if (number < kCouplingStabilityLimit) return;
    char buf[400];
    std::snprintf(buf, sizeof buf,
                  "the virtual coupling is unstable at dt %.4g s: (k dt^2 + 2 c dt) / m = %.4g "
                  "with k %.4g N/m, c %.4g N s/m, m %.4g kg (k dt^2/m %.4g) must stay below 4, "
                  "the stability limit of ODE's semi-implicit Euler step; lower the stiffness or "
                  "the time step, or raise the mass",
                  scene.dt, number, k.stiffness, k.damping, mass,
                  k.stiffness * scene.dt * scene.dt / mass);
    throw InputError(scene.file, where, buf);
  };
  for (size_t i = 0; i < scene.tools.size(); ++i) {
    const ToolSpec& t = scene.tools[i];
    if (!t.dynamics) continue;
    // A grasper's jaws (a tenth of its mass each) are hinged to the shaft: the coupling moves
    // the whole assembly.
    const Real mass = t.dynamics->mass * (t.type == ToolType::Grasper ? 1.2 : 1.0);
    check(t.dynamics->coupling, mass, "/tools/" + std::to_string(i) + "/dynamics");
  }
  for (size_t j = 0; j < scene.objects.size(); ++j) {
    const ObjectSpec& o = scene.objects[j];
    if (o.trajectory.empty()) continue;  // a free object has no coupling
    check(o.coupling, o.mass, "/objects/" + std::to_string(j));
  }
}

}  // namespace deform
