// Contact queries through Bullet on the liver phantom with a probe (5 mm tip, 8 mm shaft) pressed
// 4 mm into its top: vertex spheres (ContactWorld::query) against surface triangles
// (queryTriangles, pooled btTriangleShapes), and one respondToContact() projection on the surface.
#include <benchmark/benchmark.h>
#include <deform/geometry/phantom.h>
#include <deform/sdk/contact.h>
#include <deform/sdk/mesh.h>

namespace {

using namespace deform;

struct Setup {
  SurfaceMesh liver = makePhantom("liver");
  ContactWorld world;
  Setup() {
    const Box b = boundingBox(liver.V);
    const Vec3 top =
        liver.V.row(nearestVertex(liver.V, Vec3(b.center().x(), b.center().y(), b.hi.z())))
            .transpose();
    const int probe = world.addBody(probeShape(0.005, 0.08, 0.004, Vec3::UnitZ()));
    world.setPose(probe, top + Vec3(0, 0, 0.005 - 0.004));
  }
};

void BM_VertexSphereQuery(benchmark::State& state) {
  Setup s;
  for (auto _ : state) benchmark::DoNotOptimize(s.world.query(s.liver.V));
  state.counters["contacts"] = static_cast<double>(s.world.query(s.liver.V).size());
}
BENCHMARK(BM_VertexSphereQuery)->Unit(benchmark::kMicrosecond);

void BM_TriangleQuery(benchmark::State& state) {
  Setup s;
  for (auto _ : state) benchmark::DoNotOptimize(s.world.queryTriangles(s.liver.V, s.liver.F));
  state.counters["contacts"] =
      static_cast<double>(s.world.queryTriangles(s.liver.V, s.liver.F).size());
}
BENCHMARK(BM_TriangleQuery)->Unit(benchmark::kMicrosecond);

void BM_ResolveSurfaceContacts(benchmark::State& state) {
  Setup s;
  const VecX invMass = VecX::Constant(s.liver.numVertices(), 1000.0);
  for (auto _ : state) {
    MatX3 x = s.liver.V;
    ContactProxy proxy;
    proxy.nodes = &x;
    proxy.invMass = &invMass;
    proxy.faces = &s.liver.F;
    benchmark::DoNotOptimize(respondToContact(s.world, proxy, ContactResponse::Project, 1e-3));
  }
}
BENCHMARK(BM_ResolveSurfaceContacts)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
