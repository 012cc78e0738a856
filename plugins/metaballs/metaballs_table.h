// Metaballs plugin: data for the table `metaballs-construction` (DESIGN.md; the paper's Table 1):
// for the liver, gallbladder, stomach and intestine phantoms, the surface vertex count, sphere and
// link counts, construction seconds and milliseconds per deformation step (PBD + skinning, a grasp
// dragging the organ), with the paper's own figures beside ours.
#pragma once

#include <nlohmann/json.hpp>

#include <string>
#include <vector>

namespace deform::metaballs {

struct PaperTable1Row {
  const char* organ;
  int vertices, spheres, links;
  double constructionSeconds, deformationMs;
};
/// The paper's Table 1 (Pan et al. 2015).
const std::vector<PaperTable1Row>& paperTable1();

/// Builds each phantom's metaballs (no cache: construction is timed) and times `steps` steps.
/// Returns {"table": "metaballs-construction", "rows": [...]} with "ours" and "paper" per row.
nlohmann::json metaballsConstructionTable(int steps = 200);

}  // namespace deform::metaballs
