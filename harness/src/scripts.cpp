// Finding and running the shipped Python scripts (see scripts.h).
#include <deform_harness/scripts.h>

#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstdio>
#include <cstdlib>
#include <filesystem>

#ifndef DEFORM_SOURCE_DIR
#define DEFORM_SOURCE_DIR ""
#endif

namespace deform::harness {

namespace fs = std::filesystem;

namespace {

/// $env, else the source tree's `source` folder, else <prefix>/share/deformbench/`installed`.
std::string dataDir(const char* env, const fs::path& source, const char* installed) {
  if (const char* e = std::getenv(env); e && *e) return e;
  const fs::path inSource = fs::path(DEFORM_SOURCE_DIR) / source;
  std::error_code ec;
  if (!std::string(DEFORM_SOURCE_DIR).empty() && fs::is_directory(inSource, ec))
    return inSource.string();
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    const fs::path share = exe.parent_path().parent_path() / "share" / "deformbench" / installed;
    if (fs::is_directory(share, ec)) return share.string();
  }
  return "";
}

}  // namespace

std::string scriptsDir() {
  return dataDir("DEFORM_SCRIPTS_DIR", fs::path("harness") / "scripts", "scripts");
}

std::string shippedCalibrationsDir() {
  return dataDir("DEFORM_CALIBRATIONS_DIR", "calibrations", "calibrations");
}

std::string pythonInterpreter() {
  if (const char* env = std::getenv("DEFORM_PYTHON"); env && *env) return env;
  if (access("/usr/bin/python3", X_OK) == 0) return "/usr/bin/python3";
  return "python3";
}

namespace {

std::string quote(const std::string& s) {
  std::string q = "'";
  for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
  return q + "'";
}

}  // namespace

ScriptResult runScript(const std::string& script, const std::vector<std::string>& args) {
  ScriptResult r;
  const std::string dir = scriptsDir();
  if (dir.empty()) {
    r.output = "the deformbench scripts folder was not found (set DEFORM_SCRIPTS_DIR)";
    return r;
  }
  // No __pycache__ beside the shipped scripts (they may live in a read-only install).
  std::string cmd = "PYTHONDONTWRITEBYTECODE=1 " + quote(pythonInterpreter()) + " " +
                    quote((fs::path(dir) / script).string());
  for (const auto& a : args) {
    cmd += ' ';  // not " " + quote(a): GCC 12 warns falsely (-Wrestrict) on that operator+
    cmd += quote(a);
  }
  cmd += " 2>&1";
  std::fflush(nullptr);
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) {
    r.output = "cannot start " + pythonInterpreter();
    return r;
  }
  std::array<char, 512> buf{};
  while (fgets(buf.data(), int(buf.size()), p)) r.output += buf.data();
  const int status = pclose(p);
  r.exitCode = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  if (r.exitCode == 127) r.output = "cannot run " + pythonInterpreter() + ": " + r.output;
  return r;
}

}  // namespace deform::harness
