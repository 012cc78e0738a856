// Tasks, the local and Slurm dispatchers (see dispatch.h); the MPI one is in mpi/.
#include <deform/internal/atomic_file.h>
#include <deform/sdk/cache.h>
#include <deform/sdk/error.h>
#include <deform_harness/cases.h>
#include <deform_harness/child_process.h>
#include <deform_harness/dispatch.h>
#include <sys/stat.h>

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <fstream>
#include <map>
#include <mutex>
#include <sstream>
#include <thread>

namespace deform::harness {

namespace fs = std::filesystem;
using ojson = nlohmann::ordered_json;

namespace {

std::string readText(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// Single-quoted for sh.
std::string shellQuote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

ojson runChildTask(const ojson& task) {
  ChildJob job;
  job.argv = task.at("argv").get<std::vector<std::string>>();
  job.log = task.at("log").get<std::string>();
  if (task.contains("fresh_dir")) {
    const fs::path dir = task["fresh_dir"].get<std::string>();
    fs::remove_all(dir);
    fs::create_directories(dir);
  }
  const ChildOutcome o = runChild(job, task.at("timeout_s").get<double>());
  ojson out = {{"argv", job.argv},
               {"wait_status", o.waitStatus},
               {"timed_out", o.timedOut},
               {"spawn_error", o.spawnError},
               {"wall_s", o.wallS}};
  if (task.contains("outcome"))
    writeFileAtomic(task["outcome"].get<std::string>(), out.dump(2) + "\n");
  return out;
}

}  // namespace

ojson executeTask(const ojson& task) {
  const std::string kind = task.value("kind", "");
  if (kind == "case") return runCaseTask(task);
  if (kind == "child") return runChildTask(task);
  throw std::invalid_argument("unknown task kind '" + kind + "'");
}

ojson lostTaskResult(const ojson& task, const std::string& message) {
  if (task.value("kind", "") == "case") return lostCaseDoc(task, message);
  return {{"argv", task.value("argv", ojson::array())},
          {"wait_status", 0},
          {"timed_out", false},
          {"spawn_error", message},
          {"wall_s", 0.0}};
}

ojson resumedTaskResult(const ojson& task) {
  if (task.value("kind", "") != "child" || !task.value("resume", false) ||
      !task.contains("outcome"))
    return nullptr;
  try {
    const ojson o = ojson::parse(readText(task["outcome"].get<std::string>()));
    // "retry_failed": a child that was killed, timed out or exited non-zero runs again.
    const bool failed = o.value("timed_out", false) || !o.value("spawn_error", "").empty() ||
                        o.value("wait_status", 0) != 0;
    if (failed && task.value("retry_failed", false)) return nullptr;
    if (o.at("argv") == task.at("argv")) return o;
  } catch (const std::exception&) {
    // absent or unreadable: run it
  }
  return nullptr;
}

std::vector<std::vector<size_t>> byStage(const std::vector<ojson>& tasks,
                                         const std::vector<size_t>& todo) {
  std::map<int, std::vector<size_t>> stages;
  for (size_t i : todo) stages[tasks[i].value("stage", 0)].push_back(i);
  std::vector<std::vector<size_t>> out;
  for (auto& [stage, ids] : stages) out.push_back(std::move(ids));
  return out;
}

std::vector<size_t> tasksToRun(const std::vector<ojson>& tasks,
                               const std::function<void(size_t, const ojson&)>& onDone) {
  std::vector<size_t> todo;
  for (size_t i = 0; i < tasks.size(); ++i) {
    const ojson r = resumedTaskResult(tasks[i]);
    if (r.is_null()) {
      todo.push_back(i);
    } else if (onDone) {
      onDone(i, r);
    }
  }
  return todo;
}

namespace {

ojson executeCaught(const ojson& task) {
  try {
    return executeTask(task);
  } catch (const std::exception& e) {
    return lostTaskResult(task, std::string("worker error: ") + e.what());
  }
}

class LocalDispatcher : public Dispatcher {
 public:
  explicit LocalDispatcher(int jobs) : m_jobs(std::max(1, jobs)) {}
  int width() const override { return m_jobs; }

  void run(const std::vector<ojson>& tasks, const std::function<void(size_t)>& onStart,
           const std::function<void(size_t, const ojson&)>& onDone) override {
    const std::vector<size_t> todo = tasksToRun(tasks, onDone);
    for (const std::vector<size_t>& stage : byStage(tasks, todo))
      runStage(tasks, stage, onStart, onDone);
  }

 private:
  void runStage(const std::vector<ojson>& tasks, const std::vector<size_t>& todo,
                const std::function<void(size_t)>& onStart,
                const std::function<void(size_t, const ojson&)>& onDone) {
    if (m_jobs == 1) {
      for (size_t i : todo) {
        if (onStart) onStart(i);
        const ojson r = executeCaught(tasks[i]);
        if (onDone) onDone(i, r);
      }
      return;
    }
    std::mutex m;
    std::condition_variable cv;
    std::deque<std::pair<size_t, ojson>> finished;
    std::map<size_t, std::thread> threads;
    size_t next = 0;
    while (next < todo.size() || !threads.empty()) {
      while (next < todo.size() && int(threads.size()) < m_jobs) {
        const size_t i = todo[next++];
        if (onStart) onStart(i);
        threads.emplace(i, std::thread([&, i] {
                          ojson r = executeCaught(tasks[i]);
                          std::lock_guard<std::mutex> lock(m);
                          finished.emplace_back(i, std::move(r));
                          cv.notify_one();
                        }));
      }
      std::deque<std::pair<size_t, ojson>> done;
      {
        std::unique_lock<std::mutex> lock(m);
        cv.wait(lock, [&] { return !finished.empty(); });
        done.swap(finished);
      }
      for (auto& [i, r] : done) {
        threads.at(i).join();
        threads.erase(i);
        if (onDone) onDone(i, r);
      }
    }
  }

  int m_jobs;
};

class SlurmDispatcher : public Dispatcher {
 public:
  SlurmDispatcher(fs::path dir, std::string exe, std::vector<std::string> collect, fs::path work)
      : m_dir(fs::absolute(std::move(dir))),
        m_exe(std::move(exe)),
        m_collect(std::move(collect)),
        m_work(fs::absolute(std::move(work))) {}
  int width() const override { return 1; }

  void run(const std::vector<ojson>& tasks, const std::function<void(size_t)>&,
           const std::function<void(size_t, const ojson&)>& onDone) override {
    const std::vector<size_t> todo = tasksToRun(tasks, onDone);
    std::error_code ec;
    fs::create_directories(m_dir / "tasks", ec);
    fs::create_directories(m_dir / "logs", ec);
    if (!fs::is_directory(m_dir / "tasks"))
      throw InputError(m_dir.string(), "", "cannot create the Slurm folder");
    for (const auto& e : fs::directory_iterator(m_dir / "tasks")) fs::remove(e.path());
    for (const auto& e : fs::directory_iterator(m_dir))
      if (e.path().filename().string().rfind("job_", 0) == 0) fs::remove(e.path());
    // One array per stage (dispatch.h): stage s is job.sbatch (s = 0) or job_<s>.sbatch, its
    // tasks numbered on from the previous stage's, and it starts when the previous one ended.
    const std::vector<std::vector<size_t>> stages = byStage(tasks, todo);
    std::vector<std::string> scripts;
    size_t k = 0;
    for (size_t s = 0; s < stages.size(); ++s) {
      const size_t first = k;
      for (size_t i : stages[s])
        writeFileAtomic(m_dir / "tasks" / (std::to_string(k++) + ".json"), tasks[i].dump(2) + "\n");
      const std::string name = s == 0 ? "job.sbatch" : "job_" + std::to_string(s) + ".sbatch";
      std::ostringstream job;
      job << "#!/bin/bash\n"
          << "# deformbench: one array task per case; each runs the case's child process(es).\n"
          << "#SBATCH --job-name=deformbench-cases" << (s == 0 ? "" : "-" + std::to_string(s))
          << "\n"
          << "#SBATCH --ntasks=1\n#SBATCH --cpus-per-task=1\n"
          << "#SBATCH --output=" << (m_dir / "logs" / "task_%a.out").string() << "\n"
          << "#SBATCH --array=" << first << "-" << k - 1 << "\n";
      job << "exec " << shellQuote(m_exe) << " work " << shellQuote((m_dir / "tasks").string())
          << "/\"$SLURM_ARRAY_TASK_ID\".json\n";
      writeScript(m_dir / name, job.str());
      scripts.push_back(name);
    }
    if (scripts.empty()) {
      std::ostringstream job;
      job << "#!/bin/bash\n# deformbench: every case was finished already (--resume).\n";
      writeScript(m_dir / "job.sbatch", job.str());
    }

    std::ostringstream collect;
    collect << "#!/bin/bash\n"
            << "# deformbench: assemble the outputs from the finished cases (--resume).\n"
            << "#SBATCH --job-name=deformbench-collect\n"
            << "#SBATCH --ntasks=1\n#SBATCH --cpus-per-task=1\n"
            << "#SBATCH --output=" << (m_dir / "logs" / "collect.out").string() << "\n"
            << "cd " << shellQuote(m_work.string()) << " || exit 1\nexec";
    for (const std::string& a : m_collect) collect << " " << shellQuote(a);
    collect << "\n";
    writeScript(m_dir / "collect.sbatch", collect.str());

    std::ostringstream submit;
    submit << "#!/bin/bash\n"
           << "# Submits the case array(s), each after the previous one, then the collect step\n"
           << "# once every array task ended.\n"
           << "set -euo pipefail\ncd \"$(dirname \"$0\")\"\n";
    if (scripts.empty()) {
      submit << "sbatch collect.sbatch\n";
    } else {
      for (size_t s = 0; s < scripts.size(); ++s) {
        submit << "jid=$(sbatch --parsable " << (s == 0 ? "" : "--dependency=afterany:\"$jid\" ")
               << "\"$@\" " << scripts[s] << ")\n"
               << "jid=${jid%%;*}\n";
      }
      submit << "sbatch --dependency=afterany:\"$jid\" collect.sbatch\n";
    }
    writeScript(m_dir / "submit.sh", submit.str());
    throw PlanWritten("slurm: " + std::to_string(todo.size()) + " case task(s) and the collect " +
                      "step written to " + m_dir.string() + "; submit with " +
                      (m_dir / "submit.sh").string());
  }

 private:
  static void writeScript(const fs::path& p, const std::string& text) {
    writeFileAtomic(p, text);
    ::chmod(p.c_str(), 0755);
  }
  fs::path m_dir;
  std::string m_exe;
  std::vector<std::string> m_collect;
  fs::path m_work;
};

}  // namespace

std::unique_ptr<Dispatcher> localDispatcher(int jobs) {
  return std::make_unique<LocalDispatcher>(jobs);
}

std::unique_ptr<Dispatcher> slurmDispatcher(const fs::path& dir, const std::string& executable,
                                            const std::vector<std::string>& collectCommand,
                                            const fs::path& workDir) {
  return std::make_unique<SlurmDispatcher>(dir, executable, collectCommand, workDir);
}

#ifndef DEFORM_HAVE_MPI
bool mpiAvailable() {
  return false;
}
bool mpiStart(int&, char**&, double, int& exitCode) {
  exitCode = 0;
  return true;
}
void mpiStop(int) {}
std::unique_ptr<Dispatcher> mpiDispatcher(const std::function<void(const std::string&)>&) {
  return localDispatcher(1);
}
#endif

}  // namespace deform::harness
