// Mesh reading and validation speed: a 32768-triangle sphere written as binary STL (always), and
// eval-data's Liver.stl (30726 triangles) when ../shared/eval-data is present.
#include <benchmark/benchmark.h>
#include <deform/geometry/mesh_check.h>
#include <deform/geometry/mesh_io.h>
#include <unistd.h>

#include <filesystem>
#include <map>

namespace deform {
namespace {

/// Octahedron subdivided `levels` times (8 * 4^levels triangles), projected on the unit sphere.
SurfaceMesh sphere(int levels) {
  SurfaceMesh m;
  m.V.resize(6, 3);
  m.V << 1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1, 0, 0, 0, 1, 0, 0, -1;
  m.F.resize(8, 3);
  m.F << 0, 2, 4, 2, 1, 4, 1, 3, 4, 3, 0, 4, 2, 0, 5, 1, 2, 5, 3, 1, 5, 0, 3, 5;
  for (int l = 0; l < levels; ++l) {
    std::map<std::pair<int, int>, int> mid;
    std::vector<Vec3> V;
    for (int i = 0; i < m.V.rows(); ++i) V.push_back(m.V.row(i).transpose());
    auto midpoint = [&](int a, int b) {
      const auto key = std::minmax(a, b);
      const auto [it, inserted] = mid.try_emplace({key.first, key.second}, int(V.size()));
      if (inserted) V.push_back((0.5 * (V[size_t(a)] + V[size_t(b)])).normalized());
      return it->second;
    };
    MatX3i F(4 * m.F.rows(), 3);
    for (int f = 0; f < m.F.rows(); ++f) {
      const int a = m.F(f, 0), b = m.F(f, 1), c = m.F(f, 2);
      const int ab = midpoint(a, b), bc = midpoint(b, c), ca = midpoint(c, a);
      F.row(4 * f) << a, ab, ca;
      F.row(4 * f + 1) << ab, b, bc;
      F.row(4 * f + 2) << ca, bc, c;
      F.row(4 * f + 3) << ab, bc, ca;
    }
    m.V.resize(Eigen::Index(V.size()), 3);
    for (size_t i = 0; i < V.size(); ++i) m.V.row(Eigen::Index(i)) = V[i].transpose();
    m.F = F;
  }
  return m;
}

}  // namespace

std::string sphereStl() {
  static const std::string path = [] {
    const std::string p = (std::filesystem::temp_directory_path() /
                           ("deform_bench_sphere_" + std::to_string(::getpid()) + ".stl"))
                              .string();
    writeStl(p, sphere(6));
    return p;
  }();
  return path;
}

namespace {

std::string liverStl() {
  return (std::filesystem::path(__FILE__).parent_path() / "../../shared/eval-data/Liver.stl")
      .lexically_normal()
      .string();
}

/// True, with the benchmark skipped as an error, when the mesh file is not there.
bool skipMissing(benchmark::State& state, const std::string& path) {
  if (std::filesystem::exists(path)) return false;
  state.SkipWithError(("missing " + path).c_str());
  return true;
}

void readAndValidate(benchmark::State& state, const std::string& path) {
  if (skipMissing(state, path)) return;
  for (auto _ : state) {
    const LoadedMesh m = readMesh(path);
    const MeshReport r = validateSurface(m.surface);
    benchmark::DoNotOptimize(r.issues.size());
  }
}

void readOnly(benchmark::State& state, const std::string& path) {
  if (skipMissing(state, path)) return;
  for (auto _ : state) benchmark::DoNotOptimize(readMesh(path).surface.numFaces());
}

void validateOnly(benchmark::State& state, const std::string& path) {
  if (skipMissing(state, path)) return;
  const SurfaceMesh m = readMesh(path).surface;
  for (auto _ : state) benchmark::DoNotOptimize(validateSurface(m).issues.size());
}

void repairOnly(benchmark::State& state, const std::string& path) {
  if (skipMissing(state, path)) return;
  const SurfaceMesh m = readMesh(path).surface;
  for (auto _ : state) {
    SurfaceMesh copy = m;
    benchmark::DoNotOptimize(repairSurface(copy).weldedVertices);
  }
}

BENCHMARK_CAPTURE(readOnly, sphere32k_stl, sphereStl())->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(validateOnly, sphere32k_stl, sphereStl())->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(readAndValidate, sphere32k_stl, sphereStl())->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(repairOnly, sphere32k_stl, sphereStl())->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(readOnly, Liver_stl, liverStl())->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(readAndValidate, Liver_stl, liverStl())->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace deform

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  std::error_code ec;
  std::filesystem::remove(deform::sphereStl(), ec);
  return 0;
}
