// deformbench tables: the papers' tables, their cases run through the dispatcher.
#include "cli.h"

#include <deform/engine/plugin_loader.h>
#include <deform_harness/child_process.h>
#include <deform_harness/progress.h>
#include <deform_harness/tables.h>

#include <fstream>
#include <iostream>

namespace deform::harness::cli {

namespace {

struct TablesArgs {
  std::vector<std::string> names;
  CommonArgs common;
  long long referenceElements = 0;
  double timeout = 0;
  bool resume = false;
  bool retryFailed = false;
  bool inProcess = false;
  bool noReferenceCheck = false;
  bool surfaceBaselines = false;
  std::string truthCubeData;
  std::string truthCubeContact = "bonded";
  DispatchArgs dispatch;
  std::vector<std::string> calibrations;

  void declare(CLI::App* tables) {
    tables->add_option("name", names, "table name(s) or all")->required();
    tables->add_option("--out", common.out, "output folder")->required();
    tables
        ->add_option(
            "--reference-elements", referenceElements,
            "target tets of the reference FEM, quadratic (default 20000, 4000 with --quick; the "
            "hybrid tables 4000)")
        ->check(positiveValue(true));
    tables->add_flag("--no-reference-check", noReferenceCheck,
                     "skip the convergence study of each table's reference (three solves at 2, "
                     "1.4 and 1 x its edge length; cached)");
    tables->add_flag("--surface-baselines", surfaceBaselines,
                     "hybrid tables: PBD and mass-spring on the organ's surface mesh alone, as the "
                     "paper ran them (default: on its volume, network = volume)");
    tables->add_option(
        "--data", truthCubeData,
        "truth-cube: a bead file of the layout of data/truth-cube/uniaxial_positions.csv "
        "(default: that file)");
    tables
        ->add_option("--contact", truthCubeContact,
                     "truth-cube: the plate's contact, bonded (default) or sliding (the normal "
                     "displacement prescribed, the tangential free: a lubricated plate)")
        ->check(CLI::IsMember({"bonded", "sliding"}));
    tables->add_flag("--explain", common.explain,
                     "say what each case loaded, built, cached, skipped");
    tables
        ->add_option("--timeout", timeout,
                     "seconds per case, each case running in its own process (default 900)")
        ->check(positiveValue(false));
    auto* tablesResume =
        tables->add_flag("--resume", resume, "reuse the cases already finished in --out");
    tables
        ->add_flag("--retry-failed", retryFailed,
                   "with --resume: run the cases with a failed run (crash, timeout) again")
        ->needs(tablesResume);
    tables->add_flag("--in-process", inProcess,
                     "run the cases in this process (no time limit, a crash ends the command)");
    addCommon(tables, common, true);
    addDispatch(tables, dispatch);
    tables
        ->add_option("--calibration", calibrations,
                     "calibration.json: its model runs at its defaults and calibrated in every "
                     "case, and the table 'calibration' shows both (repeatable)")
        ->allow_extra_args(false);
  }
};

int cmdTables(const TablesArgs& ta) {
  const CommonArgs& a = ta.common;
  PluginLoader loader(searchPath(a.pluginDirs));
  TablesOptions o;
  o.quick = a.quick;
  o.outDir = makeOutDir(a.out);
  o.cases = caseOptions(a);
  o.referenceElements = ta.referenceElements;
  o.referenceCheck = !ta.noReferenceCheck;
  o.surfaceBaselines = ta.surfaceBaselines;
  o.truthCubeData = ta.truthCubeData;
  o.truthCubeContact = ta.truthCubeContact;
  o.calibrations = readCalibrations(ta.calibrations);
  if (ta.resume && ta.inProcess)
    throw InputError("--resume", "", "needs the cases in child processes (drop --in-process)");
  const bool dispatched = ta.dispatch.jobs > 1 || ta.dispatch.mpi || !ta.dispatch.slurm.empty();
  if (dispatched && ta.inProcess)
    throw InputError("--in-process", "", "--jobs, --mpi and --slurm need child processes");
  const std::unique_ptr<Dispatcher> dispatcher = makeDispatcher(ta.dispatch);
  o.cases.dispatcher = dispatcher.get();
  if (!ta.inProcess) {
    ChildCaseOptions child;
    child.executable = selfExecutable();
    child.pluginArgs = pluginDirArgs(loader.searchPath());
    if (ta.timeout > 0) child.timeoutS = ta.timeout;
    child.resume = ta.resume;
    child.retryFailed = ta.retryFailed;
    o.cases.child = child;
  }
  std::vector<Table> tables;
  {
    Progress progress(0, "tables");
    tables = buildTables(ta.names, loader, o, &progress);
  }
  if (a.explain) {
    for (const auto& f : loader.loadedFiles()) std::cout << "explain: loaded plugin " << f << "\n";
  }
  for (const Table& t : tables) {
    std::ifstream md(o.outDir / (t.name + ".md"));
    std::cout << "\n" << md.rdbuf();
  }
  std::cout << "\ntables: " << o.outDir.string() << " (<table>.md/.csv/.json; scenes/ to rerun "
            << "any row with deformbench run)\n";
  // The reference checks' warnings again at the end, where they are seen.
  for (const std::string& w : tableWarnings(tables)) std::cout << w << "\n";
  return 0;
}

}  // namespace

Verb addTables(CLI::App& app) {
  return makeVerb<TablesArgs>(
      app, "tables",
      "regenerate the papers' tables (metaballs-construction, method-comparison, bem-timing, "
      "bem-accuracy, hybrid-accuracy, hybrid-timing, verification, truth-cube, or all)",
      cmdTables);
}

}  // namespace deform::harness::cli
