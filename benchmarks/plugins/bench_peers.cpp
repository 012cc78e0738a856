// Peer comparison in one run (Google Benchmark): time per step of
//   - our PBD (plugins/pbd, XPBD, stretch + global volume, 10 iterations) against
//     bullet_softbody (btSoftBody, links + volume force, 10 position iterations) on the same
//     liver surface, makePhantom("liver", 0.27) (~2.2k vertices);
//   - our fem_hex (967 hexahedra, corotational, PCG) against bullet_deformable (Neo-Hookean,
//     implicit, Bullet's CG) at a similar node count, its CG preconditioned by the factor of the
//     step's matrix at rest (second argument 1, the default) and not (0, Bullet's own).
// Every model pins the same bottom slab (z below 0.25 of the height), feels gravity and a grasp
// of the nodes within 1.5 cm of the top centre lifting 2 cm over 0.5 s and back. Each benchmark
// iteration is one step; the counter median_us is the median step time (the headline).
// After the runs the program prints the ratios of the medians.
//
//   bench_peers                      # all four, then the ratios
//   bench_peers --benchmark_filter=Surface
#include "bullet_deformable_model.h"
#include "bullet_softbody_model.h"
#include "hex_fem_model.h"
#include "pbd_model.h"

#include <deform/geometry/phantom.h>
#include <deform/geometry/tet_mesher.h>

#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <map>
#include <string>

namespace {

using namespace deform;

std::map<std::string, double>& medians() {
  static std::map<std::string, double> m;
  return m;
}
std::map<std::string, double>& nodeCounts() {
  static std::map<std::string, double> m;
  return m;
}

Organ liverOrgan(Real resolution) {
  Organ o;
  o.source = "phantom:liver";
  o.surface = makePhantom("liver", resolution);
  const Box b = boundingBox(o.surface.V);
  Box slab = b;
  slab.lo -= Vec3::Constant(0.01);
  slab.hi.x() += 0.01;
  slab.hi.y() += 0.01;
  slab.hi.z() = b.lo.z() + 0.25 * b.size().z();
  o.fixed.boxes.push_back(slab);
  return o;
}

/// Steps `model` under gravity with a grasp of the nodes within 1.5 cm of the top centre, lifting
/// them 2 cm over 500 steps and back (triangle wave). Records the median step time.
void runSteps(benchmark::State& state, Model& model, const std::string& name) {
  const MatX3 nodes = model.surface();  // the grasp holds organ surface vertices
  const Box b = boundingBox(nodes);
  const Vec3 top(b.center().x(), b.center().y(), b.hi.z());
  GraspInput grasp;
  for (int n = 0; n < nodes.rows(); ++n)
    if ((nodes.row(n).transpose() - top).norm() < 0.015) grasp.vertices.push_back(n);
  MatX3 rest(grasp.vertices.size(), 3);
  for (size_t k = 0; k < grasp.vertices.size(); ++k) rest.row(k) = nodes.row(grasp.vertices[k]);
  grasp.targets = rest;
  StepInput in;
  in.dt = 1e-3;
  in.gravity = Vec3(0, 0, -9.81);
  in.grasps = {grasp};
  for (int s = 0; s < 5; ++s) model.step(in);  // warm-up; the grasp closes
  std::vector<double> times;
  long long step = 0;
  for (auto _ : state) {
    const int phase = static_cast<int>(step % 1000);
    const Real lift = 0.02 * (phase < 500 ? phase : 1000 - phase) / 500.0;
    in.grasps[0].targets.col(2) = rest.col(2).array() + lift;
    const auto t0 = std::chrono::steady_clock::now();
    const StepStatus s = model.step(in);
    times.push_back(
        std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() - t0).count());
    if (s != StepStatus::Ok) {
      state.SkipWithError("diverged");
      return;
    }
    ++step;
  }
  std::sort(times.begin(), times.end());
  const double median = times[times.size() / 2];
  state.counters["median_us"] = median;
  state.counters["nodes"] = static_cast<double>(nodes.rows());
  state.counters["grasped"] = static_cast<double>(grasp.vertices.size());
  medians()[name] = median;
  nodeCounts()[name] = static_cast<double>(nodes.rows());
}

void SurfacePbd(benchmark::State& state) {
  const Organ o = liverOrgan(0.27);
  pbd::PbdConfig c;
  c.iterations = 10;
  c.bending = false;  // stretch + global volume: the same constraint set as bullet_softbody's
  c.volume = true;
  pbd::PbdModel m;
  m.init(o, c);
  runSteps(state, m, "pbd");
  state.counters["constraints"] = static_cast<double>(m.counts().at("constraints"));
}

void SurfaceBulletSoftBody(benchmark::State& state) {
  const Organ o = liverOrgan(0.27);
  bullet_softbody::SoftBodyConfig c;
  c.iterations = 10;
  bullet_softbody::BulletSoftBodyModel m;
  m.init(o, c, 1e-3, fixedNodeIndices(o.surface.V, o.fixed, o.surface));
  runSteps(state, m, "bullet_softbody");
  state.counters["links"] = static_cast<double>(m.counts().at("links"));
}

class HexBenchModel final : public fem_hex::HexFemModel {
 public:
  void init(const ModelSetup&) override {}
};

void VolumeFemHex(benchmark::State& state) {
  const Organ o = liverOrgan(1.0);
  fem_hex::HexFemConfig c;  // defaults: 967 hexahedra, corotational, PCG
  HexBenchModel m;
  m.initialize(o, c, 1e-3,
               [&](const MatX3& nodes) { return fixedNodeIndices(nodes, o.fixed, o.surface); });
  runSteps(state, m, "fem_hex");
  state.counters["hexes"] = static_cast<double>(m.grid().numHexes());
}

void VolumeBulletDeformable(benchmark::State& state) {
  // The surface vertices are tet nodes, so a coarse surface keeps the node count near fem_hex's.
  const Organ o = liverOrgan(0.12);
  TetMeshOptions opt;
  opt.targetElements = state.range(0);
  opt.source = o.source;
  const TetMesh mesh = tetrahedralize(o.surface, opt).mesh;
  std::vector<int> surfaceNode(size_t(o.surface.numVertices()));
  for (size_t i = 0; i < surfaceNode.size(); ++i) surfaceNode[i] = int(i);
  bullet_deformable::DeformableConfig c;
  const bool preconditioned = state.range(1) != 0;
  if (!preconditioned) c.preconditioner = bullet_deformable::CgPreconditioning::None;
  bullet_deformable::BulletDeformableModel m;
  m.init(mesh, surfaceNode, o.material, c, 1e-3, fixedNodeIndices(mesh.V, o.fixed, o.surface));
  runSteps(state, m, preconditioned ? "bullet_deformable" : "bullet_deformable(none)");
  state.counters["tets"] = static_cast<double>(mesh.numTets());
  const NumericCounters n = m.numericCounters();
  state.counters["cg_per_step"] =
      double(n.at("cg_iterations")) / double(std::max<long long>(1, n.at("cg_solves")));
}

BENCHMARK(SurfacePbd)->Unit(benchmark::kMillisecond)->MinTime(2.0);
BENCHMARK(SurfaceBulletSoftBody)->Unit(benchmark::kMillisecond)->MinTime(2.0);
BENCHMARK(VolumeFemHex)->Unit(benchmark::kMillisecond)->MinTime(2.0);
BENCHMARK(VolumeBulletDeformable)
    ->Args({3000, 1})
    ->Args({3000, 0})
    ->Unit(benchmark::kMillisecond)
    ->MinTime(2.0);

}  // namespace

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  const auto& m = medians();
  const auto& n = nodeCounts();
  auto ratio = [&](const char* slow, const char* fast) {
    if (m.count(slow) && m.count(fast))
      std::printf("median step %s / %s = %.2f  (%.0f us vs %.0f us; %.0f vs %.0f nodes)\n", slow,
                  fast, m.at(slow) / m.at(fast), m.at(slow), m.at(fast), n.at(slow), n.at(fast));
  };
  ratio("bullet_softbody", "pbd");
  ratio("bullet_deformable", "fem_hex");
  ratio("bullet_deformable(none)", "bullet_deformable");
  return 0;
}
