// deformbench harness: handing the long commands' cases out to local processes, MPI ranks or a
// Slurm job array.
//
// A task is a JSON document that says everything a worker needs to run one unit of work: a
// "case" (the `deformbench run` child of a generated scene, with the retry without reference of
// cases.h; the result is the case.json document) or a "child" (one ChildJob with a time limit;
// the result is the outcome: wait status, timed out, spawn error, wall time). The worker writes
// its result next to the run as well (case.json, outcome.json), so that a later command with
// --resume reads it back whichever launcher ran it: this thread, a local process slot, an MPI
// rank, or a Slurm array task on another host. Paths in tasks are absolute: workers on other
// hosts need the output folder (and the plugins) on a shared filesystem at the same path.
//
// The dispatcher runs tasks and reports each one's result in the calling thread; it never
// changes what a task computes, so the outputs equal the serial run's (timings apart). Callers
// (tables, stability, sweep, converge, calibrate) build the tasks, consume the results in their
// own order, and write their outputs as before.
#pragma once

#include <filesystem>
#include <functional>
#include <memory>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <vector>

namespace deform::harness {

/// Runs one task in this process (it forks the task's children) and returns its result. Throws
/// std::invalid_argument for a task it does not understand.
nlohmann::ordered_json executeTask(const nlohmann::ordered_json& task);

/// The result a task gets when no worker could run it (two workers lost while running it): a
/// failed case (every run failed with `message`) or a child outcome with spawn_error = message.
nlohmann::ordered_json lostTaskResult(const nlohmann::ordered_json& task,
                                      const std::string& message);

/// The stored result of a task that says "resume": true, when an earlier run (any launcher) left
/// it; null otherwise.
nlohmann::ordered_json resumedTaskResult(const nlohmann::ordered_json& task);

/// The indices of the tasks still to run, ascending: the others left a result in an earlier
/// command (resumedTaskResult()) and are handed to onDone (when given) at once, in order.
std::vector<size_t> tasksToRun(
    const std::vector<nlohmann::ordered_json>& tasks,
    const std::function<void(size_t, const nlohmann::ordered_json&)>& onDone);

/// Stages: a task may say "stage": S (default 0). Every dispatcher runs the tasks of a stage only
/// after every task of the earlier stages ended (e.g. the sweep's first case solves the reference
/// that the later ones read from the cache); the Slurm one writes one job array per stage, each
/// submitted after the previous one. byStage() groups the indices `todo` by stage, ascending.
std::vector<std::vector<size_t>> byStage(const std::vector<nlohmann::ordered_json>& tasks,
                                         const std::vector<size_t>& todo);

/// Thrown by the Slurm dispatcher once it has written the job files: the command stops there
/// (its outputs are assembled by the collect step). what() is the summary to print.
struct PlanWritten : std::runtime_error {
  using std::runtime_error::runtime_error;
};

class Dispatcher {
 public:
  virtual ~Dispatcher() = default;
  /// Runs every task. onStart(i) just before task i is handed out (not for resumed tasks),
  /// onDone(i, result) when its result is known; both in the calling thread, in any order.
  virtual void run(const std::vector<nlohmann::ordered_json>& tasks,
                   const std::function<void(size_t)>& onStart,
                   const std::function<void(size_t, const nlohmann::ordered_json&)>& onDone) = 0;
  /// How many tasks run at once (1 for the serial dispatcher).
  virtual int width() const = 0;
};

/// Up to `jobs` tasks at once in this process's threads (each task is child processes: the
/// numerics inside a case stay single-threaded). jobs = 1 is the serial run.
std::unique_ptr<Dispatcher> localDispatcher(int jobs);

/// Writes the tasks and a Slurm job array into dir, then throws PlanWritten:
///   dir/tasks/<i>.json      one task per array index;
///   dir/job.sbatch          the array: `deformbench work dir/tasks/$SLURM_ARRAY_TASK_ID.json`
///                           (stage 0; job_<s>.sbatch for a later stage s);
///   dir/collect.sbatch      `collectCommand` (the same command with --resume, no --slurm) run
///                           in `workDir`;
///   dir/submit.sh           sbatch job.sbatch (then each job_<s>.sbatch after the previous
///                           one), then collect.sbatch after the last (afterany).
/// `executable` is the deformbench to run in the array tasks.
std::unique_ptr<Dispatcher> slurmDispatcher(const std::filesystem::path& dir,
                                            const std::string& executable,
                                            const std::vector<std::string>& collectCommand,
                                            const std::filesystem::path& workDir);

/// True when this build has MPI (CMake found it).
bool mpiAvailable();

/// MPI session for `--mpi`, set up before the command line is parsed: every rank calls
/// mpiStart(); ranks > 0 then serve tasks until rank 0 says stop (mpiStart returns false for
/// them: the caller exits with the returned code), rank 0 runs the command and calls
/// mpiStop(exitCode) at the end (also on errors). When a worker was lost, MPI_Finalize would
/// wait for it forever: then mpiStop ends every live rank at once (rank 0 with exitCode)
/// without it. lostAfterS: a busy worker silent for this long (it sends a
/// heartbeat every second) is taken as dead; its task goes to another worker once.
bool mpiStart(int& argc, char**& argv, double lostAfterS, int& exitCode);
void mpiStop(int exitCode);

/// Rank 0's dispatcher (mpiStart must have returned true): hands out one task at a time to each
/// idle worker, dynamically. With no worker (mpirun -n 1, or every worker lost) it runs the
/// remaining tasks itself, one at a time.
std::unique_ptr<Dispatcher> mpiDispatcher(const std::function<void(const std::string&)>& note);

}  // namespace deform::harness
