// Reference FEM benchmark: Gmsh meshing of the liver phantom at ~50k tets (target 35000 gives
// 51k: the refined surface bounds the element size near the boundary) and one quasi-static
// Newton solve (grasp and lift under gravity) per material; peak memory (ru_maxrss) and where
// the solve's time goes (SolveReport's breakdown, wall seconds).
// Run: build/plugins/reference_fem/bench_reference_fem --benchmark_repetitions=3
#include "fem_solver.h"
#include "test_shapes.h"

#include <deform/geometry/phantom.h>
#include <deform/geometry/tet_mesher.h>

#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <cmath>
#include <cstdlib>
#include <fstream>
#include <string>

using namespace deform;
using namespace deform::reference_fem;

namespace {

const SurfaceMesh& organ() {
  static const SurfaceMesh s = makePhantom("liver");
  return s;
}

constexpr long long kTargetElements = 35000;

const TetMeshResult& mesh50k() {
  static const TetMeshResult r = [] {
    TetMeshOptions o;
    o.targetElements = kTargetElements;
    o.refineSurface = true;
    return tetrahedralize(organ(), o);
  }();
  return r;
}

double peakRssMb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

void BM_MeshLiver50k(benchmark::State& state) {
  TetMeshOptions o;
  o.targetElements = kTargetElements;
  o.refineSurface = true;
  TetMeshResult r;
  for (auto _ : state) r = tetrahedralize(organ(), o);
  state.counters["tets"] = double(r.quality.elements);
  state.counters["nodes"] = double(r.quality.nodes);
  state.counters["min_dihedral_deg"] = r.quality.minDihedralDeg;
  state.counters["min_mean_ratio"] = r.quality.minMeanRatio;
  state.counters["mesh_wall_s"] = r.seconds;  // Gmsh runs in a child: CPU time misses it
  state.counters["peak_rss_MB"] = peakRssMb();
}
BENCHMARK(BM_MeshLiver50k)->Unit(benchmark::kMillisecond)->Iterations(1);

/// Grasp the nodes within 1 cm of the top point, lift them 2 cm, under gravity, with the
/// bottom 15% of the organ fixed. One full solve from rest (pattern analysis included).
void BM_QuasiStaticGraspLift(benchmark::State& state) {
  const TetMeshResult& m = mesh50k();
  const MaterialModel model = MaterialModel(state.range(0));
  Material mat;  // 5500 Pa, 0.3, 1000 kg/m^3 (the scene format's default)
  mat.poisson = 0.45;
  FemSystem sys(m.mesh, mat, model);
  const Box box = boundingBox(m.mesh.V);
  LoadCase lc;
  lc.gravity = Vec3(0, 0, -9.81);
  const Real zFix = box.lo.z() + 0.15 * box.size().z();
  const int top = nearestVertex(m.mesh.V, Vec3(box.center().x(), box.center().y(), box.hi.z()));
  for (int i = 0; i < sys.numNodes(); ++i) {
    if (m.mesh.V(i, 2) < zFix) {
      lc.fixedNodes.push_back(i);
    } else if ((m.mesh.V.row(i) - m.mesh.V.row(top)).norm() < 0.01) {
      lc.prescribedNodes.push_back(i);
    }
  }
  lc.targets.resize(lc.prescribedNodes.size(), 3);
  for (size_t k = 0; k < lc.prescribedNodes.size(); ++k)
    lc.targets.row(k) = m.mesh.V.row(lc.prescribedNodes[k]) + Vec3(0, 0, 0.02).transpose();
  SolveReport rep;
  VecX x;
  rusage before{}, after{};
  getrusage(RUSAGE_SELF, &before);
  for (auto _ : state) benchmark::DoNotOptimize(x = solveEquilibrium(sys, lc, {}, &rep));
  getrusage(RUSAGE_SELF, &after);
  // DEFORM_BENCH_DUMP=dir: write the solution (3N doubles, raw) to dir/<material>.bin, to compare
  // the answers of two builds.
  if (const char* dir = std::getenv("DEFORM_BENCH_DUMP")) {
    std::ofstream out(std::string(dir) + "/" + materialModelName(model) + ".bin", std::ios::binary);
    out.write(reinterpret_cast<const char*>(x.data()), std::streamsize(x.size() * sizeof(Real)));
  }
  state.SetLabel(materialModelName(model));
  state.counters["tets"] = double(m.mesh.numTets());
  state.counters["dofs"] = double(3 * sys.numNodes());
  state.counters["newton_iterations"] = rep.newtonIterations;
  state.counters["load_steps"] = rep.loadSteps;
  state.counters["converged"] = rep.converged;
  state.counters["factorizations"] = rep.factorizations;
  state.counters["pcg_iterations"] = rep.pcgIterations;
  state.counters["factor_nnz"] = double(rep.factorNonZeros);
  state.counters["factor_Gflop"] = rep.factorFlops * 1e-9;
  state.counters["analyze_s"] = rep.analyzeSeconds;
  state.counters["assembly_s"] = rep.assemblySeconds;
  state.counters["factor_s"] = rep.factorSeconds;
  state.counters["cg_solve_s"] = rep.solveSeconds;
  state.counters["objective_s"] = rep.objectiveSeconds;
  state.counters["peak_rss_MB"] = peakRssMb();
  // Where wall time goes besides this thread's user time: kernel time (page faults of fresh
  // allocations), minor page faults, and involuntary context switches (another process ran).
  const auto seconds = [](const timeval& t) { return double(t.tv_sec) + 1e-6 * double(t.tv_usec); };
  state.counters["user_s"] = seconds(after.ru_utime) - seconds(before.ru_utime);
  state.counters["sys_s"] = seconds(after.ru_stime) - seconds(before.ru_stime);
  state.counters["minor_faults"] = double(after.ru_minflt - before.ru_minflt);
  state.counters["invol_switches"] = double(after.ru_nivcsw - before.ru_nivcsw);
}
/// One assembly of the full stiffness pattern's values at a deformed state (the grasp-lift's
/// linearised lift applied as a smooth field: every element strained), per material; arg 1 = 1:
/// with the PSD projection of the element stress derivatives.
void BM_StiffnessAssembly(benchmark::State& state) {
  const TetMeshResult& m = mesh50k();
  Material mat;
  mat.poisson = 0.45;
  FemSystem sys(m.mesh, mat, MaterialModel(state.range(0)));
  const Box box = boundingBox(m.mesh.V);
  VecX x = sys.restPositions();
  for (int i = 0; i < sys.numNodes(); ++i) {
    const Real s = (m.mesh.V(i, 2) - box.lo.z()) / box.size().z();
    x(3 * i + 2) += 0.1 * s * s * box.size().z();                // up to 10% stretch along z
    x(3 * i) += 0.05 * s * (m.mesh.V(i, 1) - box.center().y());  // and shear
  }
  VecX values;
  for (auto _ : state) {
    sys.stiffnessValues(x, values, state.range(1) != 0);
    benchmark::DoNotOptimize(values.data());
  }
  state.SetLabel(std::string(materialModelName(MaterialModel(state.range(0)))) +
                 (state.range(1) ? " projected" : ""));
  state.counters["tets"] = double(m.mesh.numTets());
  state.counters["ns_per_tet"] =
      benchmark::Counter(double(m.mesh.numTets()), benchmark::Counter::kIsIterationInvariantRate |
                                                       benchmark::Counter::kInvert);
}
BENCHMARK(BM_StiffnessAssembly)
    ->Args({int(MaterialModel::Linear), 0})
    ->Args({int(MaterialModel::Corotational), 0})
    ->Args({int(MaterialModel::NeoHookean), 0})
    ->Args({int(MaterialModel::NeoHookean), 1})
    ->Unit(benchmark::kMillisecond);

BENCHMARK(BM_QuasiStaticGraspLift)
    ->Arg(int(MaterialModel::Linear))
    ->Arg(int(MaterialModel::Corotational))
    ->Arg(int(MaterialModel::NeoHookean))
    ->MeasureProcessCPUTime()  // CPU of every thread (CHOLMOD's OpenMP helpers, if any)
    ->UseRealTime()
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1);

}  // namespace

BENCHMARK_MAIN();
