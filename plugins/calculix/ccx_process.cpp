#include "ccx_process.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <thread>
#include <vector>

extern char** environ;

namespace deform::calculix {

namespace fs = std::filesystem;

namespace {

bool isExecutableFile(const std::string& path) {
  struct stat st {};
  return !path.empty() && ::stat(path.c_str(), &st) == 0 && S_ISREG(st.st_mode) &&
         ::access(path.c_str(), X_OK) == 0;
}

std::string readFile(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

/// ccx's own account of a failure: its "*ERROR" lines (with the line after each, which often
/// names the cause), or else the last non-empty lines of its output.
std::string ccxErrorText(const std::string& log) {
  std::vector<std::string> lines;
  std::istringstream in(log);
  for (std::string line; std::getline(in, line);) {
    const size_t a = line.find_first_not_of(" \t\r");
    if (a == std::string::npos) continue;
    const size_t b = line.find_last_not_of(" \t\r");
    lines.push_back(line.substr(a, b - a + 1));
  }
  std::string out;
  for (size_t i = 0; i < lines.size() && out.size() < 400; ++i)
    if (lines[i].rfind("*ERROR", 0) == 0) out += (out.empty() ? "" : "; ") + lines[i];
  if (!out.empty()) return out;
  for (size_t i = lines.size() > 3 ? lines.size() - 3 : 0; i < lines.size(); ++i)
    out += (out.empty() ? "" : "; ") + lines[i];
  return out.empty() ? "no output" : out;
}

}  // namespace

std::string findCcx() {
  if (const char* given = std::getenv("DEFORM_CCX"))
    return isExecutableFile(given) ? std::string(given) : std::string();
  const char* path = std::getenv("PATH");
  std::istringstream dirs(path ? path : "/usr/local/bin:/usr/bin:/bin");
  for (std::string dir; std::getline(dirs, dir, ':');) {
    const std::string candidate = (dir.empty() ? std::string(".") : dir) + "/ccx";
    if (isExecutableFile(candidate)) return candidate;
  }
  return "";
}

double halfPhysicalMemory() {
  const long pages = ::sysconf(_SC_PHYS_PAGES), page = ::sysconf(_SC_PAGE_SIZE);
  return pages > 0 && page > 0 ? 0.5 * double(pages) * double(page) : 0.0;
}

CcxRun runCcx(const std::string& ccx, const std::string& input, double timeoutSeconds, int threads,
              double maxMemoryBytes) {
  CcxRun run;
  std::string tmpl = (fs::temp_directory_path() / "deform_ccx.XXXXXX").string();
  if (!::mkdtemp(tmpl.data())) {
    run.message = std::string("cannot create a temporary folder: ") + std::strerror(errno);
    return run;
  }
  const fs::path dir(tmpl);
  struct Cleanup {
    fs::path dir;
    ~Cleanup() {
      std::error_code ec;
      fs::remove_all(dir, ec);
    }
  } cleanup{dir};
  {
    std::ofstream out(dir / "job.inp", std::ios::binary);
    out << input;
    if (!out) {
      run.message = "cannot write " + (dir / "job.inp").string();
      return run;
    }
  }
  // Everything the child needs is prepared before fork(): after it, only async-signal-safe calls.
  std::vector<std::string> env;
  const std::string n = std::to_string(threads);
  for (char** e = environ; *e; ++e) {
    const std::string kv(*e);
    if (kv.rfind("OMP_NUM_THREADS=", 0) == 0 || kv.rfind("CCX_NPROC", 0) == 0) continue;
    env.push_back(kv);
  }
  for (const char* k : {"OMP_NUM_THREADS=", "CCX_NPROC_STIFFNESS=", "CCX_NPROC_EQUATION_SOLVER=",
                        "CCX_NPROC_RESULTS="})
    env.push_back(k + n);
  std::vector<char*> envp;
  for (std::string& kv : env) envp.push_back(kv.data());
  envp.push_back(nullptr);
  std::string prog = ccx, dash = "-i", job = "job";
  char* argv[] = {prog.data(), dash.data(), job.data(), nullptr};
  const std::string dirStr = dir.string(), logStr = (dir / "ccx.log").string();
  struct rlimit memory {};
  memory.rlim_cur = memory.rlim_max = maxMemoryBytes > 0 ? rlim_t(maxMemoryBytes) : RLIM_INFINITY;

  const auto t0 = std::chrono::steady_clock::now();
  const pid_t pid = ::fork();
  if (pid < 0) {
    run.message = std::string("cannot start ccx: fork: ") + std::strerror(errno);
    return run;
  }
  if (pid == 0) {
    ::setpgid(0, 0);
    // ccx dies with the process that started it (a harness killed at its timeout).
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (maxMemoryBytes > 0 && ::setrlimit(RLIMIT_AS, &memory) != 0) ::_exit(126);
    if (::chdir(dirStr.c_str()) != 0) ::_exit(126);
    const int in = ::open("/dev/null", O_RDONLY);
    const int log = ::open(logStr.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0600);
    if (in < 0 || log < 0) ::_exit(126);
    ::dup2(in, 0);
    ::dup2(log, 1);
    ::dup2(log, 2);
    ::execve(argv[0], argv, envp.data());
    ::_exit(127);
  }
  int status = 0;
  struct rusage usage {};
  bool timedOut = false;
  for (int sleepUs = 200;;) {
    const pid_t r = ::wait4(pid, &status, WNOHANG, &usage);
    if (r == pid) break;
    if (r < 0 && errno != EINTR) {
      run.message = std::string("waiting for ccx: ") + std::strerror(errno);
      return run;
    }
    const double elapsed =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (!timedOut && elapsed > timeoutSeconds) {
      timedOut = true;
      ::kill(-pid, SIGKILL);
      ::kill(pid, SIGKILL);
    }
    std::this_thread::sleep_for(std::chrono::microseconds(sleepUs));
    sleepUs = std::min(sleepUs * 2, 20000);
  }
  run.wallSeconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  run.cpuSeconds = double(usage.ru_utime.tv_sec) + 1e-6 * double(usage.ru_utime.tv_usec) +
                   double(usage.ru_stime.tv_sec) + 1e-6 * double(usage.ru_stime.tv_usec);
  const std::string log = readFile(dir / "ccx.log");
  std::ostringstream why;
  if (timedOut) {
    why << "ccx did not finish within " << timeoutSeconds << " s (killed)";
  } else if (WIFSIGNALED(status)) {
    why << "ccx was killed by signal " << WTERMSIG(status) << ": " << ccxErrorText(log);
  } else if (WIFEXITED(status) && WEXITSTATUS(status) == 127) {
    why << "cannot run " << ccx;
  } else if (WIFEXITED(status) && WEXITSTATUS(status) != 0) {
    why << "ccx exited with status " << WEXITSTATUS(status) << ": " << ccxErrorText(log);
  } else if (!fs::exists(dir / "job.dat")) {
    why << "ccx wrote no job.dat: " << ccxErrorText(log);
  }
  // The limit is named unless ccx said why itself (an *ERROR line not about memory, such as
  // "increment size smaller than minimum"): an allocation that failed under it rarely says so.
  const bool ccxSaidWhy = log.find("*ERROR") != std::string::npos &&
                          log.find("alloc") == std::string::npos &&
                          log.find("memory") == std::string::npos;
  if (!timedOut && !why.str().empty() && maxMemoryBytes > 0 && !ccxSaidWhy) {
    char limit[64];
    std::snprintf(limit, sizeof limit, "%.3g GB", maxMemoryBytes / 1e9);
    why << " (its memory was limited to " << limit << ", calculix's max_memory)";
  }
  run.message = why.str();
  if (!run.message.empty()) return run;
  run.dat = readFile(dir / "job.dat");
  run.ok = true;
  return run;
}

}  // namespace deform::calculix
