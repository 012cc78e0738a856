// deformbench command line: the helpers the verbs share (cli.h).
#include "cli.h"

#include <deform_harness/calibration.h>
#include <deform_harness/child_process.h>
#include <deform_harness/scripts.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <iomanip>
#include <iostream>
#include <sstream>

namespace deform::harness::cli {

std::vector<std::string> g_commandLine;

std::string oneLine(std::string s) {
  std::replace(s.begin(), s.end(), '\n', ' ');
  std::replace(s.begin(), s.end(), '\r', ' ');
  return s;
}

std::vector<std::string> searchPath(const std::vector<std::string>& extraDirs) {
  std::vector<std::string> path = extraDirs;
  for (const auto& d : PluginLoader::defaultSearchPath()) path.push_back(d);
  return path;
}

/// A check for a positive option value that says so in words (CLI11's PositiveNumber prints its
/// range with the largest double written out in 309 digits).
CLI::Validator positiveValue(bool whole) {
  return CLI::Validator(
      [whole](std::string& text) -> std::string {
        double v = 0;
        size_t used = 0;
        try {
          v = std::stod(text, &used);
        } catch (const std::exception&) {
          used = 0;
        }
        if (used != text.size() || !std::isfinite(v)) return "'" + text + "' is not a number";
        if (whole && (v < 1 || v != std::floor(v)))
          return "must be a whole number of at least 1, got " + text;
        if (!whole && !(v > 0)) return "must be above 0, got " + text;
        return "";
      },
      whole ? "INT >= 1" : "> 0");
}

/// Plugin names are file names (deform_NAME.so) without folders: a name that is a path would
/// put the stability outputs outside --out.
void requirePluginName(const std::string& option, const std::string& name) {
  const bool ok = !name.empty() && name.front() != '.' &&
                  std::all_of(name.begin(), name.end(), [](unsigned char c) {
                    return std::isalnum(c) || c == '_' || c == '-' || c == '.' || c == '+';
                  });
  if (!ok)
    throw InputError(option, name,
                     "not a plugin name (letters, digits, '_', '-', '.', no folders; "
                     "`deformbench plugins` lists them)");
}

std::string fmt(double v, int precision) {
  if (!std::isfinite(v)) return "-";
  std::ostringstream s;
  s << std::setprecision(precision) << v;
  return s.str();
}

namespace {

/// The files, with "shipped" replaced by every file of the shipped calibrations folder (those
/// marked true).
std::vector<std::pair<std::string, bool>> expandShipped(const std::vector<std::string>& files) {
  std::vector<std::pair<std::string, bool>> out;
  for (const std::string& f : files) {
    if (f != "shipped") {
      out.emplace_back(f, false);
      continue;
    }
    const std::string dir = shippedCalibrationsDir();
    if (dir.empty())
      throw InputError("--calibration", "shipped",
                       "no shipped calibrations folder (calibrations/ in the source tree, "
                       "share/deformbench/calibrations installed, or $DEFORM_CALIBRATIONS_DIR)");
    std::vector<std::string> found;
    for (const auto& e : fs::recursive_directory_iterator(dir))
      if (e.is_regular_file() && e.path().extension() == ".json") found.push_back(e.path());
    std::sort(found.begin(), found.end());  // a stable order, whatever the file system's
    for (const std::string& s : found) out.emplace_back(s, true);
  }
  return out;
}

}  // namespace

std::vector<CalibrationParams> readCalibrations(const std::vector<std::string>& files) {
  std::vector<CalibrationParams> out;
  for (const auto& [f, shipped] : expandShipped(files)) {
    CalibrationParams c = readCalibrationFile(f);
    c.shipped = shipped;
    // A fit of the organ's material is the whole scene's: no twin can hold it (shipped ones are
    // read by tables truth-cube, and passed over elsewhere).
    if (!shipped && !c.material.empty())
      throw InputError(f, "/material",
                       "fits the organ's material, which belongs to a whole scene, not to a "
                       "model's calibrated twin: write it into the scene's organ (tables "
                       "truth-cube reads such fits from calibrations/truth-cube/)");
    // One file per model and organ: calibrations of one model on different organs (a table
    // over several phantoms) each apply to their own organ's cases.
    for (const CalibrationParams& o : out) {
      if (o.plugin != c.plugin || o.model != c.model) continue;
      const bool overlap =
          o.organs.empty() || c.organs.empty() ||
          std::any_of(c.organs.begin(), c.organs.end(),
                      [&o](const std::string& organ) { return calibrationApplies(o, organ); });
      if (overlap)
        throw InputError(f, "",
                         "a second calibration of " + c.plugin + "/" + c.model + " for " +
                             (c.organs.empty() ? std::string("any organ") : c.organs.front()) +
                             " (first: " + o.file + "); give one file per model and organ");
    }
    out.push_back(std::move(c));
  }
  return out;
}

void addCommon(CLI::App* cmd, CommonArgs& c, bool quick) {
  if (quick) cmd->add_flag("--quick", c.quick, "fewer cases, shorter runs (CI)");
  auto* cd = cmd->add_option("--cache-dir", c.cacheDir, "precomputation cache folder");
  auto* nc = cmd->add_flag("--no-cache", c.noCache, "do not read or write the cache");
  cd->excludes(nc);
}

std::optional<fs::path> cacheChoice(const CommonArgs& a) {
  if (a.noCache) return fs::path();
  if (!a.cacheDir.empty()) return fs::path(a.cacheDir);
  return std::nullopt;
}

CaseOptions caseOptions(const CommonArgs& a) {
  CaseOptions o;
  o.cacheDir = cacheChoice(a);
  if (a.explain)
    o.explain = [](const std::string& s) { std::cout << "explain: " << s << "\n" << std::flush; };
  return o;
}

fs::path makeOutDir(const std::string& out) {
  if (out.empty()) throw InputError("--out", "", "an output folder is required");
  std::error_code ec;
  fs::create_directories(out, ec);
  if (ec || !fs::is_directory(out)) throw InputError(out, "", "cannot create the output folder");
  return fs::path(out);
}

namespace {

/// The same command for the collect step: no --slurm, with --resume.
std::vector<std::string> collectCommand() {
  std::vector<std::string> out = {selfExecutable()};
  bool resume = false;
  for (size_t i = 1; i < g_commandLine.size(); ++i) {
    const std::string& a = g_commandLine[i];
    if (a == "--slurm") {
      ++i;
      continue;
    }
    if (a.rfind("--slurm=", 0) == 0) continue;
    if (a == "--resume") resume = true;
    out.push_back(a);
  }
  if (!resume) out.push_back("--resume");
  return out;
}

}  // namespace

std::unique_ptr<Dispatcher> makeDispatcher(const DispatchArgs& d) {
  if (d.mpi)
    return mpiDispatcher([](const std::string& line) { std::cerr << line << "\n" << std::flush; });
  if (!d.slurm.empty())
    return slurmDispatcher(d.slurm, selfExecutable(), collectCommand(), fs::current_path());
  return localDispatcher(d.jobs);
}

void addDispatch(CLI::App* cmd, DispatchArgs& d) {
  auto* jobs = cmd->add_option("--jobs", d.jobs, "cases at once, each its own process (default 1)")
                   ->check(positiveValue(true));
  auto* slurm = cmd->add_option("--slurm", d.slurm,
                                "write a Slurm job array of the cases and a collect step into "
                                "this folder (submits nothing; see README)");
  slurm->excludes(jobs);
  if (mpiAvailable()) {
    auto* mpi = cmd->add_flag("--mpi", d.mpi,
                              "under mpirun: rank 0 hands out the cases to the other ranks");
    mpi->excludes(jobs);
    mpi->excludes(slurm);
  }
}

bool plot(const std::string& script, const std::vector<std::string>& args) {
  const ScriptResult r = runScript(script, args);
  if (r.exitCode == 0) {
    if (!r.output.empty()) std::cout << r.output;
    return true;
  }
  if (r.exitCode == kScriptNoMatplotlib) {
    std::cout << "matplotlib is not installed for " << pythonInterpreter()
              << ": wrote the data, no picture (apt-get install python3-matplotlib)\n";
  } else {
    std::cout << "plot " << script << " failed (" << oneLine(r.output) << "): wrote the data\n";
  }
  return false;
}

void addChildArgs(CLI::App* cmd, ChildArgs& c, const std::string& what) {
  cmd->add_option("--timeout", c.timeout,
                  "seconds per " + what + ", each in its own process (implies child processes)")
      ->check(positiveValue(false));
  auto* resume =
      cmd->add_flag("--resume", c.resume,
                    "reuse the " + what + "s already finished in --out (implies child processes)");
  cmd->add_flag("--retry-failed", c.retryFailed,
                "with --resume: run the " + what + "s whose run failed (crash, timeout) again")
      ->needs(resume);
  addDispatch(cmd, c.dispatch);
}

bool childArgsGiven(const CLI::App& cmd) {
  for (const char* o : {"--jobs", "--mpi", "--slurm", "--resume", "--timeout"})
    if (cmd.get_option_no_throw(o) && cmd.count(o) > 0) return true;
  return false;
}

/// The child-process options (nullopt: in this process) and the dispatcher of sweep / converge.
std::optional<ChildCaseOptions> childOptions(const ChildArgs& c, PluginLoader& loader,
                                             double defaultTimeoutS) {
  if (!c.given) return std::nullopt;
  ChildCaseOptions child;
  child.executable = selfExecutable();
  child.pluginArgs = pluginDirArgs(loader.searchPath());
  child.timeoutS = c.timeout > 0 ? c.timeout : defaultTimeoutS;
  child.resume = c.resume;
  child.retryFailed = c.retryFailed;
  return child;
}

void printReferenceCheckLine(const std::string& label, const std::string& sceneFile,
                             const std::optional<ConvergenceResult>& check,
                             const std::optional<fs::path>& cacheDir) {
  if (cacheDir && cacheDir->empty()) return;  // --no-cache: nothing was looked up
  if (!check) {
    std::cout << "reference" << (label.empty() ? "" : " " + label)
              << ": discretisation error not estimated (`deformbench "
              << "converge " << sceneFile << " --out DIR --of-reference` estimates it, then `run` "
              << "and `sweep` print it)\n";
    return;
  }
  std::cout << "reference" << (label.empty() ? "" : " " + label) << ": "
            << convergenceSummary(*check);
  const std::string w = convergenceWarning(*check);
  std::cout << (w.empty() ? "" : "; warning: " + w) << " (cached study)\n";
}

}  // namespace deform::harness::cli
