// Running CalculiX's `ccx` as a child process: find the program, run one job in a private
// temporary folder with a wall-clock deadline, and collect its output and resource usage.
//
// ccx is the solver of CalculiX (G. Dhondt, "The Finite Element Method for Three-Dimensional
// Thermomechanical Applications", Wiley 2004, doi:10.1002/0470021217; www.calculix.de). It reads
// JOB.inp and writes JOB.dat (*NODE PRINT tables) and JOB.frd; it reports errors on stdout as
// lines starting with "*ERROR" and exits non-zero (201) when a step does not finish.
#pragma once

#include <optional>
#include <string>

namespace deform::calculix {

/// The ccx program to run: $DEFORM_CCX when that variable is set (a path; nothing when it names
/// no executable file), otherwise the first executable `ccx` on $PATH. Empty when none.
std::string findCcx();

struct CcxRun {
  bool ok = false;      ///< exit status 0, not killed, and JOB.dat exists
  std::string message;  ///< why not: ccx's *ERROR lines (or its last output), a signal, a timeout
  std::string dat;      ///< the contents of JOB.dat
  double wallSeconds = 0;
  double cpuSeconds = 0;  ///< user + system time of the child (its rusage)
};

/// Writes `input` to JOB.inp in a fresh folder under the system's temporary folder, runs
/// `ccx -i JOB` there (stdin /dev/null, stdout and stderr to a file, OMP_NUM_THREADS and
/// CCX_NPROC_* set to `threads`), kills it (SIGKILL) after `timeoutSeconds`, reads JOB.dat and
/// removes the folder. With `maxMemoryBytes` > 0 the child's address space is limited to it
/// (RLIMIT_AS): a ccx whose factorisation fills in without bound fails alone, and a failed run's
/// message names the limit. Never throws for a ccx failure: `ok` is false and `message` says why.
CcxRun runCcx(const std::string& ccx, const std::string& input, double timeoutSeconds,
              int threads = 1, double maxMemoryBytes = 0);

/// Half of this machine's physical memory, bytes (calculix's default `max_memory`).
double halfPhysicalMemory();

}  // namespace deform::calculix
