// The paper's static accuracy measure (static_accuracy.h).
#include "static_accuracy.h"

#include "bem_accuracy.h"
#include "conforming_surface.h"
#include "surface_decimation.h"

#include <deform/geometry/phantom.h>
#include <deform/sdk/cache.h>
#include <deform/sdk/error.h>

#include <chrono>
#include <map>
#include <optional>

namespace deform::particle_bem {

namespace {

Box bottomBox(const MatX3& V, Real fraction) {
  const Box b = boundingBox(V);
  Box f;
  f.lo = b.lo - Vec3::Constant(1);
  f.hi = b.hi + Vec3::Constant(1);
  f.hi[2] = b.lo[2] + fraction * b.size()[2];
  return f;
}

/// The load case on `organ`: a 500 Pa downward traction over 15% of the largest extent around
/// the top vertex, the bottom 15% fixed.
LossRatioCase tableLoadCase(const SurfaceMesh& organ) {
  const Box box = boundingBox(organ.V);
  LossRatioCase c;
  c.center = organ.V.row(topVertex(organ.V)).transpose();
  c.radius = 0.15 * box.size().maxCoeff();
  c.traction = Vec3(0, 0, -500);
  c.fixedBox = bottomBox(organ.V, 0.15);
  return c;
}

}  // namespace

int topVertex(const MatX3& V) {
  int t = 0;
  for (int i = 0; i < V.rows(); ++i)
    if (V(i, 2) > V(t, 2)) t = i;
  return t;
}

nlohmann::json bemStaticAccuracy(const SurfaceMesh& organ,
                                 const std::vector<std::pair<int, int>>& rows,
                                 const std::filesystem::path& cacheDir) {
  LossRatioCase c = tableLoadCase(organ);
  c.support = FixedSupport::SupportFacesSingular;
  c.variants = false;
  const Material material{5500, 0.45, 1000};
  const std::vector<Box> boxes = {c.fixedBox};
  Cache cache(cacheDir);
  std::optional<SurfaceMesh> conforming;  // built on the first miss only
  std::map<int, SurfaceMesh> decimated;   // the coarse counts recur across rows
  const auto surface = [&](int n) -> const SurfaceMesh& {
    if (!conforming) conforming = conformToBoxes(organ, boxes);
    auto it = decimated.find(n);
    if (it == decimated.end())
      it = decimated.emplace(n, decimateQuadric(*conforming, n, boxes)).first;
    return it->second;
  };
  nlohmann::json out = nlohmann::json::array();
  for (const auto& [coarseN, fineN] : rows) {
    const auto t0 = std::chrono::steady_clock::now();
    CacheKey key;
    // "v1": bump when bemLossRatio, the decimation, the assembly or this case change.
    key.add("particle_bem.static_accuracy v1").add(organ.V).add(organ.F).add(coarseN).add(fineN);
    key.add(material.young).add(material.poisson).add(c.radius).add(c.traction[2]);
    nlohmann::json row;
    if (const auto hit = cache.get("particle_bem.static_accuracy", key)) {
      try {
        ByteReader r(*hit);
        row = nlohmann::json::parse(r.string());
        row["cached"] = true;
      } catch (const std::exception&) {
        row = nlohmann::json();
        cache.reject("particle_bem.static_accuracy", key);
      }
    }
    if (row.is_null()) {
      const SurfaceMesh& coarse = surface(coarseN);
      const SurfaceMesh& fine = surface(fineN);
      const LossRatioResult res = bemLossRatio(coarse, fine, material, c);
      row = {{"coarse_vertices", coarseN},
             {"fine_vertices", fineN},
             {"coarse_surface_vertices", coarse.numVertices()},
             {"fine_surface_vertices", fine.numVertices()},
             {"fine_surface_polygons", fine.numFaces()},
             {"vertex_ratio", double(fine.numVertices()) / coarse.numVertices()},
             {"loss_ratio", res.ratio},
             {"displacement_ratio", res.displacementRatio},
             {"mean_fine_displacement_m", res.meanFineDisplacement}};
      ByteWriter w;
      w.string(row.dump());
      cache.put("particle_bem.static_accuracy", key, w.bytes());
      row["cached"] = false;
    }
    row["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    out.push_back(row);
  }
  return out;
}

nlohmann::json staticAccuracyMeasure(const nlohmann::json& q) {
  const std::string organ = q.value("organ", std::string("phantom:liver"));
  if (organ.rfind("phantom:", 0) != 0)
    throw InputError("static accuracy request", "organ",
                     "'" + organ + "' is not a phantom (phantom:NAME)");
  std::vector<std::pair<int, int>> rows;
  for (const auto& r : q.at("rows")) rows.emplace_back(r.at(0).get<int>(), r.at(1).get<int>());
  const SurfaceMesh mesh = makePhantom(organ.substr(8));
  return nlohmann::json{
      {"rows", bemStaticAccuracy(mesh, rows, q.value("cache_dir", std::string()))}};
}

}  // namespace deform::particle_bem
