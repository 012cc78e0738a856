// Google Benchmark of one step of each model on the default scene's organ: the 8,122-vertex liver
// phantom of scenes/liver_grasp_lift.json (its material and support), held by the scene's
// grasper and lifted slowly, gravity as the scene gives it (none). The plugins are loaded from the
// build tree, as the harness loads them, so one run of this program times every model on the
// same machine state: the ratios to `pbd` are what the targets compare.
//   liver8k_bench [--benchmark_filter=...]   (the repetitions' median is the headline)
// A plugin that is not built is skipped with a message.
#include <benchmark/benchmark.h>
#include <deform/engine/interaction.h>
#include <deform/engine/plugin_loader.h>
#include <deform/engine/scene.h>
#include <deform/sdk/cache.h>
#include <deform/sdk/mesh.h>

#include <cstdio>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace {

using namespace deform;
using json = nlohmann::json;

struct Case {
  std::string name, plugin;
  json params;
};

const std::vector<Case>& cases() {
  static const std::vector<Case> c = {
      {"pbd", "pbd", json::object()},
      {"pbd_bending_isometric", "pbd", {{"bending", true}}},
      {"pbd_bending_dihedral", "pbd", {{"bending", true}, {"bending_model", "dihedral"}}},
      {"massspring_local_global", "massspring", {{"integrator", "local_global"}}},
      {"massspring_local_global_3it",
       "massspring",
       {{"integrator", "local_global"}, {"local_global_iterations", 3}}},
      // Liu et al.'s plain alternation from y, 10 iterations (local_global's default before the
      // Chebyshev acceleration and warm start), on the same solver.
      {"massspring_local_global_plain10",
       "massspring",
       {{"integrator", "local_global"},
        {"local_global_iterations", 10},
        {"local_global_acceleration", "none"},
        {"local_global_warm_start", false}}},
      {"massspring_implicit_euler", "massspring", {{"integrator", "implicit_euler"}}},
      // One explicit step (the cost per substep of G3's automatic substepping; at the scene's
      // dt it may diverge, counted in diverged_steps).
      {"massspring_symplectic_euler", "massspring", json::object()},
      {"hybrid_fem_pbd", "hybrid_fem_pbd", json::object()},
      // The hybrid's double-precision surface projection and grasp response (before G7 item 3).
      {"hybrid_fem_pbd_float64", "hybrid_fem_pbd", {{"precision", "float64"}}},
      {"hybrid_fem_pbd_dihedral", "hybrid_fem_pbd", {{"bending_model", "dihedral"}}},
      {"fem_hex", "fem_hex", json::object()},
  };
  return c;
}

struct World {
  Scene scene = parseSceneFile(DEFORM_SOURCE_DIR "/scenes/liver_grasp_lift.json");
  Organ organ = loadOrgan(scene);
  PluginLoader loader;
  Cache cache{Cache::defaultDir()};
};

World& world() {
  static World w;
  return w;
}

void runCase(benchmark::State& state, const Case& c) {
  World& w = world();
  const ModelInfo* info = nullptr;
  try {
    info = &w.loader.load(c.plugin);
  } catch (const std::exception& e) {
    state.SkipWithError((c.plugin + " not available: " + e.what()).c_str());
    return;
  }
  const ParamValues params = resolveParams(info->params, c.params, "liver8k_bench", "/params");
  std::unique_ptr<Model> m = info->create();
  m->init(ModelSetup{w.organ, params, w.cache, w.scene.dt, w.scene.gravity});
  // The scene's grasp as the harness picks it: every rest-surface vertex within the radius of
  // where the jaws close (at least the nearest) follows the tool.
  const ToolSpec& tool = w.scene.tools.at(0);
  const Vec3 closeAt = tool.trajectory.at(1).pos;
  const MatX3 rest = w.organ.surface.V;
  GraspInput g;
  g.vertices = graspedSurfaceVertices(rest, closeAt, tool.radius);
  g.targets.resize(static_cast<Eigen::Index>(g.vertices.size()), 3);
  StepInput in;
  in.dt = w.scene.dt;
  in.gravity = w.scene.gravity;
  Real lift = 0;
  const auto advance = [&](Real dz) {
    lift = std::min<Real>(lift + dz, 0.025);  // the scene lifts 25 mm, then holds
    for (size_t k = 0; k < g.vertices.size(); ++k)
      g.targets.row(k) = rest.row(g.vertices[k]) + Vec3(0, 0, lift).transpose();
    in.grasps = {g};
  };
  for (int s = 0; s < 100; ++s) {  // warm-up: 5 mm in 0.1 s (the scene's lifting speed)
    advance(5e-5);
    if (m->step(in) != StepStatus::Ok) {
      state.SkipWithError("diverged during the warm-up");
      return;
    }
  }
  std::map<std::string, double> phase;
  long long steps = 0, diverged = 0;
  for (auto _ : state) {
    advance(5e-5);
    diverged += m->step(in) != StepStatus::Ok;
    for (const auto& [k, v] : m->phaseTimes()) phase[k] += v;
    ++steps;
  }
  for (const auto& [k, v] : phase) state.counters[k + "_ms"] = v / double(steps);
  state.counters["nodes"] = double(rest.rows());
  state.counters["grasped"] = double(g.vertices.size());
  state.counters["diverged_steps"] = double(diverged);
}

}  // namespace

int main(int argc, char** argv) {
  for (const Case& c : cases())
    benchmark::RegisterBenchmark(("Liver8k/" + c.name).c_str(),
                                 [&c](benchmark::State& s) { runCase(s, c); })
        ->Unit(benchmark::kMillisecond)
        ->MinTime(0.3)
        ->Repetitions(5)
        ->ReportAggregatesOnly(true);
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
