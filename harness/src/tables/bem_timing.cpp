// bem-timing: Zhu, Gu & Zhou 2010 (particles + precomputed BEM), Table 1. particle_bem at the
// paper's five point numbers, time per step by phase.
#include "paper_figures.h"
#include "table_kit.h"

namespace deform::harness::tables {

namespace {

ojson phaseOf(const RunRecord* r, const std::string& phase) {
  if (!r || !r->phaseMs.count(phase)) return nullptr;
  return r->phaseMs.at(phase);
}

}  // namespace

TableDef bemTiming(const TablesOptions& o) {
  TableDef t = tableDef(
      "bem-timing", "particles guided by precomputed BEM: time per step by phase",
      "Zhu, Gu & Zhou 2010 (particles + precomputed BEM), Table 1",
      columns({{{"model", "model"}, {"point_number", "point number"}, {"status", "status"}},
               withPaper("surface_ms", "surface computation ms", "paper surface ms"),
               withPaper("correction_ms", "position correction ms", "paper correction ms"),
               withPaper("interpolation_ms", "surface interpolation ms", "paper interpolation ms"),
               withPaper("overall_ms", "overall ms (step median)", "paper overall ms"),
               {{"precompute_s", "precompute s"}, {"scene", "scene"}, {"note", "note"}}}));
  const double duration = o.quick ? 0.05 : 0.3;
  t.notes = {
      "particle_bem (guided) on the liver phantom at resolution 0.27 (~2.2k vertices), "
      "coarse surface = the paper's point number; a grasper at the liver's top lifts 1 cm "
      "over " +
          formatG(duration) +
          " s and a 0.5 N force presses beside it; bottom 15% "
          "fixed. Phases are medians over the steps after warm-up; overall is the median "
          "wall time of step().",
      "The paper's machine: 2.26 GHz Pentium M (2010)."};
  SurfaceMesh s;
  const ojson organ = phantomOrgan("liver", 0.27, 0.15, s);
  const Vec3 beside = topVertex(s) + Vec3(0.02, 0, 0);
  for (const auto& p : kBemTable1) {
    if (o.quick && p.points != 284 && p.points != 784) continue;
    ojson j = baseScene("bem-timing-" + std::to_string(p.points),
                        "Zhu et al. 2010 Table 1 timing case: " + std::to_string(p.points) +
                            " surface particles on the liver phantom.",
                        organ, duration);
    j["tools"] = graspFromTop(s, 0.05, 0.12, 0.01, duration);
    j["loads"] = verticalForce(beside, -0.5, duration);
    j["models"] =
        ojson::array({model("particle_bem", "particle_bem", {{"coarse_vertices", p.points}})});
    t.cases.push_back({"bem-timing/points_" + std::to_string(p.points), j});
  }
  const bool quick = o.quick;
  t.rows = [quick](const Results& res, const fs::path& dir) {
    std::vector<ojson> rows;
    for (const auto& p : kBemTable1) {
      ojson row;
      row["model"] = p.model;
      row["point_number"] = p.points;
      row["paper_surface_ms"] = p.surfaceMs;
      row["paper_correction_ms"] = p.correctionMs;
      row["paper_interpolation_ms"] = p.interpolationMs;
      row["paper_overall_ms"] = p.overallMs;
      if (const CaseResult* c =
              caseOrSkipped(res, "bem-timing/points_" + std::to_string(p.points), quick, row)) {
        const RunRecord* r = c->run("particle_bem");
        row["surface_ms"] = phaseOf(r, "surface");
        row["correction_ms"] = phaseOf(r, "correction");
        row["interpolation_ms"] = phaseOf(r, "interpolation");
        row["overall_ms"] = stepMedian(r);
        row["precompute_s"] = precomputeS(r);
        caseCells(row, *c, "particle_bem", r, dir, false);
      }
      rows.push_back(row);
    }
    return rows;
  };
  return t;
}

}  // namespace deform::harness::tables
