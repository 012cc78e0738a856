// The table system (tables.h): the seven tables' definitions (one file each in this folder, on the
// TableDef seam of table_kit.h) run as one set of cases, their references checked, written.
#include "table_kit.h"

#include <deform_harness/calibration.h>
#include <deform_harness/child_process.h>
#include <deform_harness/convergence.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <functional>
#include <future>
#include <map>
#include <set>

namespace deform::harness {

using namespace tables;

namespace {

/// What a table says about one of its references: a note, and a warning when the reference is
/// not shown converged to 1% of the peak displacement.
struct ReferenceCheck {
  std::string note, warning;
  /// The rows' "reference" cell: which reference (order, tets) and its estimated error.
  std::string cell;
};

/// A study's reason (ConvergenceResult::reason) in a few words, for a table cell.
std::string reasonWords(const std::string& reason) {
  static const std::map<std::string, std::string> words = {
      {"levels_failed", "a level did not run"},      {"not_refining", "levels do not refine"},
      {"levels_too_close", "levels too close in h"}, {"coincide", "levels coincide"},
      {"not_monotone", "differences not monotone"},  {"not_asymptotic", "order not asymptotic"}};
  const auto it = words.find(reason);
  return it == words.end() ? reason : it->second;
}

std::string percentCell(double fraction) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.2g%%", 100 * fraction);
  return buf;
}

/// Case c's reference as its check names it: the words, plugin, order, run and study folder.
struct CheckedReference {
  std::string what, plugin, order;
  const ojson& ref;
  const RunRecord* run;
  fs::path studyDir;
};

CheckedReference checkedReference(const Case& c, const CaseResult& r, const TablesOptions& o) {
  const ojson& ref = c.scene["reference"];
  const std::string plugin = ref.value("plugin", "");
  return {"reference (" + c.id + ")",
          plugin,
          "P" + std::to_string(ref["params"].value("element_order", 1)),
          ref,
          r.run(ref.value("label", plugin)),
          o.outDir / "convergence" / c.id};
}

/// The convergence study of case c's reference (convergence.h) at three levels, the finest being
/// the reference the table used (same params, same target count: the same mesh and answer), so
/// the estimate is the error of the figures in the table. A reference that did not run is not
/// checked: `out` gets its cell and no study is returned.
std::optional<ConvergenceStudyInput> referenceStudy(const Case& c, const CaseResult& r,
                                                    const TablesOptions& o, ReferenceCheck& out) {
  const CheckedReference ref = checkedReference(c, r, o);
  if (!ref.run || ref.run->status != RunStatus::Ok) {
    out.note = ref.what + ": convergence not checked: " + statusOf(r, ref.plugin, ref.run);
    out.cell = ref.order + ", not checked (" + statusOf(r, ref.plugin, ref.run) + ")";
    return std::nullopt;
  }
  // The reference's own size h: levels 2h, 1.4h, h, and h / 1.4 where the surface bounds them.
  ConvergenceStudyInput in{c.scene, (o.outDir / "scenes" / (c.id + ".json")).string(),
                           referenceCheckOptions()};
  ConvergeOptions& co = in.options;
  co.outDir = ref.studyDir;
  co.cacheDir = o.cases.cacheDir;
  co.reuseSolves = true;  // the finest level is the case's reference, solved once
  // The levels run as the cases ran: child processes through the tables' dispatcher (two at a
  // time with --jobs 2, on the ranks with --mpi), or in this process with --in-process.
  co.child = o.cases.child;
  co.dispatcher = o.cases.dispatcher;
  return in;
}

/// The cell, note and warning of case c's reference from its study.
ReferenceCheck referenceCheckOf(const Case& c, const CaseResult& r, const ConvergenceResult& res,
                                const TablesOptions& o) {
  ReferenceCheck out;
  const CheckedReference ref = checkedReference(c, r, o);
  std::string elements = "? tets";
  if (ref.run && ref.run->counts.count("elements"))
    elements = std::to_string(ref.run->counts.at("elements")) + " tets";
  out.cell = ref.order + ", " + elements + ", ";
  if (res.graded) out.cell += "graded toward the interaction, ";
  if (std::isfinite(res.relativeError)) {
    out.cell += "error " + percentCell(res.relativeError) + " (est.)";
    if (!res.asymptotic) out.cell += ", " + reasonWords(res.reason);
  } else {
    out.cell += "no estimate (" + reasonWords(res.reason) + ")";
    if (std::isfinite(res.boundRelative))
      out.cell += ", levels differ by " + percentCell(res.boundRelative);
  }
  out.note = ref.what + ": " + ref.plugin + " " + ref.order + " " +
             ref.ref["params"].value("material", std::string("neo_hookean")) + ", " + elements +
             ", " + convergenceSummary(res) + "; study in " +
             relativeTo(ref.studyDir / "convergence.json", o.outDir) + ".";
  const std::string w = convergenceWarning(res);
  if (!w.empty()) out.warning = "warning: " + ref.what + ": " + w + ".";
  return out;
}

}  // namespace

std::vector<std::string> tableNames() {
  return {"metaballs-construction", "method-comparison", "bem-timing",   "bem-accuracy",
          "hybrid-accuracy",        "hybrid-timing",     "verification", "truth-cube"};
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

/// Per case id: the (label, twin label) of each run that --calibration doubled.
using Twins = std::map<std::string, std::vector<std::pair<std::string, std::string>>>;

/// The "calibration" table (--calibration): every case model that a calibration file names, at
/// its defaults and calibrated (its "+cal" twin, run in the same case), side by side.
Table calibrationTable(const std::vector<const Case*>& order, const Twins& twins,
                       const Results& results, const std::vector<CalibrationParams>& calibrations) {
  Table t;
  t.name = "calibration";
  t.title = "Default and calibrated parameters side by side (--calibration)";
  t.source = "";  // no paper: the same cases at default and calibrated parameters
  for (const CalibrationParams& c : calibrations) {
    std::string organs;
    for (const std::string& o : c.organs) organs += (organs.empty() ? "" : "; ") + o;
    t.notes.push_back(c.plugin + "/" + c.model + ": " + c.file + " " + c.params.dump() +
                      (organs.empty() ? std::string(", applied to every organ (no organs recorded)")
                                      : ", fitted on and applied to " + organs + " only"));
  }
  t.columns = {{"case", "case"},
               {"model", "model"},
               {"rmse_50_default_mm", "rmse_50 default (mm)"},
               {"rmse_50_calibrated_mm", "rmse_50 calibrated (mm)"},
               {"rmse_all_default_mm", "rmse_all default (mm)"},
               {"rmse_all_calibrated_mm", "rmse_all calibrated (mm)"},
               {"loss_ratio_default", "loss ratio default"},
               {"loss_ratio_calibrated", "loss ratio calibrated"},
               {"status", "status"},
               {"note", "note"}};
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
      // Each run's status as the paper tables give it: a run that did not do what the scene
      // asked (did not settle, an empty grasp) is "invalid (why)", never ok.
      std::string status;
      if (!a || !b) status = "not run";
      for (const auto& [which, r] : {std::pair{"default ", a}, std::pair{"calibrated ", b}}) {
        if (!r) continue;
        const std::string st = statusOf(it->second, r->plugin, r);
        if (st != "ok") status += (status.empty() ? "" : ", ") + std::string(which) + st;
      }
      row["status"] = status.empty() ? "ok" : status;
      // A twin whose other parameters are not those its calibration was fitted with (e.g. a
      // surface network's thickness on a volume network), or whose fit ended at a bound of its
      // search, says so.
      std::string note;
      if (b) {
        const CalibrationParams* cal =
            calibrationFor(calibrations, b->plugin, b->model,
                           calibrationOrgan(c->scene.value("organ", ojson::object())), true);
        if (cal) note = calibratedRunNote(*cal, b->params);
      }
      row["note"] = note;
      t.rows.push_back(row);
    }
  }
  return t;
}

/// The tables named (`all` for every one), in order; an unknown name is an input error.
std::vector<std::string> wantedTables(const std::vector<std::string>& names) {
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
  return wanted;
}

/// One progress line for a finished case: each run's status, the missing plugins.
std::string caseSummary(const CaseResult& r, bool child) {
  std::string summary;
  if (!r.error.empty()) {
    summary = "not run (" + r.error + ")";
  } else {
    for (const RunRecord& run : r.result->runs) {
      std::string part = run.label + " " + statusName(run.status);
      if (run.status == RunStatus::Failed && child) part += " (" + run.message + ")";
      summary += (summary.empty() ? "" : ", ") + part;
    }
  }
  for (const auto& [plugin, why] : r.missing)
    summary += (summary.empty() ? "" : ", ") + plugin + " missing";
  if (r.resumed) summary += " (resumed)";
  return summary;
}

/// Runs every case (with its --calibration twins, recorded in `twins`) through the dispatcher
/// (options.cases.dispatcher: serial, --jobs, MPI or Slurm); the results are keyed by case id, so
/// the tables do not depend on the finishing order. `onSlotFree` is called once, in this thread,
/// when a case finishes with every case handed out (a worker is then idle to the end), or after
/// the last case when that never happened.
Results runCases(const std::vector<const Case*>& order, PluginLoader& loader,
                 const TablesOptions& options, Progress* progress, Twins& twins,
                 const std::function<void()>& onSlotFree) {
  Results results;
  size_t started = 0;
  bool slotFreed = false;
  const auto slotFree = [&] {
    if (slotFreed) return;
    slotFreed = true;
    if (onSlotFree) onSlotFree();
  };
  std::vector<SceneCase> sceneCases;
  for (const Case* c : order) {
    CaseOptions co = options.cases;
    // Reference solves are shared through the cache by problem (runner.h, reuseReference):
    // between tables that pose the same case, with the reference checks' finest levels, and
    // with later commands on the same cache.
    co.reuseReference = true;
    if (c->noCache) co.cacheDir = fs::path();
    ojson scene = c->scene;
    twins[c->id] = addCalibratedTwins(scene, options.calibrations);
    sceneCases.push_back({scene, options.outDir / "scenes" / (c->id + ".json"),
                          options.outDir / "runs" / c->id, co});
  }
  runSceneCases(
      sceneCases, loader, options.cases.dispatcher,
      [&](size_t i) {
        ++started;
        if (progress) progress->start(order[i]->id);
      },
      [&](size_t i, CaseResult&& r) {
        const Case* c = order[i];
        if (progress) progress->finish(c->id, caseSummary(r, options.cases.child.has_value()));
        results.emplace(c->id, std::move(r));
        if (started == order.size()) slotFree();
      });
  slotFree();
  return results;
}

/// Each distinct reference the tables check, once (the hybrid tables share theirs); the studies'
/// levels run side by side (runConvergences).
std::map<std::string, ReferenceCheck> checkReferences(const std::vector<TableDef>& defs,
                                                      const std::vector<const Case*>& order,
                                                      const Results& results, PluginLoader& loader,
                                                      const TablesOptions& options,
                                                      Progress* progress) {
  std::map<std::string, ReferenceCheck> checks;
  if (!options.referenceCheck) return checks;
  std::vector<const Case*> toCheck;
  for (const TableDef& d : defs)
    for (const std::string& id : checkedCases(d, results))
      if (!checks.count(id) && results.count(id)) {
        checks[id] = {};
        for (const Case* c : order)
          if (c->id == id) toCheck.push_back(c);
      }
  std::vector<ConvergenceStudyInput> studies;
  std::vector<const Case*> studied;
  for (const Case* c : toCheck)
    if (auto in = referenceStudy(*c, results.at(c->id), options, checks[c->id])) {
      studies.push_back(std::move(*in));
      studied.push_back(c);
    }
  if (progress) progress->addTotal(int(studied.size()));
  for (const Case* c : studied)
    if (progress) progress->start("reference check " + c->id);
  const std::vector<ConvergenceResult> res = runConvergences(studies, loader, nullptr);
  for (size_t i = 0; i < studied.size(); ++i) {
    const Case& c = *studied[i];
    checks[c.id] = referenceCheckOf(c, results.at(c.id), res[i], options);
    if (progress)
      progress->finish("reference check " + c.id,
                       (checks[c.id].warning.empty() ? std::string("converged")
                                                     : std::string("not shown converged")) +
                           (res[i].cached ? " (cached)" : ""));
  }
  return checks;
}

/// A table from its definition, the results and the reference checks.
Table assembleTable(const TableDef& d, const Results& results,
                    const std::map<std::string, ReferenceCheck>& checks,
                    const TablesOptions& options) {
  Table t{.name = d.name,
          .title = d.title,
          .source = d.source,
          .notes = d.notes,
          .columns = d.columns,
          .rows = {}};
  const std::vector<std::string> checked = checkedCases(d, results);
  if (!checked.empty() && !options.referenceCheck)
    t.notes.push_back("reference: convergence not checked (--no-reference-check).");
  for (const std::string& id : checked) {
    if (!checks.count(id)) continue;
    t.notes.push_back(checks.at(id).note);
    if (!checks.at(id).warning.empty()) t.notes.push_back(checks.at(id).warning);
  }
  // Every row judged against a checked reference says which one and its estimated error.
  const bool referenceColumn = !checked.empty() && options.referenceCheck;
  if (referenceColumn) {
    auto at = std::find_if(t.columns.begin(), t.columns.end(),
                           [](const TableColumn& c) { return c.key == "status"; });
    t.columns.insert(at, {"reference", "reference"});
  }
  for (ojson row : d.rows(results, options.outDir)) {
    // A row whose reference is not shown converged to 1% is flagged in its status, not only
    // noted under the table: the row of the checked case, and the rows sharing its reference
    // set-up (the hybrid tables check one case per phantom and direction).
    for (const std::string& id : checked) {
      if (!checks.count(id)) continue;
      const std::string scene = row.value("scene", "");
      const std::string phantom = row.value("phantom", "");
      const std::string direction = row.value("direction", "");
      const std::string group =
          "hybrid/" + phantom + "_" + (direction.empty() ? "" : direction + "_");
      const bool covered =
          scene == "scenes/" + id + ".json" || (!phantom.empty() && id.rfind(group, 0) == 0);
      if (!covered) continue;
      row["reference"] =
          checks.at(id).cell + (scene == "scenes/" + id + ".json" ? "" : " (study of " + id + ")");
      if (checks.at(id).warning.empty() || !row.contains("status")) continue;
      std::string status = row["status"].is_string() ? row["status"].get<std::string>() : "";
      appendTo(status, "reference not shown converged to 1% (see the notes)");
      row["status"] = status;
    }
    if (referenceColumn && !row.contains("reference")) row["reference"] = nullptr;
    t.rows.push_back(inColumnOrder(row, t.columns));
  }
  return t;
}

}  // namespace

std::vector<Table> buildTables(const std::vector<std::string>& names, PluginLoader& loader,
                               const TablesOptions& options, Progress* progress) {
  const std::vector<std::string> wanted = wantedTables(names);
  const long long refElements =
      options.referenceElements > 0
          ? options.referenceElements
          : (options.quick ? kQuickReferenceElements : kReferenceElements);
  const long long hybridElements =
      options.referenceElements > 0 ? options.referenceElements : kHybridReferenceElements;
  const std::map<std::string, std::function<TableDef()>> make = {
      {"metaballs-construction", [&] { return metaballsConstruction(options); }},
      {"method-comparison", [&] { return methodComparison(options, refElements); }},
      {"bem-timing", [&] { return bemTiming(options); }},
      {"bem-accuracy", [&] { return bemAccuracy(options, loader, progress); }},
      {"hybrid-accuracy", [&] { return hybridTable(options, hybridElements, false); }},
      {"hybrid-timing", [&] { return hybridTable(options, hybridElements, true); }},
      {"verification", [&] { return verification(options, loader); }},
      {"truth-cube", [&] { return truthCube(options, loader); }}};
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

  Twins twins;  // --calibration
  // The tables' own work that needs no case starts when the cases leave a worker idle (every
  // case handed out and one finished), not earlier, so that it never shares a core with a
  // timed case on a machine the dispatcher fills; it runs on beside the reference checks.
  std::vector<std::future<void>> background;
  const Results results = runCases(order, loader, options, progress, twins, [&] {
    for (const TableDef& d : defs)
      if (d.background) background.push_back(std::async(std::launch::async, d.background));
  });
  const std::map<std::string, ReferenceCheck> checks =
      checkReferences(defs, order, results, loader, options, progress);
  for (std::future<void>& f : background) f.get();

  std::vector<Table> tables;
  for (const TableDef& d : defs) {
    Table t = assembleTable(d, results, checks, options);
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
