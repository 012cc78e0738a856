// metaballs-construction: Pan et al. 2015 (metaballs + PBD skinning), Table 1. The metaballs
// plugin built for four phantom organs (uncached) and dragged by a grasper.
#include "paper_figures.h"
#include "table_kit.h"

namespace deform::harness::tables {

TableDef metaballsConstruction(const TablesOptions& o) {
  TableDef t =
      tableDef("metaballs-construction", "metaballs construction and deformation per organ",
               "Pan et al. 2015 (metaballs + PBD skinning), Table 1",
               columns({{{"organ", "organ"}, {"status", "status"}},
                        withPaper("vertices", "vertices"),
                        withPaper("spheres", "spheres"),
                        withPaper("links", "links"),
                        withPaper("construction_s", "construction s"),
                        withPaper("deformation_ms", "deformation ms"),
                        {{"scene", "scene"}, {"note", "note"}}}));
  const double resolution = o.quick ? 0.25 : 1.0;
  const double duration = o.quick ? 0.05 : 0.5;
  t.notes = {"Our organs are the built-in phantoms (" +
                 std::string(o.quick ? "resolution 0.25, --quick" : "resolution 1") +
                 "), the sphere count is set to the paper's; construction is timed without the "
                 "cache; deformation ms is the median step time while a grasper lifts the organ "
                 "top by 2 cm (no gravity), bottom 15% fixed.",
             "The paper's machine and mesh differ: compare trends, not absolute seconds."};
  for (const auto& p : kMetaballsTable1) {
    SurfaceMesh s;
    ojson organ = phantomOrgan(p.organ, resolution, 0.15, s);
    ojson j = baseScene(std::string("metaballs-construction-") + p.organ,
                        std::string("Metaballs built for the ") + p.organ +
                            " phantom and dragged up 2 cm by a grasper at its top.",
                        organ, duration);
    j["tools"] = graspFromTop(s, 0.3, 0.35, 0.02, duration);
    j["models"] = ojson::array({model("metaballs", "metaballs", {{"spheres", p.spheres}})});
    t.cases.push_back({std::string("metaballs/") + p.organ, j, /*noCache=*/true});
  }
  t.rows = [](const Results& res, const fs::path& dir) {
    std::vector<ojson> rows;
    for (const auto& p : kMetaballsTable1) {
      const CaseResult& c = res.at(std::string("metaballs/") + p.organ);
      const RunRecord* r = c.run("metaballs");
      ojson row;
      row["organ"] = p.organ;
      row["vertices"] = c.organVertices >= 0 ? ojson(c.organVertices) : ojson(nullptr);
      row["paper_vertices"] = p.vertices;
      row["spheres"] = countOf(r, "spheres");
      row["paper_spheres"] = p.spheres;
      row["links"] = countOf(r, "links");
      row["paper_links"] = p.links;
      row["construction_s"] =
          r && r->status != RunStatus::Unsupported ? precomputeS(r) : ojson(nullptr);
      row["paper_construction_s"] = p.constructionS;
      row["deformation_ms"] = stepMedian(r);
      row["paper_deformation_ms"] = p.deformationMs;
      caseCells(row, c, "metaballs", r, dir, false);
      rows.push_back(row);
    }
    return rows;
  };
  return t;
}

}  // namespace deform::harness::tables
