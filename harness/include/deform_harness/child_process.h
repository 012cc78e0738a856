// deformbench harness: running `deformbench` children with a wall-clock limit, for the long
// commands whose cases must not take the whole command down (stability: one child per
// (model, case); tables: one child per case). Each child gets its own process group (a timeout
// kills whatever it forked too, e.g. the Gmsh child of reference_fem), its stdout and stderr go
// to a log file, and DEFORM_PROGRESS=plain is set for it. A crash (signal), a hang (killed at the
// limit) or a non-zero exit becomes a readable one-line message; the caller records it and goes on.
#pragma once

#include <sys/types.h>

#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace deform::harness {

/// One child to run: argv[0] is the program (an absolute path), log receives stdout + stderr.
struct ChildJob {
  std::vector<std::string> argv;
  std::filesystem::path log;
};

/// How a child ended.
struct ChildOutcome {
  int waitStatus = 0;      ///< as from waitpid (meaningless when timedOut or !spawnError.empty())
  bool timedOut = false;   ///< killed (SIGKILL to its process group) at the time limit
  std::string spawnError;  ///< fork() failed: why; the child never ran
  double wallS = 0;        ///< wall time from start to end (or kill), s

  /// Exited with code 0 (not killed, not timed out).
  bool succeeded() const;
};

/// Runs the jobs, at most `parallel` at once, each killed when it runs longer than timeoutS
/// (> 0). onStart(i) is called just before job i starts, onDone(i, outcome) when it ended (both
/// in the calling process, in completion order). Blocks until every job has ended.
void runChildren(const std::vector<ChildJob>& jobs, int parallel, double timeoutS,
                 const std::function<void(size_t)>& onStart,
                 const std::function<void(size_t, const ChildOutcome&)>& onDone);

/// One job alone (runChildren with one job).
ChildOutcome runChild(const ChildJob& job, double timeoutS);

/// Why a child did not succeed, in one line ("" when it succeeded):
///   "timeout: no result after 120 s (killed)", "killed by signal 11 (SIGSEGV)",
///   "exit code 2: <last line of its log>", "cannot fork: ...".
std::string childFailure(const ChildOutcome& outcome, double timeoutS, const std::string& logTail);

/// "killed by signal 11 (SIGSEGV)".
std::string signalText(int sig);

/// The last non-empty line of a text file, at most maxChars (its end); "" when unreadable.
std::string lastLogLine(const std::filesystem::path& file, size_t maxChars);

/// The running program (/proc/self/exe), for re-executing `deformbench` as a child.
std::string selfExecutable();

/// "--plugin-dir D" for each folder of a loader's search path, so a child resolves the same
/// plugin files in the same order as the parent.
std::vector<std::string> pluginDirArgs(const std::vector<std::string>& searchPath);

}  // namespace deform::harness
