// The six tables (see tables.h): their cases as generated scenes, and the rows built from the
// runs. Paper figures are data copied from the papers in ../shared/papers.
#include <deform/cache.h>
#include <deform/mesh.h>
#include <deform/phantom.h>
#include <deform_harness/calibration.h>
#include <deform_harness/child_process.h>
#include <deform_harness/convergence.h>
#include <deform_harness/tables.h>

#include <dlfcn.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <map>
#include <set>

namespace deform::harness {

namespace fs = std::filesystem;
using ojson = nlohmann::ordered_json;

namespace {

// ------------------------------------------------------------------------------------ helpers

/// Element order of the method-comparison reference: quadratic (10-node) tets, since linear
/// ones are ~10% too stiff on the liver at any affordable size (plugins/reference_fem/README.md).
constexpr int kReferenceOrder = 2;
/// Element order of the hybrid tables' reference: linear for now. Their cases press up to 20 N
/// on one vertex of a 5.5 kPa phantom; with quadratic tets the reference's Newton solve of the
/// cube's 20 N downward case did not finish in 15 min at 3k tets (linear: 0.45 s at 4.5k), which
/// would time every such case out. The tables' reference check says how far from converged
/// the linear reference is; switch this to 2 once the solver handles those loads.
constexpr int kHybridReferenceOrder = 1;
/// Target tets of the reference (a multiple of 8: the check's coarsest level is 1/8 of it).
constexpr long long kReferenceElements = 20000, kQuickReferenceElements = 4000;

ojson vec(const Vec3& v) {
  return ojson::array({v.x(), v.y(), v.z()});
}

std::string number(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%g", v);
  return buf;
}

/// "2N", "0p5N": a force as part of a file name.
std::string forceTag(double f) {
  std::string s = number(f) + "N";
  std::replace(s.begin(), s.end(), '.', 'p');
  return s;
}

/// Appends `part` to a "; "-separated list (nothing when part is empty).
void appendTo(std::string& list, const std::string& part) {
  if (!part.empty()) list += (list.empty() ? "" : "; ") + part;
}

ojson model(const std::string& plugin, const std::string& label, ojson params = ojson::object()) {
  return {{"plugin", plugin}, {"label", label}, {"params", std::move(params)}};
}

ojson material() {
  return {{"young", 5500}, {"poisson", 0.3}, {"density", 1000}};
}

/// Organ block of a phantom with the bottom `fixedFraction` of its height fixed (a box a little
/// larger than the organ in x and y); the phantom's mesh goes to meshOut.
ojson phantomOrgan(const std::string& name, double resolution, double fixedFraction,
                   SurfaceMesh& meshOut) {
  meshOut = makePhantom(name, resolution);
  const Box b = boundingBox(meshOut.V);
  const Vec3 m = Vec3::Constant(0.05 * b.diagonal());
  const Vec3 lo = b.lo - m;
  const Vec3 hi(b.hi.x() + m.x(), b.hi.y() + m.y(), b.lo.z() + fixedFraction * b.size().z());
  return {{"mesh", "phantom:" + name},
          {"resolution", resolution},
          {"material", material()},
          {"fixed", {{"box", ojson::array({vec(lo), vec(hi)})}}}};
}

ojson baseScene(const std::string& name, const std::string& description, ojson organ,
                double duration) {
  ojson j;
  j["name"] = name;
  j["description"] = description;
  j["organ"] = std::move(organ);
  j["gravity"] = {0, 0, 0};
  j["dt"] = 0.001;
  j["duration"] = duration;
  return j;
}

/// The reference of a scene, its error samples (the 10 and 50 vertices nearest the load).
void addReference(ojson& scene, ojson reference) {
  scene["reference"] = std::move(reference);
  scene["samples"] = {{"nearest", {10, 50}}};
}

/// The tables' reference FEM with `elements` target tets of the given order (1 or 2).
ojson referenceFem(long long elements, int order) {
  return model("reference_fem", "reference_fem",
               {{"elements", elements}, {"element_order", order}});
}

/// "20000 target P2 (10-node) tets": how the notes name the reference's elements.
std::string referenceTets(long long elements, int order) {
  return std::to_string(elements) + " target P" + std::to_string(order) + " (" +
         (order == 2 ? "10" : "4") + "-node) tets";
}

/// The surface vertex nearest the centre of the top of the bounding box.
Vec3 topVertex(const SurfaceMesh& s) {
  const Box b = boundingBox(s.V);
  return s.V.row(nearestVertex(s.V, Vec3(b.center().x(), b.center().y(), b.hi.z()))).transpose();
}

/// A constant vertical point force fz (N) at `at` from t = 0 to `end`.
ojson verticalForce(const Vec3& at, double fz, double end) {
  return ojson::array({{{"type", "point_force"},
                        {"at", vec(at)},
                        {"force", {0, 0, fz}},
                        {"start", 0.0},
                        {"end", end}}});
}

/// A grasper closing at t = 0 on the point `depth` below the organ's top vertex (so that models
/// whose nodes are interior, e.g. sphere centres, have nodes within reach) and lifting `lift`
/// metres over the run.
ojson graspFromTop(const SurfaceMesh& s, double depthFraction, double radiusFraction, double lift,
                   double duration) {
  const double height = boundingBox(s.V).size().z();
  const Vec3 p = topVertex(s) - Vec3(0, 0, depthFraction * height);
  return ojson::array({{{"type", "grasper"},
                        {"radius", radiusFraction * height},
                        {"trajectory",
                         {{{"t", 0.0}, {"pos", vec(p)}, {"jaw", "closed"}},
                          {{"t", duration}, {"pos", vec(p + Vec3(0, 0, lift))}}}}}});
}

/// Columns of our figure and the paper's beside it: {key, header}, {paper_key, paperHeader}
/// ("paper " + header when paperHeader is empty).
std::vector<TableColumn> withPaper(const std::string& key, const std::string& header,
                                   const std::string& paperHeader = "") {
  return {{key, header}, {"paper_" + key, paperHeader.empty() ? "paper " + header : paperHeader}};
}

/// Concatenated column groups.
std::vector<TableColumn> columns(std::initializer_list<std::vector<TableColumn>> groups) {
  std::vector<TableColumn> out;
  for (const auto& g : groups) out.insert(out.end(), g.begin(), g.end());
  return out;
}

/// Value of a run's count, or null.
ojson countOf(const RunRecord* r, const std::string& key) {
  if (!r || !r->counts.count(key)) return nullptr;
  return r->counts.at(key);
}

ojson stepMedian(const RunRecord* r) {
  if (!r || r->stepStats.samples == 0) return nullptr;
  return r->stepStats.median;
}

/// A figure of the run's error (null without one).
ojson errorFigure(const RunRecord* r, const std::function<double(const ErrorMetrics&)>& get) {
  if (!r || !r->error) return nullptr;
  return numberOrNull(get(*r->error));
}

/// rmse_k in mm (null when the run has no such figure).
ojson rmseMm(const RunRecord* r, int k) {
  return errorFigure(r, [k](const ErrorMetrics& e) {
    for (const auto& [kk, v] : e.rmseNearest)
      if (kk == k) return 1e3 * v;
    return std::nan("");
  });
}

ojson lossRatio(const RunRecord* r) {
  return errorFigure(r, [](const ErrorMetrics& e) { return e.lossRatio; });
}

/// The precomputation time of a run that stepped, or null.
ojson precomputeS(const RunRecord* r) {
  return r && r->steps > 0 ? ojson(r->precomputeS) : ojson(nullptr);
}

/// The status cell of a row: "ok", "diverged", ..., "invalid (why)" for a run that ended but did
/// not do what the scene asked (DESIGN "Metrics": validity), or "missing plugin X: why".
std::string statusOf(const CaseResult& c, const std::string& plugin, const RunRecord* r) {
  if (c.missing.count(plugin)) return "missing plugin " + plugin + ": " + c.missing.at(plugin);
  if (!c.error.empty()) return "not run: " + c.error;
  if (!r) return "not run";
  if (r->status == RunStatus::Ok && !r->valid) return "invalid (" + r->invalidReason + ")";
  return statusName(r->status);
}

/// A note on the row: the run's message and notes, and a missing reference.
std::string noteOf(const CaseResult& c, const RunRecord* r, bool wantsError) {
  std::string s;
  if (r) {
    appendTo(s, r->message);
    for (const auto& n : r->notes) appendTo(s, n);
  }
  if (wantsError && c.missing.count("reference_fem"))
    appendTo(s, "no error: reference_fem missing (" + c.missing.at("reference_fem") + ")");
  return s;
}

std::string relativeTo(const fs::path& p, const fs::path& base) {
  return fs::relative(p, base).generic_string();
}

/// The cells every one-model row ends with: the status of `plugin`'s run r, the scene to rerun
/// it, and the note.
void caseCells(ojson& row, const CaseResult& c, const std::string& plugin, const RunRecord* r,
               const fs::path& dir, bool wantsError) {
  row["status"] = statusOf(c, plugin, r);
  row["scene"] = relativeTo(c.sceneFile, dir);
  row["note"] = noteOf(c, r, wantsError);
}

// ---------------------------------------------------------------------------------- the cases

struct Case {
  std::string id;  ///< "<group>/<name>": scenes/<id>.json, runs/<id>/
  ojson scene;
  bool noCache = false;  ///< time the precomputation itself
};

using Results = std::map<std::string, CaseResult>;

/// The case of a row, or nullptr after marking the row as skipped by --quick (or not run).
const CaseResult* caseOrSkipped(const Results& res, const std::string& id, bool quick, ojson& row) {
  if (res.count(id)) return &res.at(id);
  row["status"] = quick ? "skipped (--quick)" : "not run";
  return nullptr;
}

struct TableDef {
  std::string name, title, source;
  std::vector<std::string> notes;
  /// Cases whose reference the table checks for convergence: one per distinct reference.
  std::vector<std::string> checks;
  std::vector<TableColumn> columns;
  std::vector<Case> cases;
  std::function<std::vector<ojson>(const Results&, const fs::path& outDir)> rows;
};

TableDef tableDef(const std::string& name, const std::string& title, const std::string& source,
                  std::vector<TableColumn> cols) {
  TableDef t;
  t.name = name;
  t.title = title;
  t.source = source;
  t.columns = std::move(cols);
  return t;
}

/// The cells of a row in the order of the table's columns (keys without a column after them).
ojson inColumnOrder(const ojson& row, const std::vector<TableColumn>& cols) {
  ojson out = ojson::object();
  for (const TableColumn& c : cols)
    if (row.contains(c.key)) out[c.key] = row[c.key];
  for (const auto& [k, v] : row.items())
    if (!out.contains(k)) out[k] = v;
  return out;
}

// ------------------------------------------------------------------- metaballs-construction

struct MetaballsPaperRow {
  const char* organ;
  int vertices, spheres, links;
  double constructionS, deformationMs;
};
// Pan et al. 2015, Table 1.
constexpr MetaballsPaperRow kMetaballsTable1[] = {
    {"liver", 8128, 581, 3588, 2207, 7.5},
    {"gallbladder", 1461, 475, 3293, 1179, 2.9},
    {"stomach", 3349, 452, 3161, 2050, 8.1},
    {"intestine", 887, 383, 2625, 754, 1.2},
};

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

// ------------------------------------------------------------------------ method-comparison

struct MethodPaperCell {
  const char* counts;
  double ms;
};
// Pan et al. 2015, Table 2: elements/constraints and deformation ms, gallbladder then liver.
const std::map<std::string, std::map<std::string, MethodPaperCell>>& methodPaper() {
  static const std::map<std::string, std::map<std::string, MethodPaperCell>> m = {
      {"gallbladder",
       {{"fem_hex", {"819", 39.2}},
        {"massspring", {"4991", 0.75}},
        {"pbd", {"4991 + 3185", 1.15}},
        {"metaballs", {"3242 + 466", 2.7}}}},
      {"liver",
       {{"fem_hex", {"967", 48.6}},
        {"massspring", {"6427", 2.5}},
        {"pbd", {"6427 + 4079", 2.2}},
        {"metaballs", {"3588 + 581", 7.6}}}}};
  return m;
}

std::string ourCounts(const RunRecord* r, const std::string& label) {
  if (!r || r->counts.empty()) return "";
  const auto get = [&](const char* k) { return r->counts.count(k) ? r->counts.at(k) : 0LL; };
  if (label == "fem_hex") return std::to_string(get("elements"));
  if (label == "massspring") return std::to_string(get("springs"));
  if (label == "pbd")
    return std::to_string(get("distance_constraints")) + " + " +
           std::to_string(get("volume_constraints") + get("bending_constraints"));
  if (label == "metaballs")
    return std::to_string(get("constraints")) + " + " + std::to_string(get("spheres"));
  return "";
}

/// The methods of Table 2 (label = plugin).
constexpr const char* kMethods[] = {"fem_hex", "massspring", "pbd", "metaballs"};

TableDef methodComparison(const TablesOptions& o, long long refElements) {
  TableDef t =
      tableDef("method-comparison",
               "FEM (hex), mass-spring, PBD and metaballs on the gallbladder and the liver",
               "Pan et al. 2015 (metaballs + PBD skinning), Table 2",
               columns({{{"organ", "organ"}, {"method", "method"}, {"status", "status"}},
                        withPaper("counts", "elements/constraints"),
                        withPaper("ms", "ms/step", "paper ms"),
                        {{"rmse_10_mm", "rmse_10 mm"},
                         {"rmse_50_mm", "rmse_50 mm"},
                         {"rmse_all_mm", "rmse_all mm"},
                         {"loss_ratio", "loss ratio"},
                         {"scene", "scene"},
                         {"note", "note"}}}));
  const double duration = o.quick ? 0.25 : 1.0;
  t.notes = {
      "Scenes: the shipped grasp-and-lift scenes (liver at resolution 0.27, ~2.2k vertices "
      "as in the paper's PBD comparison; gallbladder at resolution 1), " +
          number(duration) + " s at 1 ms; error against reference_fem (" +
          referenceTets(refElements, kReferenceOrder) +
          ", Neo-Hookean, quasi-static, solved where the grasp closes and at the end of the "
          "run).",
      "Counts: fem_hex elements; mass-spring springs; PBD distance + volume/bending "
      "constraints; metaballs links(+Laplacian) + spheres. Mass-spring uses explicit "
      "Euler as in the paper, without its automatic substeps (substeps = 1): divergence at "
      "1 ms is an honest result.",
      "Our error column has no paper counterpart."};
  struct OrganSetup {
    const char* organ;
    double resolution;
    ojson fixed;
    ojson tools;
    int femElements, spheres;
  };
  std::vector<OrganSetup> organs;
  // The shipped scenes' boundary conditions and grasps (scenes/gallbladder_grasp_lift.json and
  // scenes/liver_grasp_lift.json).
  organs.push_back(
      {"gallbladder",
       1.0,
       {{"box", {{0.028, -0.03, -0.03}, {0.05, 0.03, 0.03}}}},
       ojson::array({{{"type", "grasper"},
                      {"radius", 0.006},
                      {"trajectory",
                       {{{"t", 0.0}, {"pos", {-0.029, -0.0021, 0.0243}}, {"jaw", "open"}},
                        {{"t", 0.1}, {"pos", {-0.029, -0.0021, 0.0143}}, {"jaw", "closed"}},
                        {{"t", 0.6}, {"pos", {-0.034, -0.0021, 0.0343}}, {"jaw", "closed"}},
                        {{"t", 1.0}, {"pos", {-0.034, -0.0021, 0.0343}}, {"jaw", "closed"}}}}}}),
       819,
       466});
  organs.push_back(
      {"liver",
       0.27,
       {{"boxes",
         {{{-0.11, -0.08, -0.05}, {0.11, -0.035, 0.05}},
          {{-0.11, -0.08, -0.05}, {0.11, 0.03, -0.032}}}}},
       ojson::array({{{"type", "grasper"},
                      {"radius", 0.008},
                      {"trajectory",
                       {{{"t", 0.0}, {"pos", {-0.0235, 0.0794, -0.0132}}, {"jaw", "open"}},
                        {{"t", 0.1}, {"pos", {-0.0235, 0.0744, -0.0232}}, {"jaw", "closed"}},
                        {{"t", 0.6}, {"pos", {-0.0235, 0.0744, 0.0018}}, {"jaw", "closed"}},
                        {{"t", 1.0}, {"pos", {-0.0235, 0.0744, 0.0018}}, {"jaw", "closed"}}}}}}),
       967,
       581});
  for (const OrganSetup& os : organs) {
    ojson organ = {{"mesh", std::string("phantom:") + os.organ},
                   {"resolution", os.resolution},
                   {"material", material()},
                   {"fixed", os.fixed}};
    ojson j = baseScene(std::string("method-comparison-") + os.organ,
                        std::string("Pan et al. 2015 Table 2 comparison on the ") + os.organ +
                            " phantom: the shipped grasp-and-lift scene.",
                        organ, duration);
    j["tools"] = os.tools;
    j["models"] = ojson::array(
        {model("fem_hex", "fem_hex", {{"elements", os.femElements}}),
         model("massspring", "massspring", {{"integrator", "explicit_euler"}, {"substeps", 1}}),
         model("pbd", "pbd"), model("metaballs", "metaballs", {{"spheres", os.spheres}})});
    addReference(j, referenceFem(refElements, kReferenceOrder));
    t.cases.push_back({std::string("method/") + os.organ, j});
    t.checks.push_back(t.cases.back().id);
  }
  t.rows = [](const Results& res, const fs::path& dir) {
    std::vector<ojson> rows;
    for (const char* organ : {"gallbladder", "liver"}) {
      const CaseResult& c = res.at(std::string("method/") + organ);
      for (const char* m : kMethods) {
        const RunRecord* r = c.run(m);
        const MethodPaperCell& paper = methodPaper().at(organ).at(m);
        ojson row;
        row["organ"] = organ;
        row["method"] = m;
        const std::string counts = ourCounts(r, m);
        row["counts"] = counts.empty() ? ojson(nullptr) : ojson(counts);
        row["paper_counts"] = paper.counts;
        row["ms"] = stepMedian(r);
        row["paper_ms"] = paper.ms;
        row["rmse_10_mm"] = rmseMm(r, 10);
        row["rmse_50_mm"] = rmseMm(r, 50);
        row["rmse_all_mm"] = errorFigure(r, [](const ErrorMetrics& e) { return 1e3 * e.rmseAll; });
        row["loss_ratio"] = lossRatio(r);
        caseCells(row, c, m, r, dir, true);
        rows.push_back(row);
      }
    }
    return rows;
  };
  return t;
}

// ------------------------------------------------------------------------------- bem-timing

struct BemTimingPaperRow {
  int model, points;
  double surfaceMs, correctionMs, interpolationMs, overallMs;
};
// Zhu, Gu & Zhou 2010, Table 1.
constexpr BemTimingPaperRow kBemTable1[] = {{1, 284, 0.63, 0.228, 0.137, 1.00},
                                            {2, 508, 1.13, 0.309, 0.266, 1.67},
                                            {3, 784, 1.75, 0.653, 0.422, 2.83},
                                            {4, 876, 1.94, 0.725, 0.497, 3.162},
                                            {5, 1144, 2.53, 1.012, 0.634, 4.176}};

ojson phaseOf(const RunRecord* r, const std::string& phase) {
  if (!r || !r->phaseMs.count(phase)) return nullptr;
  return r->phaseMs.at(phase);
}

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
          number(duration) +
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

// ----------------------------------------------------------------------------- bem-accuracy

struct BemAccuracyPaperRow {
  int coarse, fine, finePolygons;
  double ratio, loss;  ///< vertex ratio fine/coarse; accuracy loss ratio (fraction)
};
// Zhu, Gu & Zhou 2010, Table 2, plus 608/1216 (vertex ratio 2, the goal; ratio 0: no
// paper value).
constexpr BemAccuracyPaperRow kBemTable2[] = {
    {284, 256, 508, 0.90, 0.021},  {284, 394, 784, 1.39, 0.037},   {284, 574, 1144, 2.02, 0.051},
    {608, 506, 1008, 0.83, 0.014}, {608, 1000, 1996, 1.64, 0.033}, {608, 1216, 2428, 0, 0},
    {608, 1586, 3168, 2.61, 0.062}};

/// coarse_vertices of the bem-accuracy reference: particle_bem's maximum (no decimation).
constexpr int kBemFineVertices = 20000;

std::string bemAccuracyId(const BemAccuracyPaperRow& p) {
  return "bem-accuracy/coarse_" + std::to_string(p.coarse) + "_fine_" + std::to_string(p.fine);
}

/// The paper's static measure, as `bem_tables accuracy --out FILE` writes it (particle_bem): when
/// this file is in the output folder its rows override the computed ones.
constexpr const char* kBemStaticFile = "bem-accuracy-static.json";

/// particle_bem's optional export computing the static measure (plugins/particle_bem/plugin.cpp):
/// const char* f(const char* requestJson), the reply JSON owned by the plugin.
constexpr const char* kBemStaticSymbol = "deform_particle_bem_static_accuracy";

/// The rows of that file's bem-accuracy table (empty when the file is absent or unreadable).
ojson bemStaticRowsFromFile(const fs::path& file) {
  std::ifstream in(file);
  if (!in) return ojson::array();
  try {
    const ojson j = ojson::parse(in);
    for (const ojson& t : j.is_array() ? j : ojson::array({j}))
      if (t.is_object() && t.value("name", "") == "bem-accuracy" && t.contains("rows") &&
          t["rows"].is_array())
        return t["rows"];
  } catch (const std::exception&) {
  }
  return ojson::array();
}

/// The static measure for the given (coarse, fine) pairs from the particle_bem plugin's optional
/// export (each row cached in cacheDir by the plugin). Throws std::runtime_error saying why it
/// is unavailable (plugin not found, no such export, the plugin's error).
ojson bemStaticRowsFromPlugin(PluginLoader& loader, const std::vector<std::pair<int, int>>& pairs,
                              const fs::path& cacheDir) {
  const std::string path = loader.locate("particle_bem");
  void* h = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
  if (!h) throw std::runtime_error(path + ": cannot load (" + std::string(dlerror()) + ")");
  using Fn = const char* (*)(const char*);
  const auto fn = reinterpret_cast<Fn>(dlsym(h, kBemStaticSymbol));
  if (!fn) {
    dlclose(h);
    throw std::runtime_error(path + ": no " + kBemStaticSymbol + " (an older plugin)");
  }
  ojson q = {{"organ", "phantom:liver"}, {"cache_dir", cacheDir.string()}};
  q["rows"] = ojson::array();
  for (const auto& [c, f] : pairs) q["rows"].push_back({c, f});
  ojson reply;
  try {
    reply = ojson::parse(fn(q.dump().c_str()));
  } catch (const std::exception& e) {
    dlclose(h);
    throw std::runtime_error(std::string("particle_bem static accuracy: bad reply: ") + e.what());
  }
  dlclose(h);
  if (reply.contains("error"))
    throw std::runtime_error("particle_bem static accuracy: " + reply["error"].get<std::string>());
  return reply.value("rows", ojson::array());
}

TableDef bemAccuracy(const TablesOptions& o, PluginLoader& loader, Progress* progress) {
  TableDef t = tableDef("bem-accuracy",
                        "accuracy loss of the coarse BEM surface against BEM on the fine surface",
                        "Zhu, Gu & Zhou 2010 (particles + precomputed BEM), Table 2",
                        columns({{{"coarse_vertices", "coarse vertices"}},
                                 withPaper("fine_vertices", "fine vertices"),
                                 {{"fine_polygons", "fine polygons"}},
                                 withPaper("vertex_ratio", "vertex ratio"),
                                 withPaper("loss_ratio", "accuracy loss ratio", "paper loss ratio"),
                                 {{"status", "status"}, {"scene", "scene"}, {"note", "note"}},
                                 {{"static_loss_ratio", "static BEM loss ratio (paper's measure)"},
                                  {"static_fine_vertices", "static fine vertices"},
                                  {"static_vertex_ratio", "static vertex ratio"}}}));
  const double duration = o.quick ? 0.15 : 0.5;
  t.notes = {
      "The organ (the fine surface) is the liver phantom at the resolution giving about the "
      "paper's fine vertex count; the model is particle_bem with coarse_vertices = the "
      "coarse count; the reference is the same plugin run without decimation (coarse_vertices "
      "= " +
          std::to_string(kBemFineVertices) +
          ": BEM on the whole fine surface, cut along the fixed box's top face, so it has a few "
          "more nodes than the fine vertices, which are among them). Loss ratio = sum|u_ref - u| / "
          "sum|u_ref| over the fine vertices at the end of the run (" +
          number(duration) +
          " s; a 0.5 N force presses on the liver's top, bottom 15% "
          "fixed, E = 5.5 kPa, nu = 0.3, no gravity).",
      "Where the coarse count exceeds the fine one (paper rows with ratio < 1) our "
      "decimation cannot add vertices: the model's coarse surface is then the organ surface "
      "cut along the box and decimated to at most the coarse count, near the reference "
      "(a small loss).",
      "Two measures, both R = sum|u_o - u_imp| / sum|u_o| over the fine vertices (the "
      "paper's definition, Table 2), against the paper's figure (paper loss ratio): "
      "'accuracy loss ratio' (loss_ratio) is the whole model run above (point force as a "
      "3 cm pressure patch, particles, virtual springs, transfer to the organ surface; under "
      "a constant load the springs scale every displacement by the same factor on both runs, "
      "1 at the compared instant, so it equals the static BEM answer to that load); 'static BEM "
      "loss ratio (paper's measure)' (static_loss_ratio) is the "
      "paper's own measure, static BEM only: both surfaces decimated from the 8122-vertex "
      "liver, the same Gaussian traction field (500 Pa, r = 3 cm) integrated over each "
      "mesh's elements, nu = 0.45, the model's discretisation (conforming support, "
      "singular reaction, gradient transfer): the headline loss_ratio of the particle_bem "
      "program `bem_tables accuracy`, computed here through the plugin's optional export " +
          std::string(kBemStaticSymbol) +
          " (one BEM assembly and solve per surface, about 1-2 min for the seven rows on 2 "
          "cores, each row then kept in the precomputation cache); static fine vertices are "
          "those of the solved fine surface (cut along the box, decimated). A file " +
          kBemStaticFile + " in the output folder (`bem_tables accuracy --out <out>/" +
          kBemStaticFile +
          "`) overrides the computed rows. The issue's goal, R <= 3% at a "
          "vertex ratio of 2, is stated on the paper's measure."};
  for (const auto& p : kBemTable2) {
    if (o.quick && !(p.coarse == 284 && p.fine != 574)) continue;
    // The liver phantom's vertex count scales about linearly with resolution (8122 at 1).
    SurfaceMesh s;
    const ojson organ = phantomOrgan("liver", double(p.fine) / 8122.0, 0.15, s);
    ojson j = baseScene("bem-accuracy-" + std::to_string(p.coarse) + "-" + std::to_string(p.fine),
                        "Zhu et al. 2010 Table 2 case: coarse " + std::to_string(p.coarse) +
                            " vertices against BEM on a fine liver of about " +
                            std::to_string(p.fine) + " vertices.",
                        organ, duration);
    j["loads"] = verticalForce(topVertex(s), -0.5, duration + 1.0);
    j["models"] =
        ojson::array({model("particle_bem", "particle_bem", {{"coarse_vertices", p.coarse}})});
    // The reference's BEM surface is the whole organ surface: coarse_vertices at the
    // parameter's maximum, since with the conforming support (the default) the organ surface is
    // first cut along the fixed box, which adds vertices (562 -> 633 at the 574 row); a count of
    // the organ's vertices would decimate that cut surface back, a coarser reference (1.9%
    // instead of 1.1% from the organ surface subdivided once, particle_bem README "Sixth pass").
    addReference(j, model("particle_bem", "bem_fine", {{"coarse_vertices", kBemFineVertices}}));
    t.cases.push_back({bemAccuracyId(p), j});
  }
  const bool quick = o.quick;
  const fs::path cacheDir = o.cases.cacheDir ? *o.cases.cacheDir : Cache::defaultDir();
  // The static measure is one more step of the command's progress (minutes when not cached).
  if (progress) progress->addTotal(1);
  t.rows = [quick, cacheDir, &loader, progress](const Results& res, const fs::path& dir) {
    // The static measure: the file's rows when the user put one there, else the plugin's.
    ojson statics = bemStaticRowsFromFile(dir / kBemStaticFile);
    std::string staticError;
    if (statics.empty()) {
      std::vector<std::pair<int, int>> pairs;
      for (const auto& p : kBemTable2)
        if (!quick || (p.coarse == 284 && p.fine != 574)) pairs.emplace_back(p.coarse, p.fine);
      const std::string what = "bem-accuracy static measure (particle_bem)";
      if (progress) progress->start(what);
      try {
        statics = bemStaticRowsFromPlugin(loader, pairs, cacheDir);
      } catch (const std::exception& e) {
        staticError = std::string("static measure not computed: ") + e.what();
      }
      int cached = 0;
      for (const ojson& s : statics) cached += s.value("cached", false) ? 1 : 0;
      if (progress)
        progress->finish(what, staticError.empty()
                                   ? "ok (" + std::to_string(cached) + " of " +
                                         std::to_string(statics.size()) + " rows cached)"
                                   : "not computed");
    } else if (progress) {
      progress->addTotal(-1);  // read from the file: no step
    }
    std::vector<ojson> rows;
    for (const auto& p : kBemTable2) {
      ojson row;
      row["coarse_vertices"] = p.coarse;
      for (const ojson& s : statics)
        if (s.value("coarse_vertices", -1) == p.coarse && s.value("fine_vertices", -1) == p.fine) {
          row["static_loss_ratio"] = s.value("loss_ratio", ojson(nullptr));
          // The solved fine surface (the plugin's rows; the file's rows name it fine_vertices).
          row["static_fine_vertices"] = s.value("fine_surface_vertices", s["fine_vertices"]);
          row["static_vertex_ratio"] = s.value("vertex_ratio", ojson(nullptr));
        }
      if (p.ratio > 0) {
        row["paper_fine_vertices"] = p.fine;
        row["paper_vertex_ratio"] = p.ratio;
        row["paper_loss_ratio"] = p.loss;
      }
      if (const CaseResult* c = caseOrSkipped(res, bemAccuracyId(p), quick, row)) {
        const RunRecord* r = c->run("particle_bem");
        if (c->organVertices >= 0) {
          row["fine_vertices"] = c->organVertices;
          row["fine_polygons"] = c->organFaces;
          row["vertex_ratio"] = double(c->organVertices) / double(p.coarse);
        }
        row["loss_ratio"] = lossRatio(r);
        caseCells(row, *c, "particle_bem", r, dir, false);
        const RunRecord* ref = c->run("bem_fine");
        if (ref && ref->status != RunStatus::Ok) {
          std::string note = row["note"];
          appendTo(note, "reference: " + ref->message);
          row["note"] = note;
        }
      }
      if (!staticError.empty() && (!quick || (p.coarse == 284 && p.fine != 574))) {
        std::string note = row.contains("note") && row["note"].is_string() ? row["note"] : "";
        appendTo(note, staticError);
        row["note"] = note;
      }
      rows.push_back(row);
    }
    return rows;
  };
  return t;
}

// ---------------------------------------------------------------- hybrid-accuracy and -timing

struct HybridPhantom {
  const char* name;
  double resolution;
};
// Liver at 0.27: the ~2.2k-vertex liver of the PBD comparisons; the others at resolution 1.
constexpr HybridPhantom kHybridPhantoms[] = {
    {"cube", 1.0}, {"sphere", 1.0}, {"liver", 0.27}, {"steak", 1.0}};
constexpr double kHybridForces[] = {0.5, 1.0, 2.0, 5.0, 10.0, 20.0};
/// m, the pressure patch of the hybrid cases' point force (the same for every model).
constexpr double kHybridLoadRadius = 0.03;
/// The direction of the hybrid case whose reference is checked (with the largest force).
constexpr bool kCheckedHybridUp = false;
/// The compared models of the hybrid tables.
struct HybridModel {
  const char* plugin;  ///< = its label in the scenes
  const char* key;     ///< of its columns ("<key>_ms", "<key>_rmse_mm") and status parts
  const char* header;  ///< of its columns
};
constexpr HybridModel kHybridModels[] = {{"hybrid_fem_pbd", "hybrid", "hybrid"},
                                         {"pbd", "pbd", "PBD"},
                                         {"massspring", "massspring", "mass-spring"}};

std::string hybridFigureKey(const HybridModel& m, bool timing) {
  return std::string(m.key) + (timing ? "_ms" : "_rmse_mm");
}

struct HybridCase {
  const HybridPhantom* phantom;
  double force;
  bool up;
  std::string id() const {
    return std::string("hybrid/") + phantom->name + "_" + (up ? "up_" : "down_") + forceTag(force);
  }
};

std::vector<HybridCase> hybridCases(bool quick) {
  std::vector<HybridCase> cases;
  for (const HybridPhantom& p : kHybridPhantoms) {
    if (quick && std::string(p.name) != "cube") continue;
    for (double f : kHybridForces) {
      if (quick && f != 2.0 && f != 20.0) continue;
      for (bool up : {true, false}) cases.push_back({&p, f, up});
    }
  }
  return cases;
}

std::vector<Case> hybridSceneCases(bool quick, long long refElements) {
  // Compared at equilibrium (each dynamic model runs until it settles; the duration is the cap),
  // against the quasi-static reference under the same constant load.
  const double duration = quick ? 1.0 : 3.0;
  std::vector<Case> out;
  for (const HybridCase& hc : hybridCases(quick)) {
    SurfaceMesh s;
    const ojson organ = phantomOrgan(hc.phantom->name, hc.phantom->resolution, 0.1, s);
    ojson j = baseScene(std::string("hybrid-") + hc.phantom->name + "-" +
                            (hc.up ? "up-" : "down-") + forceTag(hc.force),
                        std::string("Hybrid FEM+PBD paper Sec. 8.3: ") +
                            (hc.up ? "upward tension" : "downward pressure") + " of " +
                            number(hc.force) + " N at the top of the " + hc.phantom->name +
                            " phantom, bottom tenth fixed, E = 5.5 kPa, nu = 0.3, no gravity.",
                        organ, duration);
    j["loads"] = verticalForce(topVertex(s), hc.up ? hc.force : -hc.force, duration + 1.0);
    // A 3 cm pressure patch (a probe head's footprint): at the default 1 cm, 20 N on 5.5 kPa
    // tissue draws the organ into a tentacle with no equilibrium inside the divergence box
    // (plugins/reference_fem/README.md).
    j["loads"][0]["radius"] = kHybridLoadRadius;
    j["compare_at"] = "equilibrium";
    j["models"] =
        ojson::array({model("hybrid_fem_pbd", "hybrid_fem_pbd"),
                      model("pbd", "pbd", {{"bending", true}}), model("massspring", "massspring")});
    addReference(j, referenceFem(refElements, kHybridReferenceOrder));
    out.push_back({hc.id(), j});
  }
  return out;
}

const char* kHybridNote =
    "The paper's table figures are not in the project's copy of the paper (lost in text "
    "extraction, see plugins/hybrid_fem_pbd/README.md); its columns are empty rather than "
    "guessed.";

std::vector<ojson> hybridRows(const Results& res, const fs::path& dir, bool quick, bool timing) {
  std::vector<ojson> rows;
  for (const HybridCase& hc : hybridCases(quick)) {
    const CaseResult& c = res.at(hc.id());
    ojson row;
    row["phantom"] = hc.phantom->name;
    row["force_N"] = hc.force;
    row["direction"] = hc.up ? "up" : "down";
    std::string status, note;
    for (const HybridModel& m : kHybridModels) {
      const RunRecord* r = c.run(m.plugin);
      const std::string st = statusOf(c, m.plugin, r);
      if (st != "ok") appendTo(status, std::string(m.key) + ": " + st);
      const std::string figure = hybridFigureKey(m, timing);
      row[figure] = timing ? stepMedian(r) : rmseMm(r, 50);
      row["paper_" + figure] = nullptr;
      if (r && !r->message.empty()) appendTo(note, std::string(m.key) + ": " + r->message);
    }
    const RunRecord* ref = c.run("reference_fem");
    if (timing) {
      row["fem_ms"] = stepMedian(ref);
      row["paper_fem_ms"] = nullptr;
    }
    if (c.missing.count("reference_fem")) {
      appendTo(status, "reference: " + statusOf(c, "reference_fem", nullptr));
    } else if (ref && ref->status != RunStatus::Ok) {
      appendTo(status, std::string("reference: ") + statusName(ref->status));
      appendTo(note, "reference: " + ref->message);
    }
    row["status"] = status.empty() ? "ok" : status;
    row["scene"] = relativeTo(c.sceneFile, dir);
    row["note"] = note;
    rows.push_back(row);
  }
  return rows;
}

/// The cases whose reference the hybrid tables check: per phantom the one with the largest
/// force, pressing down (kCheckedHybridUp: compression under the load is the harder case). The
/// phantoms' references differ in mesh and in load; one study per phantom keeps the cost at about
/// one case's reference x 1.5 per phantom rather than per row.
std::vector<std::string> hybridChecks(bool quick) {
  std::map<std::string, HybridCase> worst;
  for (const HybridCase& hc : hybridCases(quick)) {
    if (hc.up != kCheckedHybridUp) continue;
    auto it = worst.find(hc.phantom->name);
    if (it == worst.end() || hc.force > it->second.force)
      worst.insert_or_assign(hc.phantom->name, hc);
  }
  std::vector<std::string> out;
  for (const HybridPhantom& p : kHybridPhantoms)
    if (worst.count(p.name)) out.push_back(worst.at(p.name).id());
  return out;
}

/// hybrid-accuracy (timing false) or hybrid-timing: the same cases, other figures.
TableDef hybridTable(const TablesOptions& o, long long refElements, bool timing) {
  std::vector<TableColumn> figures;
  for (const HybridModel& m : kHybridModels) {
    const auto pair = withPaper(hybridFigureKey(m, timing),
                                std::string(m.header) + (timing ? " ms" : " rmse_50 mm"),
                                std::string("paper ") + m.header);
    figures.insert(figures.end(), pair.begin(), pair.end());
  }
  if (timing) {
    const auto fem = withPaper("fem_ms", "FEM ms per solve", "paper FEM");
    figures.insert(figures.end(), fem.begin(), fem.end());
  }
  const char* source = "hybrid FEM+PBD paper (Scientific Programming 2021), ";
  TableDef t =
      timing ? tableDef("hybrid-timing", "ms per step of hybrid, PBD, mass-spring and the fine FEM",
                        source + std::string("Tables 4-5"), {})
             : tableDef("hybrid-accuracy",
                        "RMSE of the 50 vertices nearest the load against the fine reference FEM",
                        source + std::string("Tables 2-3"), {});
  t.columns = columns({{{"phantom", "phantom"}, {"force_N", "force N"}, {"direction", "direction"}},
                       figures,
                       {{"status", "status"}, {"scene", "scene"}, {"note", "note"}}});
  if (timing) {
    t.notes = {"The same runs as hybrid-accuracy. FEM: reference_fem (" +
                   referenceTets(refElements, kHybridReferenceOrder) +
                   ", Neo-Hookean, quasi-static): wall time of one equilibrium solve at the "
                   "compared instant from rest, with load stepping where Newton needed it.",
               kHybridNote};
  } else {
    t.notes = {
        "Constant vertical point force at the top vertex nearest the top's centre, bottom "
        "tenth fixed, E = 5.5 kPa, nu = 0.3, no gravity, spread over a 3 cm pressure patch "
        "every model receives alike; 1 ms steps, each model compared once it settled (largest "
        "surface speed below 1e-4 m/s for 20 steps; " +
            number(o.quick ? 1.0 : 3.0) +
            " s cap: a model that has not settled by then is "
            "invalid); reference_fem with " +
            referenceTets(refElements, kHybridReferenceOrder) + " solved at equilibrium.",
        kHybridNote};
  }
  t.cases = hybridSceneCases(o.quick, refElements);
  t.checks = hybridChecks(o.quick);
  const bool quick = o.quick;
  t.rows = [quick, timing](const Results& res, const fs::path& dir) {
    return hybridRows(res, dir, quick, timing);
  };
  return t;
}

/// What a table says about one of its references: a note, and a warning when the reference is
/// not shown converged to 1% of the peak displacement.
struct ReferenceCheck {
  std::string note, warning;
};

/// The convergence study of case c's reference (convergence.h) at three levels, the finest being
/// the reference the table used (same params, same target count: the same mesh and answer), so
/// the estimate is the error of the figures in the table.
ReferenceCheck checkReference(const Case& c, const CaseResult& r, PluginLoader& loader,
                              const TablesOptions& o, Progress* progress) {
  ReferenceCheck out;
  const std::string what = "reference (" + c.id + ")";
  const ojson& ref = c.scene["reference"];
  const std::string plugin = ref.value("plugin", "");
  const RunRecord* run = r.run(ref.value("label", plugin));
  if (!run || run->status != RunStatus::Ok) {
    out.note = what + ": convergence not checked: " + statusOf(r, plugin, run);
    return out;
  }
  const ojson& params = ref["params"];
  ConvergeOptions co;
  co.baseElements = params.value("elements", 0LL);
  co.factors = kReferenceCheckFactors;
  co.outDir = o.outDir / "convergence" / c.id;
  co.cacheDir = o.cases.cacheDir;
  const fs::path sceneFile = o.outDir / "scenes" / (c.id + ".json");
  if (progress) progress->start("reference check " + c.id);
  ConvergenceResult res;
  try {
    res = runConvergence(c.scene, sceneFile.string(), loader, co, nullptr);
  } catch (const std::exception& e) {
    res.message = e.what();
  }
  std::string elements = "? tets";
  if (run->counts.count("elements"))
    elements = std::to_string(run->counts.at("elements")) + " tets";
  out.note = what + ": " + plugin + " P" + std::to_string(params.value("element_order", 1)) + " " +
             params.value("material", std::string("neo_hookean")) + ", " + elements + ", " +
             convergenceSummary(res) + "; study in " +
             relativeTo(co.outDir / "convergence.json", o.outDir) + ".";
  const std::string w = convergenceWarning(res);
  if (!w.empty()) out.warning = "warning: " + what + ": " + w + ".";
  if (progress)
    progress->finish("reference check " + c.id,
                     (w.empty() ? std::string("converged") : std::string("not shown converged")) +
                         (res.cached ? " (cached)" : ""));
  return out;
}

}  // namespace

std::vector<std::string> tableNames() {
  return {"metaballs-construction", "method-comparison", "bem-timing",
          "bem-accuracy",           "hybrid-accuracy",   "hybrid-timing"};
}

std::vector<std::string> tableWarnings(const std::vector<Table>& tables) {
  std::vector<std::string> out;
  std::set<std::string> seen;
  for (const Table& t : tables)
    for (const std::string& n : t.notes)
      if (n.rfind("warning: ", 0) == 0 && seen.insert(n).second) out.push_back(n);
  return out;
}

namespace {

/// The "calibration" table (--calibration): every case model that a calibration file names, at
/// its defaults and calibrated (its "+cal" twin, run in the same case), side by side.
Table calibrationTable(
    const std::vector<const Case*>& order,
    const std::map<std::string, std::vector<std::pair<std::string, std::string>>>& twins,
    const Results& results, const std::vector<CalibrationParams>& calibrations) {
  Table t;
  t.name = "calibration";
  t.title = "Default and calibrated parameters side by side (--calibration)";
  t.source = "";  // no paper: the same cases at default and calibrated parameters
  for (const CalibrationParams& c : calibrations)
    t.notes.push_back(c.plugin + "/" + c.model + ": " + c.file + " " + c.params.dump());
  t.columns = {{"case", "case"},
               {"model", "model"},
               {"rmse_50_default_mm", "rmse_50 default (mm)"},
               {"rmse_50_calibrated_mm", "rmse_50 calibrated (mm)"},
               {"rmse_all_default_mm", "rmse_all default (mm)"},
               {"rmse_all_calibrated_mm", "rmse_all calibrated (mm)"},
               {"loss_ratio_default", "loss ratio default"},
               {"loss_ratio_calibrated", "loss ratio calibrated"},
               {"status", "status"}};
  const auto metrics = [](const RunRecord* r, const char* suffix, ojson& row) {
    double r50 = NAN, all = NAN, loss = NAN;
    if (r && r->error) {
      for (const auto& [k, v] : r->error->rmseNearest)
        if (k == 50) r50 = v;
      all = r->error->rmseAll;
      loss = r->error->lossRatio;
    }
    row[std::string("rmse_50_") + suffix + "_mm"] = numberOrNull(1e3 * r50);
    row[std::string("rmse_all_") + suffix + "_mm"] = numberOrNull(1e3 * all);
    row[std::string("loss_ratio_") + suffix] = numberOrNull(loss);
  };
  for (const Case* c : order) {
    const auto it = results.find(c->id);
    if (it == results.end()) continue;
    for (const auto& [label, twin] : twins.at(c->id)) {
      const std::string original = label.empty() ? twin.substr(0, twin.size() - 4) : label;
      const RunRecord* a = it->second.run(original);
      const RunRecord* b = it->second.run(twin);
      ojson row = {{"case", c->id}, {"model", original}};
      metrics(a, "default", row);
      metrics(b, "calibrated", row);
      std::string status;
      if (!a || !b) status = "not run";
      if (a && a->status != RunStatus::Ok)
        status += "default " + std::string(statusName(a->status));
      if (b && b->status != RunStatus::Ok)
        status += (status.empty() ? "" : ", ") + std::string("calibrated ") + statusName(b->status);
      row["status"] = status.empty() ? "ok" : status;
      t.rows.push_back(row);
    }
  }
  return t;
}

}  // namespace

std::vector<Table> buildTables(const std::vector<std::string>& names, PluginLoader& loader,
                               const TablesOptions& options, Progress* progress) {
  const auto all = tableNames();
  std::vector<std::string> wanted;
  for (const std::string& n : names) {
    if (n == "all") {
      wanted.insert(wanted.end(), all.begin(), all.end());
    } else if (std::find(all.begin(), all.end(), n) == all.end()) {
      std::string list;
      for (const auto& t : all) list += (list.empty() ? "" : ", ") + t;
      throw InputError("tables", n, "unknown table (known: " + list + ", all)");
    } else {
      wanted.push_back(n);
    }
  }
  const long long refElements =
      options.referenceElements > 0
          ? options.referenceElements
          : (options.quick ? kQuickReferenceElements : kReferenceElements);
  const std::map<std::string, std::function<TableDef()>> make = {
      {"metaballs-construction", [&] { return metaballsConstruction(options); }},
      {"method-comparison", [&] { return methodComparison(options, refElements); }},
      {"bem-timing", [&] { return bemTiming(options); }},
      {"bem-accuracy", [&] { return bemAccuracy(options, loader, progress); }},
      {"hybrid-accuracy", [&] { return hybridTable(options, refElements, false); }},
      {"hybrid-timing", [&] { return hybridTable(options, refElements, true); }}};
  std::vector<TableDef> defs;
  std::set<std::string> seen;
  for (const std::string& n : wanted)
    if (seen.insert(n).second) defs.push_back(make.at(n)());
  // Every case once, in table order (hybrid-accuracy and hybrid-timing share theirs).
  std::vector<const Case*> order;
  std::set<std::string> ids;
  for (const TableDef& d : defs)
    for (const Case& c : d.cases)
      if (ids.insert(c.id).second) order.push_back(&c);
  if (progress) progress->addTotal(int(order.size()));

  // The cases go to the dispatcher (options.cases.dispatcher: serial, --jobs, MPI or Slurm);
  // the results are keyed by case id, so the tables do not depend on the finishing order.
  Results results;
  std::vector<SceneCase> sceneCases;
  std::map<std::string, std::vector<std::pair<std::string, std::string>>> twins;  // --calibration
  for (const Case* c : order) {
    CaseOptions co = options.cases;
    if (c->noCache) co.cacheDir = fs::path();
    ojson scene = c->scene;
    twins[c->id] = addCalibratedTwins(scene, options.calibrations);
    sceneCases.push_back({scene, options.outDir / "scenes" / (c->id + ".json"),
                          options.outDir / "runs" / c->id, co});
  }
  runSceneCases(
      sceneCases, loader, options.cases.dispatcher,
      [&](size_t i) {
        if (progress) progress->start(order[i]->id);
      },
      [&](size_t i, CaseResult&& r) {
        const Case* c = order[i];
        std::string summary;
        if (!r.error.empty()) {
          summary = "not run (" + r.error + ")";
        } else {
          for (const RunRecord& run : r.result->runs) {
            std::string part = run.label + " " + statusName(run.status);
            if (run.status == RunStatus::Failed && options.cases.child)
              part += " (" + run.message + ")";
            summary += (summary.empty() ? "" : ", ") + part;
          }
        }
        for (const auto& [plugin, why] : r.missing)
          summary += (summary.empty() ? "" : ", ") + plugin + " missing";
        if (r.resumed) summary += " (resumed)";
        if (progress) progress->finish(c->id, summary);
        results.emplace(c->id, std::move(r));
      });

  // Each distinct reference once (the hybrid tables share theirs).
  std::map<std::string, ReferenceCheck> checks;
  if (options.referenceCheck) {
    std::vector<const Case*> toCheck;
    for (const TableDef& d : defs)
      for (const std::string& id : d.checks)
        if (!checks.count(id) && results.count(id)) {
          checks[id] = {};
          for (const Case* c : order)
            if (c->id == id) toCheck.push_back(c);
        }
    if (progress) progress->addTotal(int(toCheck.size()));
    for (const Case* c : toCheck)
      checks[c->id] = checkReference(*c, results.at(c->id), loader, options, progress);
  }

  std::vector<Table> tables;
  for (const TableDef& d : defs) {
    Table t;
    t.name = d.name;
    t.title = d.title;
    t.source = d.source;
    t.notes = d.notes;
    if (!d.checks.empty() && !options.referenceCheck)
      t.notes.push_back("reference: convergence not checked (--no-reference-check).");
    for (const std::string& id : d.checks) {
      if (!checks.count(id)) continue;
      t.notes.push_back(checks.at(id).note);
      if (!checks.at(id).warning.empty()) t.notes.push_back(checks.at(id).warning);
    }
    t.columns = d.columns;
    for (ojson row : d.rows(results, options.outDir)) {
      // A row whose reference is not shown converged to 1% is flagged in its status, not only
      // noted under the table: the row of the checked case, and the rows sharing its reference
      // set-up (the hybrid tables check one case per phantom).
      for (const std::string& id : d.checks) {
        if (!checks.count(id) || checks.at(id).warning.empty() || !row.contains("status")) continue;
        const std::string scene = row.value("scene", "");
        const std::string phantom = row.value("phantom", "");
        const bool covered = scene == "scenes/" + id + ".json" ||
                             (!phantom.empty() && id.rfind("hybrid/" + phantom + "_", 0) == 0);
        if (!covered) continue;
        std::string status = row["status"].is_string() ? row["status"].get<std::string>() : "";
        appendTo(status, "reference not shown converged to 1% (see the notes)");
        row["status"] = status;
      }
      t.rows.push_back(inColumnOrder(row, d.columns));
    }
    writeTable(t, options.outDir);
    tables.push_back(std::move(t));
  }
  if (!options.calibrations.empty()) {
    Table t = calibrationTable(order, twins, results, options.calibrations);
    writeTable(t, options.outDir);
    tables.push_back(std::move(t));
  }
  return tables;
}

}  // namespace deform::harness
