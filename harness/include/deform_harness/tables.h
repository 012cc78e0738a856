// deformbench harness: the seven tables the project regenerates (DESIGN.md "Tables the project
// must regenerate"), each from generated scenes run through the plugin loader and the runner.
// A table names its plugins and their parameters as data; the harness never links a plugin's
// code. The paper's own figures are printed beside ours where the paper gives them.
//
//   metaballs-construction  Pan et al. 2015 (metaballs), Table 1
//   method-comparison       Pan et al. 2015, Table 2 (+ our error against the reference FEM)
//   bem-timing              Zhu, Gu & Zhou 2010 (particles + BEM), Table 1
//   bem-accuracy            Zhu, Gu & Zhou 2010, Table 2
//   hybrid-accuracy         hybrid FEM+PBD paper (Scientific Programming 2021), Tables 2-3
//   hybrid-timing           the same paper, Tables 4-5
//   verification            reference_fem and CalculiX against analytic and published solutions
//
// Output in DIR: <table>.md, <table>.csv, <table>.json; scenes/<group>/<case>.json (rerun any
// row with `deformbench run`); runs/<group>/<case>/ (results.json and surfaces of that case, and
// with child processes its log.txt and case.json).
//
// With options.cases.child set (the deformbench command's default) each case runs in its own
// child process with a time limit (cases.h, ChildCaseOptions): a crash or a hang becomes rows
// with status failed (the signal or the timeout) and the tables go on; --resume reuses finished
// cases. Without it the cases run in this process (library callers, tests).
//
// Reference check (issue F2): after the cases, each distinct reference a table uses
// (method-comparison: one per organ; the hybrid tables: per phantom and direction the largest
// force whose reference is valid) is
// run through the convergence study of convergence.h at 2, 1.4 and 1 x its edge length, the
// finest level being the table's reference itself, in this process and cached. The table's notes
// get "reference (CASE): ..., estimated discretisation error X% of the peak (levels ..., p = ...)"
// and, when the estimate is above 1%, not asymptotic or missing, a "warning: reference (CASE):"
// note; the study is written to DIR/convergence/CASE/. Each row judged against a checked
// reference gets a "reference" cell: its order, tets and estimated error (or why none).
#pragma once

#include <deform_harness/cases.h>
#include <deform_harness/progress.h>

#include <filesystem>
#include <string>
#include <vector>

namespace deform::harness {

struct TablesOptions {
  bool quick = false;  ///< fewer cases, shorter runs and a coarser reference (for CI)
  std::filesystem::path outDir;
  CaseOptions cases;
  /// Target tets of the reference FEM (quadratic tets); 0: the default (tables.cpp).
  long long referenceElements = 0;
  /// Run the convergence study of each distinct reference (convergence.h) and put its estimate
  /// in the table's notes, with a warning line when it is not converged to 1% of the peak.
  bool referenceCheck = true;
  /// --calibration: every case model a calibration names runs twice in its case, at its
  /// defaults and calibrated ("+cal"), and a further table "calibration" shows both.
  std::vector<CalibrationParams> calibrations;
  /// --surface-baselines: the hybrid tables run PBD and mass-spring on the organ's surface mesh
  /// alone, as the hybrid paper did, instead of on its volume (`network = volume`).
  bool surfaceBaselines = false;
  /// --data of truth-cube: the bead file ("": data/truth-cube/uniaxial_positions.csv of the
  /// source tree).
  std::string truthCubeData;
  /// --contact of truth-cube: the plate's contact, "bonded" (default) or "sliding" (the normal
  /// displacement only: a lubricated platen).
  std::string truthCubeContact = "bonded";
};

/// Names of the tables, in DESIGN.md's order.
std::vector<std::string> tableNames();

/// Builds the named tables ("all" expands to every one; an unknown name is an InputError),
/// runs their cases (each case once even when two tables share it), writes every file into
/// options.outDir and returns the tables. progress may be null.
/// The "warning: ..." notes of the tables (each once, in order): what the command prints at the
/// end of its output.
std::vector<std::string> tableWarnings(const std::vector<Table>& tables);

std::vector<Table> buildTables(const std::vector<std::string>& names, PluginLoader& loader,
                               const TablesOptions& options, Progress* progress);

/// How a model replays the Truth Cube in `tables truth-cube`, and in `calibrate --truth-cube`.
struct TruthCubeModel {
  nlohmann::ordered_json entry;  ///< its scene entry: plugin, label (the plugin) and params
  bool dynamic = false;          ///< settles in a scene per level; else all levels in one scene
  std::string problem;           ///< why it cannot (a missing plugin, no markers); "" if it can
};
TruthCubeModel truthCubeModel(PluginLoader& loader, const std::string& plugin, bool quick);

/// The compression levels (strains) of a bead file ("": the shipped data). InputError on bad
/// data.
std::vector<double> truthCubeStrains(const std::string& dataFile);

/// The scene of one level (0-based) of the Truth Cube for one model, the beads measured at its
/// compared instant (the plate moved in one quasi-static step, or over 1 s and held until the
/// model settles): what `calibrate --truth-cube` trains and validates on. InputError on a level
/// the data do not hold or an unknown contact.
nlohmann::ordered_json truthCubeLevelScene(const std::string& dataFile, size_t level,
                                           const TruthCubeModel& model, const std::string& contact,
                                           bool quick);

}  // namespace deform::harness
