#include "metaballs_table.h"

#include "metaballs_model.h"

#include <deform/phantom.h>

#include <algorithm>
#include <chrono>

namespace deform::metaballs {

const std::vector<PaperTable1Row>& paperTable1() {
  static const std::vector<PaperTable1Row> rows = {
      {"liver", 8128, 581, 3588, 2207, 7.5},
      {"gallbladder", 1461, 475, 3293, 1179, 2.9},
      {"stomach", 3349, 452, 3161, 2050, 8.1},
      {"intestine", 887, 383, 2625, 754, 1.2},
  };
  return rows;
}

nlohmann::json metaballsConstructionTable(int steps) {
  nlohmann::json rows = nlohmann::json::array();
  for (const PaperTable1Row& paper : paperTable1()) {
    Organ organ;
    organ.source = std::string("phantom:") + paper.organ;
    organ.surface = makePhantom(paper.organ);
    const ParamValues params = ParamValues::defaults(metaballsParams());
    Cache cache{std::filesystem::path()};  // disabled: time the construction itself
    const Real dt = 1e-3;
    MetaballsModel model;
    const ModelSetup setup{organ, params, cache, dt, Vec3(0, 0, -9.81)};
    model.init(setup);
    const ConstructionReport& rep = model.metaballs().report;
    // Deformation: grasp the organ's top surface vertex and lift it 2 cm over the run.
    const MatX3 x0 = model.surface();
    Eigen::Index top = 0;
    x0.col(2).maxCoeff(&top);
    StepInput in;
    in.dt = dt;
    in.gravity = Vec3(0, 0, -9.81);
    GraspInput g;
    g.vertices = {int(top)};
    g.targets = x0.row(top);
    in.grasps = {g};
    std::vector<double> ms;
    for (int s = 0; s < steps; ++s) {
      in.time = s * dt;
      in.grasps[0].targets(0, 2) = x0(top, 2) + 0.02 * (s + 1) / steps;
      const auto t = std::chrono::steady_clock::now();
      model.step(in);
      ms.push_back(
          std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t).count());
    }
    std::sort(ms.begin(), ms.end());
    const Counts c = model.counts();
    rows.push_back({{"organ", paper.organ},
                    {"ours",
                     {{"vertices", organ.surface.numVertices()},
                      {"spheres", c.at("spheres")},
                      {"links", c.at("links")},
                      {"construction_s", rep.totalSeconds()},
                      {"deformation_ms", ms.empty() ? 0.0 : ms[ms.size() / 2]},
                      {"hollow_fraction_before", rep.hollowFractionBefore()},
                      {"hollow_fraction_after", rep.hollowFractionAfter()}}},
                    {"paper",
                     {{"vertices", paper.vertices},
                      {"spheres", paper.spheres},
                      {"links", paper.links},
                      {"construction_s", paper.constructionSeconds},
                      {"deformation_ms", paper.deformationMs}}}});
  }
  return {
      {"table", "metaballs-construction"}, {"source", "Pan et al. 2015, Table 1"}, {"rows", rows}};
}

}  // namespace deform::metaballs
