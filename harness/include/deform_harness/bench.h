// deformbench harness: CI timing tables. `bench --out FILE.json` times a fixed set of
// model x scene cases (short runs through the loader and the runner, each repeated and reduced
// to the median of the per-run step medians); `bench --compare OLD NEW` prints the ratios and
// flags a case that slowed by more than the threshold AND by more than the noise (the larger of
// the two files' spreads, max - min over the repeats).
#pragma once

#include <deform_harness/cases.h>
#include <deform_harness/progress.h>

#include <filesystem>
#include <iosfwd>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace deform::harness {

struct BenchOptions {
  std::filesystem::path out;  ///< FILE.json
  int repeat = 3;
  int steps = 100;                ///< steps per run
  std::vector<std::string> only;  ///< case ids (or model names) to run; empty: all
  CaseOptions cases;
};

/// Runs the fixed case set; writes options.out (format "deformbench-bench/1"); returns it.
nlohmann::ordered_json runBench(PluginLoader& loader, const BenchOptions& options,
                                Progress* progress);

struct BenchComparison {
  struct Row {
    std::string id;
    double oldMs = NAN, newMs = NAN, ratio = NAN, noiseMs = NAN;
    /// The case's time over PBD's on the same scene in the same run (x PBD), in each file, and
    /// new over old; NaN for PBD itself or where a file has no PBD case on that scene.
    double oldXPbd = NAN, newXPbd = NAN, xRatio = NAN;
    /// "ok", "SLOWER", "faster", "new", "missing", "not timed", "not compared" (PBD itself,
    /// or a case with no PBD beside it, when the two machines do not match), or "params changed"
    /// (the files ran the case with other parameters: not judged)
    std::string verdict;
  };
  std::vector<Row> rows;
  int regressions = 0;
  /// Absolute times are judged only between matching machines (same CPU model and core count,
  /// each run's one-minute load average at most half its cores); otherwise why not.
  bool absolute = false;
  std::string absoluteWhy;
};

/// Compares two bench files (InputError for a file that is not one). Each case is judged by its
/// ratio to PBD on the same scene within each run, which a slower or busier machine leaves
/// alone; absolute milliseconds only when the machines match (BenchComparison::absolute).
BenchComparison compareBench(const nlohmann::json& oldDoc, const nlohmann::json& newDoc,
                             double threshold);
/// Reads a bench file; InputError naming it when unreadable or of another format.
nlohmann::json readBenchFile(const std::string& path);
/// Prints the comparison as a table.
void printBenchComparison(const BenchComparison& c, double threshold, std::ostream& out);

}  // namespace deform::harness
