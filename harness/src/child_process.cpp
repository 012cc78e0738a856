// Children with a time limit for the long commands (see child_process.h).
#include <deform_harness/child_process.h>
#include <deform_harness/format.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <iterator>
#include <thread>

namespace deform::harness {

namespace fs = std::filesystem;

namespace {

pid_t spawn(const std::vector<std::string>& argv, const fs::path& log) {
  // Everything the child needs is built before fork(): another thread of this process may hold
  // the allocator's lock at that moment, so the child only makes async-signal-safe calls.
  std::vector<char*> args;
  for (const auto& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  std::vector<std::string> envText;
  for (char** e = environ; e && *e; ++e)
    if (std::strncmp(*e, "DEFORM_PROGRESS=", 16) != 0) envText.emplace_back(*e);
  envText.emplace_back("DEFORM_PROGRESS=plain");
  std::vector<char*> env;
  for (auto& e : envText) env.push_back(e.data());
  env.push_back(nullptr);
  const std::string logPath = log.string();
  const std::string execFailed = "cannot exec " + argv[0] + "\n";
  const pid_t parent = getpid();
  std::fflush(nullptr);
  const pid_t pid = fork();
  if (pid != 0) return pid;
  // Child: own process group (so a timeout kills whatever it forked too), output to the log,
  // killed when the process (or thread) that started it dies (a lost MPI worker, dispatch.h).
  setpgid(0, 0);
  prctl(PR_SET_PDEATHSIG, SIGKILL);
  if (getppid() != parent) _exit(127);
  const int fd = open(logPath.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd >= 0) {
    dup2(fd, 1);
    dup2(fd, 2);
    close(fd);
  }
  execve(args[0], args.data(), env.data());
  (void)!write(2, execFailed.data(), execFailed.size());
  _exit(127);
}

using Clock = std::chrono::steady_clock;

struct Running {
  size_t index;
  pid_t pid;
  Clock::time_point start;
};

}  // namespace

bool ChildOutcome::succeeded() const {
  return spawnError.empty() && !timedOut && WIFEXITED(waitStatus) && WEXITSTATUS(waitStatus) == 0;
}

void runChildren(const std::vector<ChildJob>& jobs, int parallel, double timeoutS,
                 const std::function<void(size_t)>& onStart,
                 const std::function<void(size_t, const ChildOutcome&)>& onDone) {
  std::vector<Running> running;
  size_t next = 0;
  parallel = std::max(1, parallel);
  while (next < jobs.size() || !running.empty()) {
    while (next < jobs.size() && int(running.size()) < parallel) {
      const size_t i = next++;
      if (onStart) onStart(i);
      const Clock::time_point start = Clock::now();
      const pid_t pid = spawn(jobs[i].argv, jobs[i].log);
      if (pid < 0) {
        ChildOutcome o;
        o.spawnError = std::string("cannot fork: ") + std::strerror(errno);
        if (onDone) onDone(i, o);
        continue;
      }
      running.push_back({i, pid, start});
    }
    bool any = false;
    for (auto it = running.begin(); it != running.end();) {
      ChildOutcome o;
      o.wallS = std::chrono::duration<double>(Clock::now() - it->start).count();
      const pid_t w = waitpid(it->pid, &o.waitStatus, WNOHANG);
      if (w == 0 && o.wallS > timeoutS) {
        kill(-it->pid, SIGKILL);
        kill(it->pid, SIGKILL);
        waitpid(it->pid, &o.waitStatus, 0);
        o.timedOut = true;
      } else if (w == 0) {
        ++it;
        continue;
      }
      const size_t index = it->index;
      it = running.erase(it);
      any = true;
      if (onDone) onDone(index, o);
    }
    if (!any && !running.empty()) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
}

ChildOutcome runChild(const ChildJob& job, double timeoutS) {
  ChildOutcome out;
  runChildren({job}, 1, timeoutS, nullptr, [&](size_t, const ChildOutcome& o) { out = o; });
  return out;
}

std::string signalText(int sig) {
  const char* name = sigabbrev_np(sig);
  return "killed by signal " + std::to_string(sig) +
         (name ? std::string(" (SIG") + name + ")" : "");
}

std::string childFailure(const ChildOutcome& o, double timeoutS, const std::string& logTail) {
  if (!o.spawnError.empty()) return o.spawnError;
  if (o.timedOut) return "timeout: no result after " + formatG(timeoutS) + " s (killed)";
  if (WIFSIGNALED(o.waitStatus)) return signalText(WTERMSIG(o.waitStatus));
  const int code = WIFEXITED(o.waitStatus) ? WEXITSTATUS(o.waitStatus) : -1;
  if (code == 0) return "";
  return "exit code " + std::to_string(code) + (logTail.empty() ? "" : ": " + logTail);
}

std::string lastLogLine(const fs::path& file, size_t maxChars) {
  std::ifstream in(file);
  std::string s((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  while (!s.empty() && (s.back() == '\n' || s.back() == ' ')) s.pop_back();
  const auto nl = s.rfind('\n');
  std::string last = nl == std::string::npos ? s : s.substr(nl + 1);
  if (last.size() > maxChars) last = last.substr(last.size() - maxChars);
  return last;
}

std::string selfExecutable() {
  return fs::read_symlink("/proc/self/exe").string();
}

std::vector<std::string> pluginDirArgs(const std::vector<std::string>& searchPath) {
  std::vector<std::string> args;
  for (const auto& d : searchPath) {
    args.push_back("--plugin-dir");
    args.push_back(d);
  }
  return args;
}

}  // namespace deform::harness
