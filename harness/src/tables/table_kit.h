// The tables' shared kit (internal to harness/src/tables/): generated scenes (phantom organs with
// their support, loads, graspers, the reference FEM), figures read out of runs, and the TableDef
// seam: a table is its columns and notes, its cases as scenes, and a function from the cases'
// results to its rows. One file per paper table fills it; tables.cpp runs the cases (each once
// even when two tables share it), checks the references and writes the tables.
#pragma once

#include <deform/engine/plugin_loader.h>
#include <deform/sdk/mesh.h>
#include <deform_harness/cases.h>
#include <deform_harness/format.h>
#include <deform_harness/progress.h>
#include <deform_harness/tables.h>

#include <array>
#include <filesystem>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace deform::harness::tables {

namespace fs = std::filesystem;
using ojson = nlohmann::ordered_json;

/// Element order of the method-comparison reference: quadratic (10-node) tets, since linear
/// ones are ~10% too stiff on the liver at any affordable size (plugins/reference_fem/README.md).
inline constexpr int kReferenceOrder = 2;

/// The hybrid tables' reference (quadratic tets too): target tets, the same with --quick, and a
/// budget of Newton iterations per solve. Their cases press up to 20 N on a 3 cm patch of 5.5 kPa
/// tissue (7 kPa, above E): pressed down with 5 N or more, Newton crosses a non-convex stretch
/// (50-580 iterations) or ends where the surface passes through itself, which a reference without
/// self-contact cannot pass; the budget ends such a solve as not converged (the row then reads
/// against an invalid reference) instead of after minutes. 4,000 targets: below about that, the
/// cube's surface triangles under the patch are too large to bend with it (26% low at the peak,
/// docs/notes/issue-33-converge-by-h.md).
inline constexpr long long kHybridReferenceElements = 4000;
inline constexpr long long kHybridReferenceNewtonBudget = 50;

/// Target tets of the reference (a multiple of 8: the check's coarsest level is 1/8 of it).
inline constexpr long long kReferenceElements = 20000, kQuickReferenceElements = 4000;

/// "2N", "0p5N": a force as part of a file name.
std::string forceTag(double f);

/// Appends `part` to a "; "-separated list (nothing when part is empty).
void appendTo(std::string& list, const std::string& part);

ojson model(const std::string& plugin, const std::string& label, ojson params = ojson::object());

ojson material();

/// Organ block of a phantom with the bottom `fixedFraction` of its height fixed (a box a little
/// larger than the organ in x and y); the phantom's mesh goes to meshOut.
ojson phantomOrgan(const std::string& name, double resolution, double fixedFraction,
                   SurfaceMesh& meshOut);

ojson baseScene(const std::string& name, const std::string& description, ojson organ,
                double duration);

/// The reference of a scene, its error samples (the 10 and 50 vertices nearest the load).
void addReference(ojson& scene, ojson reference);

/// The tables' reference FEM with `elements` target tets of the given order (1 or 2).
ojson referenceFem(long long elements, int order);

/// "20000 target P2 (10-node) tets": how the notes name the reference's elements.
std::string referenceTets(long long elements, int order);

/// The surface vertex nearest the centre of the top of the bounding box.
Vec3 topVertex(const SurfaceMesh& s);

/// A constant vertical point force fz (N) at `at` from t = 0 to `end`.
ojson verticalForce(const Vec3& at, double fz, double end);

/// A grasper closing at t = 0 on the point `depth` below the organ's top vertex (so that models
/// whose nodes are interior, e.g. sphere centres, have nodes within reach) and lifting `lift`
/// metres over the run.
ojson graspFromTop(const SurfaceMesh& s, double depthFraction, double radiusFraction, double lift,
                   double duration);

/// Columns of our figure and the paper's beside it: {key, header}, {paper_key, paperHeader}
/// ("paper " + header when paperHeader is empty).
std::vector<TableColumn> withPaper(const std::string& key, const std::string& header,
                                   const std::string& paperHeader = "");

/// Concatenated column groups.
std::vector<TableColumn> columns(std::initializer_list<std::vector<TableColumn>> groups);

/// Value of a run's count, or null.
ojson countOf(const RunRecord* r, const std::string& key);

ojson stepMedian(const RunRecord* r);

/// A figure of the run's error (null without one).
ojson errorFigure(const RunRecord* r, const std::function<double(const ErrorMetrics&)>& get);

/// rmse_k in mm (null when the run has no such figure).
ojson rmseMm(const RunRecord* r, int k);

/// reference_displacement_k in mm: the displacement rmse_k measures (null without it).
ojson referenceDisplacementMm(const RunRecord* r, int k);

ojson lossRatio(const RunRecord* r);

/// The precomputation time of a run that stepped, or null.
ojson precomputeS(const RunRecord* r);

/// The status cell of a row: "ok", "diverged", ..., "invalid (why)" for a run that ended but did
/// not do what the scene asked (DESIGN "Metrics": validity), or "missing plugin X: why".
std::string statusOf(const CaseResult& c, const std::string& plugin, const RunRecord* r);

/// "against an invalid reference (reference: invalid (why))" when the case's reference ran but
/// its answer is not one to measure errors against (e.g. its solver did not converge: the row's
/// errors are against it); "reference: failed (message)" (or diverged, unsupported) when it gave
/// no answer; "" otherwise.
std::string referenceStatus(const CaseResult& c);

/// A note on the row: the run's message and notes, and a missing reference.
std::string noteOf(const CaseResult& c, const RunRecord* r, bool wantsError);

std::string relativeTo(const fs::path& p, const fs::path& base);

/// The cells every one-model row ends with: the status of `plugin`'s run r, the scene to rerun
/// it, and the note.
void caseCells(ojson& row, const CaseResult& c, const std::string& plugin, const RunRecord* r,
               const fs::path& dir, bool wantsError);

struct Case {
  std::string id;  ///< "<group>/<name>": scenes/<id>.json, runs/<id>/
  ojson scene;
  bool noCache = false;  ///< time the precomputation itself
};

using Results = std::map<std::string, CaseResult>;

/// The case of a row, or nullptr after marking the row as skipped by --quick (or not run).
const CaseResult* caseOrSkipped(const Results& res, const std::string& id, bool quick, ojson& row);

struct TableDef {
  std::string name, title, source;
  std::vector<std::string> notes;
  /// Cases whose reference the table checks for convergence: one per distinct reference.
  std::vector<std::string> checks;
  /// When set, picks the checked cases from the results instead (the hybrid tables: per phantom
  /// and direction, the largest load whose reference is valid).
  std::function<std::vector<std::string>(const Results&)> pickChecks;
  std::vector<TableColumn> columns;
  std::vector<Case> cases;
  std::function<std::vector<ojson>(const Results&, const fs::path& outDir)> rows;
  /// The table's own work that needs no case (may be empty): buildTables runs it in a thread of
  /// its own beside the reference checks, before rows(). It must not touch the loader or the
  /// progress (neither is shared between threads), and rows() must do it when it did not run.
  std::function<void()> background;
};

/// The cases whose reference table d checks: d.pickChecks(results) when set, else d.checks.
std::vector<std::string> checkedCases(const TableDef& d, const Results& results);

TableDef tableDef(const std::string& name, const std::string& title, const std::string& source,
                  std::vector<TableColumn> cols);

/// The cells of a row in the order of the table's columns (keys without a column after them).
ojson inColumnOrder(const ojson& row, const std::vector<TableColumn>& cols);

// ---- the tables, one file each

TableDef metaballsConstruction(const TablesOptions& o);
TableDef methodComparison(const TablesOptions& o, long long refElements);
TableDef bemTiming(const TablesOptions& o);
TableDef bemAccuracy(const TablesOptions& o, PluginLoader& loader, Progress* progress);
/// The hybrid cases whose reference the tables check (their pickChecks): per phantom and
/// direction, the one with the largest force whose reference is valid; where none is, the
/// largest (its cell says why).
std::vector<std::string> hybridChecks(const Results& res, bool quick);
/// hybrid-accuracy (timing false) or hybrid-timing: the same cases, other figures.
TableDef hybridTable(const TablesOptions& o, long long refElements, bool timing);
/// verification: reference_fem at its defaults (and CalculiX when its plugin loads) against
/// analytic and published solutions.
TableDef verification(const TablesOptions& o, PluginLoader& loader);

/// The Truth Cube's bead file (data/truth-cube/README.md): i, j, k and the positions (m, the
/// scanner frame, -z up) at rest and at each compression level, whose nominal strains come from
/// the "N% strain" labels of the line above the "i,j,k,..." header. Throws InputError naming the
/// file and line.
struct TruthCubeData {
  struct Bead {
    std::array<int, 3> ijk{};
    std::vector<Vec3> positions;  ///< rest, then one per level
  };
  std::string file;
  std::vector<double> strains;  ///< per level, e.g. 0.05
  std::vector<Bead> beads;
};
TruthCubeData readTruthCubeData(const std::string& file);
/// The beads at `level` (0: rest) in the scene's frame (z up, the 80 mm cube centred at the
/// origin), #beads by 3, m.
MatX3 truthCubeSceneFrame(const TruthCubeData& d, int level);
/// A model's bead figures at `level` against the scan, after a rigid translation registration
/// (least squares over all beads, or the bottom layer's mean). m.
struct TruthCubeFigures {
  double rms = 0, maxError = 0, measuredRms = 0;
  std::vector<double> layerRms;  ///< per bead layer k, bottom to top
  double bulge = 0, measuredBulge = 0;
};
TruthCubeFigures truthCubeFigures(const TruthCubeData& d, const MatX3& modelRest,
                                  const MatX3& model, int level, bool bottomLayer);
/// truth-cube: the Truth Cube experiment replayed (reference_fem, CalculiX where it loads, and a
/// row per other model saying why it has no bead figures yet).
TableDef truthCube(const TablesOptions& o, PluginLoader& loader);

}  // namespace deform::harness::tables
