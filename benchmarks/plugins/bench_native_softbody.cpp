// Our PBD against Bullet's btSoftBody driven natively (issue 38 item 5): Bullet's own API, its
// default single-precision build, no plugin interface and no deformbench code in its step, on the
// same surface mesh as PBD and timed in the same run.
//
// Meshes: the built-in liver phantom at ~2.2k vertices (makePhantom("liver", 0.27)) and, where
// ../shared/eval-data is present, SOFA's liver-smooth.obj (2,194 vertices, centimetres). Both
// models: stretch along every surface edge and one global volume constraint, 10 solver
// iterations, dt = 1 ms, gravity, the bottom quarter of the height pinned, the vertices within
// 0.3 of the height of the top centre grasped and moved kinematically up by 0.4 of the height
// over 500 steps and back (triangle wave). Each benchmark iteration is one step.
//
// btSoftBody is set up as its examples set up a closed surface: btSoftBodyHelpers::
// CreateFromTriMesh (one link per edge, shuffled), setTotalMass from the faces, setPose(volume),
// kVC for the volume, piterations = 10, its own collision off (PBD has none here either); pinned
// and grasped nodes have mass 0, grasped ones get the velocity that lands them on the target.
//
// The cases run interleaved, 5 repetitions each (Google Benchmark's random interleaving, unless
// the command line sets it); at the end the program prints, for each mesh, the median step of
// every timed step of each model and their ratio.
//
//   bench_native_softbody
//   bench_native_softbody --benchmark_filter=phantom
#include "pbd_model.h"

#include <deform/geometry/mesh_io.h>
#include <deform/geometry/phantom.h>

#include <BulletSoftBody/btDefaultSoftBodySolver.h>
#include <BulletSoftBody/btSoftBody.h>
#include <BulletSoftBody/btSoftBodyHelpers.h>
#include <BulletSoftBody/btSoftBodyRigidBodyCollisionConfiguration.h>
#include <BulletSoftBody/btSoftRigidDynamicsWorld.h>
#include <benchmark/benchmark.h>
#include <btBulletDynamicsCommon.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <string>
#include <vector>

namespace {

using namespace deform;

constexpr double kDt = 1e-3;
constexpr int kIterations = 10;

/// Every timed step of a case, across repetitions: "<model>/<mesh>" -> microseconds.
std::map<std::string, std::vector<double>>& stepTimes() {
  static std::map<std::string, std::vector<double>> t;
  return t;
}

struct Setup {
  Organ organ;
  std::vector<int> grasped;
  MatX3 graspRest;
  double lift = 0;  ///< m, the top of the triangle wave
};

/// The mesh, the pinned slab and the grasp. Empty surface: the mesh is not available.
Setup makeSetup(const std::string& mesh) {
  Setup s;
  s.organ.material = {5500, 0.3, 1000};
  if (mesh == "phantom") {
    s.organ.source = "phantom:liver";
    s.organ.surface = makePhantom("liver", 0.27);
  } else {
    const auto file = std::filesystem::path(__FILE__).parent_path() /
                      "../../../shared/eval-data/liver-smooth.obj";
    if (!std::filesystem::exists(file)) return s;
    s.organ.source = file.string();
    s.organ.surface = readMesh(file.string()).surface;
    s.organ.surface.V *= 0.01;  // centimetres
  }
  const Box b = boundingBox(s.organ.surface.V);
  const double height = b.size().z();
  Box slab = b;
  slab.lo -= Vec3::Constant(0.01);
  slab.hi.x() += 0.01;
  slab.hi.y() += 0.01;
  slab.hi.z() = b.lo.z() + 0.25 * height;
  s.organ.fixed.boxes.push_back(slab);
  const Vec3 top(b.center().x(), b.center().y(), b.hi.z());
  for (int n = 0; n < s.organ.surface.numVertices(); ++n)
    if ((s.organ.surface.V.row(n).transpose() - top).norm() < 0.3 * height) s.grasped.push_back(n);
  s.graspRest.resize(Eigen::Index(s.grasped.size()), 3);
  for (size_t k = 0; k < s.grasped.size(); ++k)
    s.graspRest.row(Eigen::Index(k)) = s.organ.surface.V.row(s.grasped[k]);
  s.lift = 0.4 * height;
  return s;
}

/// The grasp's height above rest at `step` (triangle wave, 1000 steps per period).
double liftAt(const Setup& s, long long step) {
  const int phase = static_cast<int>(step % 1000);
  return s.lift * (phase < 500 ? phase : 1000 - phase) / 500.0;
}

/// Times `step(k)` once per benchmark iteration after 5 warm-up steps; records every step.
template <class StepFn>
void timeSteps(benchmark::State& state, const std::string& name, StepFn step) {
  for (int k = 0; k < 5; ++k) step(k);
  std::vector<double>& times = stepTimes()[name];
  long long k = 5;
  for (auto _ : state) {
    const auto t0 = std::chrono::steady_clock::now();
    step(k++);
    times.push_back(
        std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
  }
}

void Pbd(benchmark::State& state, const std::string& mesh) {
  const Setup s = makeSetup(mesh);
  if (s.organ.surface.numVertices() == 0) {
    state.SkipWithError("eval data not available");
    return;
  }
  pbd::PbdConfig c;  // defaults (XPBD, float32), stretch + global volume, 10 sweeps
  c.iterations = kIterations;
  c.bending = false;
  c.volume = true;
  pbd::PbdModel m;
  m.init(s.organ, c);
  StepInput in;
  in.dt = kDt;
  in.gravity = Vec3(0, 0, -9.81);
  GraspInput g;
  g.vertices = s.grasped;
  g.targets = s.graspRest;
  in.grasps = {g};
  timeSteps(state, "pbd/" + mesh, [&](long long k) {
    in.grasps[0].targets.col(2) = s.graspRest.col(2).array() + liftAt(s, k);
    benchmark::DoNotOptimize(m.step(in));
  });
  state.counters["nodes"] = double(s.organ.surface.numVertices());
  state.counters["constraints"] = double(m.counts().at("constraints"));
}

/// A btSoftRigidDynamicsWorld holding one btSoftBody, as Bullet's soft-body demos build it.
struct BulletWorld {
  btSoftBodyRigidBodyCollisionConfiguration collision;
  btCollisionDispatcher dispatcher{&collision};
  btDbvtBroadphase broadphase;
  btSequentialImpulseConstraintSolver solver;
  btSoftRigidDynamicsWorld world{&dispatcher, &broadphase, &solver, &collision};
  std::unique_ptr<btSoftBody> body;
  ~BulletWorld() {
    if (body) world.removeSoftBody(body.get());
  }
};

void NativeBtSoftBody(benchmark::State& state, const std::string& mesh) {
  const Setup s = makeSetup(mesh);
  if (s.organ.surface.numVertices() == 0) {
    state.SkipWithError("eval data not available");
    return;
  }
  const SurfaceMesh& surf = s.organ.surface;
  std::vector<btScalar> xyz;
  for (int n = 0; n < surf.numVertices(); ++n)
    for (int d = 0; d < 3; ++d) xyz.push_back(btScalar(surf.V(n, d)));
  std::vector<int> tris(surf.F.data(), surf.F.data() + surf.F.size());  // row-major int rows
  BulletWorld w;
  btSoftBodyWorldInfo& info = w.world.getWorldInfo();
  info.m_gravity = btVector3(0, 0, btScalar(-9.81));
  info.m_sparsesdf.Initialize();
  w.body.reset(
      btSoftBodyHelpers::CreateFromTriMesh(info, xyz.data(), tris.data(), int(surf.numFaces())));
  btSoftBody& b = *w.body;
  b.m_cfg.piterations = kIterations;
  b.m_cfg.kDP = btScalar(1e-3);  // PBD's 1/s damping at 1 ms
  b.m_cfg.kVC = 10;              // volume conservation
  b.m_cfg.collisions = 0;
  const double volume = std::abs(signedVolume(surf.V, surf.F));
  b.setTotalMass(btScalar(s.organ.material.density * volume), true);
  for (int n : fixedNodeIndices(surf.V, s.organ.fixed, surf)) b.setMass(n, 0);
  for (int n : s.grasped) b.setMass(n, 0);
  b.setPose(true, false);
  b.setActivationState(DISABLE_DEACTIVATION);
  w.world.addSoftBody(&b);
  timeSteps(state, "btSoftBody/" + mesh, [&](long long k) {
    const double lift = liftAt(s, k + 1);
    for (size_t i = 0; i < s.grasped.size(); ++i) {
      btSoftBody::Node& node = b.m_nodes[s.grasped[i]];
      const auto r = s.graspRest.row(Eigen::Index(i));
      const btVector3 target(btScalar(r(0)), btScalar(r(1)), btScalar(r(2) + lift));
      node.m_v = (target - node.m_x) / btScalar(kDt);
    }
    w.world.stepSimulation(btScalar(kDt), 0, btScalar(kDt));
  });
  state.counters["nodes"] = double(b.m_nodes.size());
  state.counters["links"] = double(b.m_links.size());
}

BENCHMARK_CAPTURE(Pbd, phantom, std::string("phantom"))
    ->Unit(benchmark::kMillisecond)
    ->MinTime(1.0);
BENCHMARK_CAPTURE(NativeBtSoftBody, phantom, std::string("phantom"))
    ->Unit(benchmark::kMillisecond)
    ->MinTime(1.0);
BENCHMARK_CAPTURE(Pbd, liver_smooth, std::string("liver_smooth"))
    ->Unit(benchmark::kMillisecond)
    ->MinTime(1.0);
BENCHMARK_CAPTURE(NativeBtSoftBody, liver_smooth, std::string("liver_smooth"))
    ->Unit(benchmark::kMillisecond)
    ->MinTime(1.0);

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<char*> args(argv, argv + argc);
  bool own = false;  // interleaved repetitions unless the command line says otherwise
  for (int i = 1; i < argc; ++i)
    own |= std::string(argv[i]).rfind("--benchmark_repetitions", 0) == 0 ||
           std::string(argv[i]).rfind("--benchmark_enable_random_interleaving", 0) == 0;
  std::string reps = "--benchmark_repetitions=5", mix = "--benchmark_enable_random_interleaving";
  if (!own) {
    args.push_back(reps.data());
    args.push_back(mix.data());
  }
  int n = int(args.size());
  args.push_back(nullptr);  // argv[argc]
  benchmark::Initialize(&n, args.data());
  if (benchmark::ReportUnrecognizedArguments(n, args.data())) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  const auto& t = stepTimes();
  for (const char* mesh : {"phantom", "liver_smooth"}) {
    const auto p = t.find(std::string("pbd/") + mesh);
    const auto b = t.find(std::string("btSoftBody/") + mesh);
    if (p == t.end() || b == t.end() || p->second.empty() || b->second.empty()) continue;
    const double mp = median(p->second), mb = median(b->second);
    std::printf("%s: median step btSoftBody %.1f us, pbd %.1f us: pbd %.2fx faster\n", mesh, mb, mp,
                mb / mp);
  }
  return 0;
}
