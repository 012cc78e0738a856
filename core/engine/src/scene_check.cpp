#include <deform/distance.h>
#include <deform/error.h>
#include <deform/scene.h>

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

}  // namespace deform
