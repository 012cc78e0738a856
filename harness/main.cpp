// deformbench: the command-line program. Verbs (DESIGN.md "Command line"): plugins, run, phantom,
// tables, sweep, stability, report, bench, converge, conformance. Bad input ends with one line
// "deformbench: FILE: PLACE: PROBLEM" on stderr and exit code 2; an unexpected internal error
// exits 3. `run --strict` exits 1 when a model failed (results.json is still written whole).
// Each verb lives in src/cli/<verb>.cpp with its options; this file parses and runs the one given.
#include "src/cli/cli.h"

#include <deform/sdk/cache.h>
#include <deform_harness/dispatch.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdlib>
#include <iostream>
#include <vector>

namespace {

using namespace deform;
using namespace deform::harness;
using namespace deform::harness::cli;

int realMain(int argc, char** argv) {
  CLI::App app{"deformbench: compares soft-tissue deformation models on equal terms"};
  app.require_subcommand(1);
  // Global options (--plugin-dir) are accepted before or after the verb.
  app.fallthrough();

  std::vector<std::string> pluginDirs;
  app.add_option(
      "--plugin-dir", pluginDirs,
      "extra folder to search for plugins (before $DEFORM_PLUGIN_PATH and the defaults)");

  // In the order `deformbench --help` lists them.
  const std::vector<Verb> verbs = {
      addPlugins(app),   addRun(app),       addPhantom(app),    addTables(app), addSweep(app),
      addCalibrate(app), addStability(app), addReport(app),     addBench(app),  addConverge(app),
      addVerify(app),    addWork(app),      addConformance(app)};

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);
    std::cerr << "deformbench: " << oneLine(e.what()) << " (see deformbench --help)\n";
    return kExitBadInput;
  }
  for (const Verb& verb : verbs)
    if (*verb.cmd) return verb.run(pluginDirs);
  return kExitBadInput;
}

}  // namespace

namespace {
int guardedMain(int argc, char** argv);
}  // namespace

int main(int argc, char** argv) {
  // Before anything starts threads: timings are single-threaded by contract.
  forceSingleThreadedNumerics();
  g_commandLine.assign(argv, argv + argc);
  // --mpi: every rank starts MPI; ranks > 0 serve cases until rank 0 is done (dispatch.h).
  const bool mpi =
      std::find(g_commandLine.begin(), g_commandLine.end(), "--mpi") != g_commandLine.end();
  if (mpi && !mpiAvailable()) {
    std::cerr << "deformbench: --mpi: this build has no MPI (install libopenmpi-dev and "
                 "reconfigure)\n";
    return kExitBadInput;
  }
  if (mpi) {
    const char* lost = std::getenv("DEFORM_MPI_LOST_AFTER");
    int code = 0;
    if (!mpiStart(argc, argv, lost ? std::atof(lost) : 30.0, code)) return code;
  }
  const int code = guardedMain(argc, argv);
  if (mpi) {
    std::cout.flush();
    mpiStop(code);
  }
  return code;
}

namespace {

int guardedMain(int argc, char** argv) {
  try {
    return realMain(argc, argv);
  } catch (const PlanWritten& e) {
    std::cout << e.what() << "\n";
    return 0;
  } catch (const InputError& e) {
    std::cout.flush();
    std::cerr << "deformbench: " << oneLine(e.what()) << "\n";
    return kExitBadInput;
  } catch (const PluginError& e) {
    std::cout.flush();
    std::cerr << "deformbench: " << oneLine(e.what()) << "\n";
    return kExitBadInput;
  } catch (const std::exception& e) {
    std::cout.flush();
    std::cerr << "deformbench: internal error: " << oneLine(e.what()) << "\n";
    return kExitInternal;
  } catch (...) {
    std::cerr << "deformbench: internal error: unknown exception\n";
    return kExitInternal;
  }
}

}  // namespace
