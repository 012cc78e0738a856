// deformbench: the command-line program. Verbs (DESIGN.md "Command line"): plugins, run, phantom,
// tables, sweep, stability, report, bench, converge, conformance. Bad input ends with one line
// "deformbench: FILE: PLACE: PROBLEM" on stderr and exit code 2; an unexpected internal error
// exits 3. `run
// --strict` exits 1 when a model failed (results.json is still written whole).
#include <deform/engine/plugin_loader.h>
#include <deform/engine/scene.h>
#include <deform/geometry/mesh_io.h>
#include <deform/geometry/phantom.h>
#include <deform_harness/bench.h>
#include <deform_harness/calibration.h>
#include <deform_harness/child_process.h>
#include <deform_harness/conformance.h>
#include <deform_harness/convergence.h>
#include <deform_harness/dispatch.h>
#include <deform_harness/progress.h>
#include <deform_harness/results.h>
#include <deform_harness/runner.h>
#include <deform_harness/scripts.h>
#include <deform_harness/stability.h>
#include <deform_harness/sweep.h>
#include <deform_harness/tables.h>
#include <deform_harness/verify.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <iostream>
#include <map>
#include <optional>
#include <set>
#include <sstream>

namespace {

namespace fs = std::filesystem;
using namespace deform;
using namespace deform::harness;
using nlohmann::json;

constexpr int kExitBadInput = 2;
constexpr int kExitInternal = 3;
constexpr int kExitModelFailed = 1;

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

std::string valueText(const json& v) {
  if (v.is_null()) return "";
  if (v.is_string()) return v.get<std::string>();
  return v.dump();
}

// ---------------------------------------------------------------------------------- plugins

int cmdPlugins(bool asJson, const std::vector<std::string>& pluginDirs) {
  PluginLoader loader(searchPath(pluginDirs));
  json out = json::array();
  std::vector<std::string> failures;
  for (const std::string& name : loader.discover()) {
    json entry = {{"plugin", name}};
    try {
      const std::string file = loader.locate(name);
      entry["file"] = file;
      const std::vector<ModelInfo>& models = loader.loadFile(file);
      entry["models"] = json::array();
      for (const ModelInfo& m : models) {
        json jm = {{"name", m.name},
                   {"version", m.version},
                   {"description", m.description},
                   {"citation", m.citation}};
        jm["capabilities"] = json::array();
        for (Capability c : m.capabilities) jm["capabilities"].push_back(capabilityName(c));
        jm["parameters"] = json::array();
        for (const ParamSpec& p : m.params) jm["parameters"].push_back(paramSpecToJson(p));
        entry["models"].push_back(jm);
      }
    } catch (const PluginError& e) {
      entry["error"] = oneLine(e.what());
      failures.push_back(oneLine(e.what()));
    }
    out.push_back(entry);
  }
  if (asJson) {
    std::cout << out.dump(2) << "\n";
  } else {
    if (out.empty()) {
      std::cout << "no plugins found; searched:";
      for (const auto& d : loader.searchPath()) std::cout << " " << d;
      std::cout << "\n";
    }
    for (const json& entry : out) {
      if (entry.contains("error")) {
        std::cout << entry["plugin"].get<std::string>()
                  << ": cannot load: " << entry["error"].get<std::string>() << "\n\n";
        continue;
      }
      for (const json& m : entry["models"]) {
        std::cout << m["name"].get<std::string>() << " " << m["version"].get<std::string>()
                  << " (plugin " << entry["plugin"].get<std::string>() << ")\n"
                  << "  " << m["description"].get<std::string>() << "\n"
                  << "  file:         " << entry["file"].get<std::string>() << "\n"
                  << "  citation:     " << m["citation"].get<std::string>() << "\n"
                  << "  capabilities: ";
        std::string caps;
        for (const auto& c : m["capabilities"])
          caps += (caps.empty() ? "" : ", ") + c.get<std::string>();
        std::cout << (caps.empty() ? "none" : caps) << "\n  parameters:\n";
        if (m["parameters"].empty()) std::cout << "    (none)\n";
        for (const json& p : m["parameters"]) {
          std::string range;
          if (p.contains("choices")) {
            for (const auto& c : p["choices"])
              range += (range.empty() ? "" : "|") + c.get<std::string>();
          } else if (p.contains("min")) {
            range = "[" + (p["min"].is_null() ? std::string("-inf") : valueText(p["min"])) + ", " +
                    (p["max"].is_null() ? std::string("inf") : valueText(p["max"])) + "]";
          }
          std::ostringstream line;
          line << "    " << std::left << std::setw(22) << p["key"].get<std::string>() << " "
               << std::setw(6) << p["type"].get<std::string>() << " " << std::setw(6)
               << p["unit"].get<std::string>() << " default " << std::setw(10)
               << valueText(p["default"]) << " " << std::setw(20) << range << " "
               << p["description"].get<std::string>();
          if (p.contains("calibrate")) {
            const json& c = p["calibrate"];
            line << " [calibratable: " << valueText(c["min"]) << " .. " << valueText(c["max"])
                 << ", " << c["scale"].get<std::string>() << "]";
          }
          std::cout << line.str() << "\n";
        }
        std::cout << "\n";
      }
    }
  }
  for (const auto& f : failures) std::cerr << "deformbench: " << f << "\n";
  return failures.empty() ? 0 : kExitBadInput;
}

// -------------------------------------------------------------------------------------- run

std::string fmt(double v, int precision = 3) {
  if (!std::isfinite(v)) return "-";
  std::ostringstream s;
  s << std::setprecision(precision) << v;
  return s.str();
}

void printTable(const BenchmarkResult& r) {
  const bool anyError = std::any_of(r.runs.begin(), r.runs.end(),
                                    [](const RunRecord& run) { return run.error.has_value(); });
  std::vector<std::string> header = {"label",  "status",       "ms/step",
                                     "p95 ms", "precompute s", "counts"};
  if (anyError) {
    for (int k : r.scene.nearest) header.push_back("rmse_" + std::to_string(k) + " mm");
    for (const char* h : {"rmse_all mm", "max mm", "loss_ratio"}) header.push_back(h);
  }
  std::vector<std::vector<std::string>> rows;
  for (const RunRecord& run : r.runs) {
    std::vector<std::string> row;
    row.push_back(run.label + (run.isReference ? " [ref]" : ""));
    row.push_back(run.status == RunStatus::Ok && !run.valid ? std::string("invalid")
                                                            : std::string(statusName(run.status)));
    const bool timed = run.stepStats.samples > 0;
    row.push_back(timed ? fmt(run.stepStats.median) : "-");
    row.push_back(timed ? fmt(run.stepStats.p95) : "-");
    row.push_back(run.status == RunStatus::Unsupported ? "-" : fmt(run.precomputeS));
    std::string counts;
    for (const auto& [k, v] : run.counts)
      counts += (counts.empty() ? "" : " ") + k + "=" + std::to_string(v);
    row.push_back(counts.empty() ? "-" : counts);
    if (anyError) {
      if (run.error) {
        // "*": against an invalid reference (the line under the table says which and why).
        const std::string mark = run.referenceValid.value_or(true) ? "" : "*";
        for (const auto& kv : run.error->rmseNearest) row.push_back(fmt(1e3 * kv.second) + mark);
        row.push_back(fmt(1e3 * run.error->rmseAll) + mark);
        row.push_back(fmt(1e3 * run.error->max) + mark);
        row.push_back(fmt(run.error->lossRatio) + mark);
      } else {
        for (size_t i = 0; i < r.scene.nearest.size() + 3; ++i) row.push_back("-");
      }
    }
    rows.push_back(row);
  }
  std::vector<size_t> width(header.size());
  for (size_t c = 0; c < header.size(); ++c) {
    width[c] = header[c].size();
    for (const auto& row : rows) width[c] = std::max(width[c], row[c].size());
  }
  const auto printRow = [&](const std::vector<std::string>& row) {
    std::string line;
    for (size_t c = 0; c < row.size(); ++c) {
      std::string cell = row[c];
      cell.resize(width[c], ' ');
      line += (c ? "  " : "") + cell;
    }
    while (!line.empty() && line.back() == ' ') line.pop_back();
    std::cout << line << "\n";
  };
  printRow(header);
  for (const auto& row : rows) printRow(row);
  {
    const auto against = std::find_if(r.runs.begin(), r.runs.end(), [](const RunRecord& run) {
      return !run.referenceValid.value_or(true);
    });
    const bool marked = std::any_of(r.runs.begin(), r.runs.end(), [](const RunRecord& run) {
      return run.error && !run.referenceValid.value_or(true);
    });
    if (against != r.runs.end())
      std::cout << (marked ? "*: errors against an invalid reference: " : "no errors: ")
                << against->referenceInvalidReason << "\n";
  }
  for (const RunRecord& run : r.runs) {
    if (run.error && run.error->excludedGrasped > 0) {
      std::cout << "rmse_k: the k surface vertices nearest the grasp that no grasp holds ("
                << run.error->excludedGrasped << " grasped vertices left out)\n";
      break;
    }
  }
  for (const RunRecord& run : r.runs) {
    if (!run.message.empty()) std::cout << run.label << ": " << run.message << "\n";
    for (const auto& n : run.notes) std::cout << run.label << ": note: " << n << "\n";
  }
}

struct RunArgs {
  std::string scene;
  std::string out;
  bool explain = false;
  std::vector<std::string> only;
  bool noReference = false;
  std::string cacheDir;
  bool noCache = false;
  int steps = -1;
  bool strict = false;
  std::vector<std::string> pluginDirs;
  std::vector<std::string> calibrations;
  bool reuseReference = false;
  bool reuseModelSolves = false;
  bool writeCompared = false;
  bool inProcess = false;
};

/// The --calibration files, read and checked (InputError names the file); two files for one
/// model are refused.
std::vector<CalibrationParams> readCalibrations(const std::vector<std::string>& files) {
  std::vector<CalibrationParams> out;
  for (const std::string& f : files) {
    CalibrationParams c = readCalibrationFile(f);
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

/// Validity (DESIGN "Metrics") of each run that did not do what the scene asked, and the
/// reference's estimated discretisation error when a check of it is in the cache.
void printReferenceCheck(const std::string& sceneFile, const BenchmarkResult& result,
                         PluginLoader& loader, const std::optional<fs::path>& cacheDir) {
  for (const RunRecord& run : result.runs)
    if (run.status == RunStatus::Ok && !run.valid)
      std::cout << "invalid: " << run.label << ": " << run.invalidReason << "\n";
  const auto ref = std::find_if(result.runs.begin(), result.runs.end(),
                                [](const RunRecord& r) { return r.isReference; });
  if (ref == result.runs.end() || ref->status != RunStatus::Ok) return;
  if (cacheDir && cacheDir->empty()) return;  // --no-cache: nothing to look up
  const std::optional<ConvergenceResult> check = cachedReferenceCheck(sceneFile, loader, cacheDir);
  if (!check) {
    std::cout << "reference " << ref->label
              << ": discretisation error not estimated (`deformbench converge " << sceneFile
              << " --out DIR --of-reference` estimates it, then `run` prints it)\n";
    return;
  }
  std::cout << "reference " << ref->label << ": " << convergenceSummary(*check);
  const std::string w = convergenceWarning(*check);
  std::cout << (w.empty() ? "" : "; warning: " + w) << " (cached study)\n";
}

int cmdRun(const RunArgs& a) {
  PluginLoader loader(searchPath(a.pluginDirs));
  BenchmarkOptions options;
  options.only = a.only;
  options.noReference = a.noReference;
  if (a.noCache) {
    options.cacheDir = fs::path();
  } else if (!a.cacheDir.empty()) {
    options.cacheDir = fs::path(a.cacheDir);
  }
  options.outDir = a.out;
  options.run.maxSteps = a.steps;
  options.calibrations = readCalibrations(a.calibrations);
  options.reuseReference = a.reuseReference || a.reuseModelSolves;
  options.reuseModelSolves = a.reuseModelSolves;
  options.writeComparedSurface = a.writeCompared;
  options.isolateRuns = !a.inProcess;
  if (a.explain)
    options.explain = [](const std::string& s) { std::cout << "explain: " << s << "\n"; };
  options.progress = [](const std::string& s) { std::cout << s << "\n" << std::flush; };
  const BenchmarkResult result = runBenchmark(a.scene, loader, options);
  // What "repair" changed in the organ is part of the result (--explain said it already).
  if (!a.explain)
    for (const auto& line : result.organLog) std::cout << "organ: " << line << "\n";
  std::cout << "\n";
  printTable(result);
  printReferenceCheck(a.scene, result, loader, options.cacheDir);
  std::cout << "results: " << result.resultsPath.string() << "\n";
  if (!a.strict) return 0;
  // A model that failed (bad input it alone refuses, such as a self-intersecting surface for a
  // tet mesher, or an exception) is a row of the table; in strict mode it also fails the
  // command, one line per failed run, for pipelines that must notice it.
  int failed = 0;
  for (const RunRecord& run : result.runs) {
    if (run.status != RunStatus::Failed) continue;
    std::cerr << "deformbench: " << a.scene << ": " << run.label << ": " << oneLine(run.message)
              << "\n";
    ++failed;
  }
  return failed ? kExitModelFailed : 0;
}

// ---------------------------------------------------------------------------------- phantom

int cmdPhantom(const std::string& name, const std::string& out, double resolution, bool list) {
  if (list) {
    for (const std::string& n : phantomNames()) std::cout << phantomDescription(n) << "\n";
    return 0;
  }
  if (name.empty())
    throw InputError("phantom", "", "name a phantom (see deformbench phantom --list)");
  if (out.empty()) throw InputError("phantom", "", "--out FILE is required");
  const SurfaceMesh mesh = makePhantom(name, resolution);
  std::string ext = fs::path(out).extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  if (ext == ".obj") {
    writeObj(out, mesh);
  } else if (ext == ".off") {
    writeOff(out, mesh);
  } else if (ext == ".stl") {
    writeStl(out, mesh);
  } else if (ext == ".vtp") {
    writeVtp(out, mesh);
  } else {
    throw InputError(out, "", "unknown extension '" + ext + "' (use .obj, .off, .stl or .vtp)");
  }
  std::cout << "phantom:" << name << ": " << mesh.numVertices() << " vertices, " << mesh.numFaces()
            << " triangles -> " << out << "\n";
  return 0;
}

// ------------------------------------------------------------------- tables, sweep, stability

struct CommonArgs {
  std::string out;
  bool quick = false;
  bool explain = false;
  std::string cacheDir;
  bool noCache = false;
  std::vector<std::string> pluginDirs;
};

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

// --jobs, --mpi, --slurm DIR (dispatch.h): where the cases of a long command run.
struct DispatchArgs {
  int jobs = 1;
  bool mpi = false;
  std::string slurm;
};

/// The command line as given, for the Slurm collect step (set in main()).
std::vector<std::string> g_commandLine;

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

/// Runs a plotting script; one line when matplotlib (or Python) is missing. Returns true on
/// success.
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

struct TablesArgs {
  CommonArgs common;
  long long referenceElements = 0;
  double timeout = 0;
  bool resume = false;
  bool retryFailed = false;
  bool inProcess = false;
  bool noReferenceCheck = false;
  bool surfaceBaselines = false;
  std::string truthCubeData;
  DispatchArgs dispatch;
  std::vector<std::string> calibrations;
};

int cmdTables(const std::vector<std::string>& names, const TablesArgs& ta) {
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
    tables = buildTables(names, loader, o, &progress);
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

/// sweep and converge: their cases run in this process unless a dispatch option, --resume or
/// --timeout is given; then each is a `deformbench run` child handed to the dispatcher.
struct ChildArgs {
  bool given = false;  ///< --jobs, --mpi, --slurm, --resume or --timeout on the command line
  bool resume = false;
  bool retryFailed = false;
  double timeout = 0;
  DispatchArgs dispatch;
};

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

bool childArgsGiven(CLI::App* cmd) {
  for (const char* o : {"--jobs", "--mpi", "--slurm", "--resume", "--timeout"})
    if (cmd->get_option_no_throw(o) && cmd->count(o) > 0) return true;
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

int cmdSweep(const std::string& scene, const CommonArgs& a, bool noPlot,
             const std::vector<std::string>& calibrations, const ChildArgs& ch) {
  PluginLoader loader(searchPath(a.pluginDirs));
  SweepOptions o;
  o.calibrations = readCalibrations(calibrations);
  o.quick = a.quick;
  o.outDir = makeOutDir(a.out);
  o.cases = caseOptions(a);
  const std::unique_ptr<Dispatcher> dispatcher = makeDispatcher(ch.dispatch);
  o.cases.dispatcher = dispatcher.get();
  o.cases.child = childOptions(ch, loader, 900);
  std::vector<SweepPoint> points;
  {
    Progress progress(0, "sweep");
    points = runSweep(scene, loader, o, &progress);
  }
  size_t w = 6;
  for (const SweepPoint& p : points) w = std::max(w, p.label.size() + 2);
  std::cout << "\n";
  std::cout << std::left << std::setw(int(w)) << "point" << std::setw(12) << "status"
            << std::setw(10) << "ms/step" << std::setw(14) << "rmse_50 mm" << std::setw(14)
            << "rmse_all mm"
            << "pareto\n";
  for (const SweepPoint& p : points) {
    std::cout << std::left << std::setw(int(w)) << p.label << std::setw(12)
              << (p.status.size() > 11 ? p.status.substr(0, 11) : p.status) << std::setw(10)
              << fmt(p.msMedian) << std::setw(14) << fmt(1e3 * p.rmseNearest) << std::setw(14)
              << fmt(1e3 * p.rmseAll) << (p.pareto ? "*" : "") << "\n";
  }
  std::set<std::string> notes;  // the calibrated points' (the same for most of them)
  for (const SweepPoint& p : points)
    if (!p.note.empty() && notes.insert(p.note).second) std::cout << "note: " << p.note << "\n";
  if (!noPlot)
    plot("plot_sweep.py", {(o.outDir / "sweep.json").string(), (o.outDir / "sweep.png").string()});
  std::cout << "sweep: " << (o.outDir / "sweep.json").string() << "\n";
  return 0;
}

struct CalibrateArgs {
  CommonArgs common;
  std::vector<std::string> train, validate, params;
  std::string model, metric = "rmse_all", label;
  int budget = 40;
  double timeout = 0;
  DispatchArgs dispatch;
};

int cmdCalibrate(const CalibrateArgs& a) {
  PluginLoader loader(searchPath(a.common.pluginDirs));
  CalibrateOptions o;
  o.train = a.train;
  o.validate = a.validate;
  o.plugin = a.model;
  o.params = a.params;
  o.label = a.label;
  o.budget = a.budget;
  if (!calibMetricFromName(a.metric, o.metric))
    throw InputError("--metric", "",
                     "unknown metric '" + a.metric + "' (rmse_all, rmse_50 or loss_ratio)");
  if (a.budget < 1) throw InputError("--budget", "", "must be at least 1 (trials)");
  if (a.model.empty()) throw InputError("--model", "", "name the plugin to calibrate");
  o.outDir = makeOutDir(a.common.out);
  o.cases = caseOptions(a.common);
  if (!a.dispatch.slurm.empty())
    throw InputError("--slurm", "",
                     "calibrate chooses its trials as results come: use --jobs "
                     "or --mpi");
  const std::unique_ptr<Dispatcher> dispatcher = makeDispatcher(a.dispatch);
  o.cases.dispatcher = dispatcher.get();
  ChildCaseOptions child;
  child.executable = selfExecutable();
  child.pluginArgs = pluginDirArgs(loader.searchPath());
  child.runArgs = {"--reuse-reference"};
  if (a.timeout > 0) child.timeoutS = a.timeout;
  o.cases.child = child;
  nlohmann::ordered_json doc;
  {
    Progress progress(a.budget, "calibrate");
    doc = runCalibration(loader, o, &progress);
  }
  const auto mm = [&](const nlohmann::ordered_json& v) {
    if (!v.is_number()) return std::string("-");
    return doc["metric"] == "loss_ratio" ? fmt(v.get<double>(), 4)
                                         : fmt(1e3 * v.get<double>(), 4) + " mm";
  };
  std::cout << "\n"
            << doc["plugin"].get<std::string>() << " calibrated on " << a.train.size()
            << " scene(s), " << doc["evaluations"].get<int>() << " trials, "
            << fmt(doc["wall_s"].get<double>(), 3) << " s; metric "
            << doc["metric"].get<std::string>() << "\n";
  for (const auto& [k, v] : doc["params"].items())
    std::cout << "  " << k << " = " << fmt(v.get<double>(), 5) << " (default "
              << fmt(doc["defaults"][k].get<double>(), 5) << ")\n";
  for (const auto& w : doc["warnings"]) std::cout << "warning: " << w.get<std::string>() << "\n";
  for (const char* set : {"train", "validation"}) {
    for (const auto& p : doc[set]["per_scene"])
      std::cout << "  " << std::left << std::setw(11) << set << std::setw(48)
                << fs::path(p["scene"].get<std::string>()).filename().string() << " before "
                << std::setw(12) << mm(p["before"]) << " after " << mm(p["after"]) << "\n";
    if (!doc[set]["per_scene"].empty())
      std::cout << "  " << std::left << std::setw(11) << set << std::setw(48) << "mean"
                << " before " << std::setw(12) << mm(doc[set]["before"]) << " after "
                << mm(doc[set]["after"]) << "\n";
  }
  std::cout << "calibration: " << (o.outDir / "calibration.json").string() << "\n";
  return 0;
}

struct StabilityArgs {
  CommonArgs common;
  bool resume = false, retryFailed = false;
  std::vector<std::string> models, cases;
  double timeout = 0;
  DispatchArgs dispatch;
  bool noPlot = false;
};

int cmdStability(const StabilityArgs& a) {
  for (const std::string& m : a.models) requirePluginName("--model", m);
  PluginLoader loader(searchPath(a.common.pluginDirs));
  StabilityOptions o;
  o.quick = a.common.quick;
  o.resume = a.resume || a.retryFailed;
  o.retryFailed = a.retryFailed;
  o.outDir = makeOutDir(a.common.out);
  o.models = a.models;
  o.cases = a.cases;
  o.timeoutS = a.timeout;
  o.jobs = a.dispatch.jobs;
  const std::unique_ptr<Dispatcher> dispatcher = makeDispatcher(a.dispatch);
  o.dispatcher = dispatcher.get();
  o.pluginDirs = a.common.pluginDirs;
  if (a.common.noCache) {
    // The child runs use their own cache; --no-cache keeps them out of the user's.
    o.cacheDir = (o.outDir / "cache").string();
  } else {
    o.cacheDir = a.common.cacheDir;
  }
  std::vector<StabilityRecord> records;
  {
    Progress progress(0, "stability");
    records = runStability(loader, o, &progress);
  }
  // Verdicts, never "stable" alone: a run that reached its end may still have collapsed.
  std::map<std::string, std::map<std::string, int>> summary;
  for (const auto& r : records) ++summary[r.model][r.verdict];
  std::cout << "\n";
  for (const auto& [model, counts] : summary) {
    std::cout << std::left << std::setw(18) << model;
    for (const char* s : kStabilityVerdicts)
      std::cout << " " << s << "=" << (counts.count(s) ? counts.at(s) : 0);
    std::cout << "\n";
  }
  if (!a.noPlot)
    plot("plot_stability.py", {(o.outDir / "stability.json").string(), o.outDir.string()});
  std::cout << "stability: " << (o.outDir / "stability.md").string() << "\n";
  return 0;
}

int cmdReport(const std::string& dir, const std::string& out) {
  if (!fs::is_directory(dir)) throw InputError(dir, "", "not a folder");
  const std::string html = out.empty() ? (fs::path(dir) / "report.html").string() : out;
  const ScriptResult r = runScript("report.py", {dir, html});
  std::cout << r.output;
  if (r.exitCode != 0) {
    std::cerr << "deformbench: report: " << oneLine(r.output) << "\n";
    return kExitBadInput;
  }
  return 0;
}

struct BenchArgs {
  CommonArgs common;
  std::vector<std::string> compare;
  double threshold = 0.25;
  int repeat = 3;
  int steps = 100;
  std::vector<std::string> only;
};

int cmdBench(const BenchArgs& a) {
  if (!a.compare.empty()) {
    if (a.compare.size() != 2) throw InputError("--compare", "", "give OLD.json NEW.json");
    const auto oldDoc = readBenchFile(a.compare[0]);
    const auto newDoc = readBenchFile(a.compare[1]);
    const BenchComparison c = compareBench(oldDoc, newDoc, a.threshold);
    printBenchComparison(c, a.threshold, std::cout);
    return c.regressions > 0 ? 1 : 0;
  }
  if (a.common.out.empty()) throw InputError("bench", "", "--out FILE.json or --compare OLD NEW");
  PluginLoader loader(searchPath(a.common.pluginDirs));
  BenchOptions o;
  o.out = a.common.out;
  if (o.out.has_parent_path()) fs::create_directories(o.out.parent_path());
  o.repeat = a.repeat;
  o.steps = a.steps;
  o.only = a.only;
  o.cases = caseOptions(a.common);
  {
    Progress progress(0, "bench");
    runBench(loader, o, &progress);
  }
  std::cout << "bench: " << o.out.string() << "\n";
  return 0;
}

int cmdConverge(const std::string& scene, const CommonArgs& a, long long elements,
                double edgeLength, bool ofReference, const ChildArgs& ch) {
  PluginLoader loader(searchPath(a.pluginDirs));
  ConvergeOptions o;
  o.outDir = makeOutDir(a.out);
  o.cacheDir = cacheChoice(a);
  o.baseElements = elements;
  o.baseEdgeLength = edgeLength;
  const std::unique_ptr<Dispatcher> dispatcher = makeDispatcher(ch.dispatch);
  o.dispatcher = dispatcher.get();
  o.child = childOptions(ch, loader, 86400);
  if (ofReference) {
    if (elements > 0 || edgeLength > 0)
      throw InputError("--of-reference", "",
                       "takes the reference's own size: drop --elements and --edge-length");
    o.hRatios = kReferenceCheckRatios;
  }
  ConvergenceResult r;
  {
    Progress progress(0, "converge");
    r = runConvergence(scene, loader, o, &progress);
  }
  for (const auto& l : r.levels) {
    std::cout << "level: ";
    if (l.targetH > 0) {
      std::cout << "target h = " << fmt(1e3 * l.targetH) << " mm";
    } else {
      std::cout << l.targetElements << " target elements";
    }
    std::cout << ": " << l.elements << " elements, h = " << fmt(1e3 * l.h)
              << " mm, peak |u| = " << fmt(1e3 * l.peakDisplacement) << " mm, " << l.status << ", "
              << fmt(l.solveS) << " s\n";
  }
  if (r.cached)
    std::cout << "(the study was read from the precomputation cache; --no-cache reruns it)\n";
  if (r.reason == "levels_failed") {
    std::cout << "warning: " << r.message << "\n";
    return 0;
  }
  std::cout << "max surface difference between levels: " << fmt(1e3 * r.d01) << " mm, then "
            << fmt(1e3 * r.d12) << " mm (vertices near loads and grasps left out); RMS "
            << fmt(1e3 * r.rms01) << " mm, then " << fmt(1e3 * r.rms12) << " mm\n";
  if (std::isnan(r.relativeError)) {
    std::cout << "warning: " << r.message;
    if (std::isfinite(r.boundRelative))
      std::cout << "; the levels differ by up to " << fmt(100 * r.boundRelative)
                << "% of the peak displacement";
    std::cout << "\n";
  } else {
    std::cout << "observed order p = " << fmt(r.order) << ", estimated error of the finest level "
              << fmt(1e3 * r.errorEstimate) << " mm = " << fmt(100 * r.relativeError)
              << "% of the peak displacement\n";
  }
  if (std::isfinite(r.rmsRelativeError))
    std::cout << "RMS differences: observed order p = " << fmt(r.rmsOrder)
              << ", estimated RMS error " << fmt(100 * r.rmsRelativeError)
              << "% of the peak displacement\n";
  if (!r.converged) {
    if (!std::isnan(r.relativeError))
      std::cout << "warning: the reference is not shown converged to 1%"
                << (r.asymptotic ? "" : " (" + r.message + ")")
                << ": refine it (a smaller \"edge_length\") or read its errors as bounds of that "
                   "size\n";
  } else {
    std::cout << "the reference is converged to within 1% at " << r.levels[2].elements
              << " elements\n";
  }
  return 0;
}

// ------------------------------------------------------------------------------ verify

int cmdVerify(const std::string& scene, const CommonArgs& a, int steps) {
  PluginLoader loader(searchPath(a.pluginDirs));
  VerifyOptions o;
  o.outDir = makeOutDir(a.out);
  o.cacheDir = cacheChoice(a);
  o.maxSteps = steps;
  const VerifyResult r = runVerify(scene, loader, o);
  const auto times = [](const VerifySolverTimes& t) {
    return fmt(t.wallS) + " s wall, " + fmt(t.cpuS) + " s CPU";
  };
  for (const VerifyInstant& in : r.instants)
    std::cout << "t = " << fmt(in.time) << " s: calculix differs from reference_fem by "
              << fmt(100 * in.rmsRelative) << "% RMS, " << fmt(100 * in.maxRelative)
              << "% max of the RMS displacement " << fmt(1e3 * in.referenceRms) << " mm ("
              << in.vertices << " vertices); reference_fem " << times(in.reference) << ", calculix "
              << times(in.calculix) << "\n";
  for (const std::string& note : r.notes) std::cout << "note: " << note << "\n";
  if (!r.message.empty())
    std::cout << "warning: " << r.message << "\n";
  else if (!r.agrees)
    std::cout << "warning: the solvers differ by more than " << fmt(100 * kVerifyGoal)
              << "% RMS at some instant\n";
  std::cout << "wrote " << r.jsonPath.string() << "\n";
  return 0;
}

// ------------------------------------------------------------------------------ conformance

struct ConformanceArgs {
  std::vector<std::string> plugins, models, checks, expectedFailures;
  std::string scenes;
  std::string cacheDir;
  bool noCache = false;
};

int cmdConformance(const ConformanceArgs& a, const std::vector<std::string>& pluginDirs) {
  PluginLoader loader(searchPath(pluginDirs));
  ConformanceOptions o;
  o.plugins = a.plugins;
  // With --plugin-dir and no --plugin: the plugins in those folders (an author's own build).
  if (o.plugins.empty() && !pluginDirs.empty()) {
    o.plugins = PluginLoader(pluginDirs).discover();
    if (o.plugins.empty()) {
      std::string dirs;
      for (const auto& d : pluginDirs) dirs += (dirs.empty() ? "" : ", ") + d;
      throw InputError("--plugin-dir", "",
                       "no plugin (deform_NAME.so) in " + dirs +
                           " (a plugin is built as deform_NAME.so: deformbench_add_plugin)");
    }
  }
  o.models = a.models;
  o.checks = a.checks;
  o.expectedFailures = a.expectedFailures;
  o.scenesDir = a.scenes.empty() ? defaultConformanceScenesDir() : fs::path(a.scenes);
  if (!a.scenes.empty() && !fs::is_directory(o.scenesDir))
    throw InputError(a.scenes, "", "--scenes: not a folder");
  o.report = [](const CheckResult& r) {
    std::ostringstream line;
    line << std::left << std::setw(6) << checkOutcomeName(r.outcome) << std::setw(30)
         << (r.plugin + (r.model.empty() ? "" : "/" + r.model)) << " " << std::setw(13) << r.check;
    line << std::right << std::setw(8) << (r.seconds >= 0.05 ? fmt(r.seconds, 2) + " s" : "");
    if (!r.detail.empty()) line << "  " << oneLine(r.detail);
    std::cout << line.str() << "\n" << std::flush;
  };
  Cache cache(a.noCache            ? fs::path()
              : a.cacheDir.empty() ? Cache::defaultDir()
                                   : fs::path(a.cacheDir));
  const std::vector<CheckResult> results = runConformance(loader, cache, o);
  int passed = 0, failed = 0, skipped = 0, xfail = 0;
  for (const CheckResult& r : results) {
    switch (r.outcome) {
      case CheckOutcome::Passed:
        ++passed;
        break;
      case CheckOutcome::Skipped:
        ++skipped;
        break;
      case CheckOutcome::ExpectedFailure:
        ++xfail;
        break;
      default:
        ++failed;
    }
  }
  std::cout << passed << " passed, " << failed << " failed";
  if (skipped) std::cout << ", " << skipped << " skipped (not applicable)";
  if (xfail) std::cout << ", " << xfail << " expected failures";
  std::cout << "\n";
  return failed ? kExitModelFailed : 0;
}

int realMain(int argc, char** argv) {
  CLI::App app{"deformbench: compares soft-tissue deformation models on equal terms"};
  app.require_subcommand(1);
  // Global options (--plugin-dir) are accepted before or after the verb.
  app.fallthrough();

  std::vector<std::string> pluginDirs;
  app.add_option(
      "--plugin-dir", pluginDirs,
      "extra folder to search for plugins (before $DEFORM_PLUGIN_PATH and the defaults)");

  bool pluginsJson = false;
  CLI::App* plugins = app.add_subcommand("plugins", "list every plugin found, with its parameters");
  plugins->add_flag("--json", pluginsJson, "print JSON");

  RunArgs ra;
  CLI::App* run = app.add_subcommand("run", "run every model of a scene and write results.json");
  run->add_option("scene", ra.scene, "scene file (JSON)")->required();
  run->add_option("--out", ra.out, "output folder")->required();
  run->add_flag(
      "--explain", ra.explain,
      "say which plugins were loaded, which models built, cache use and what was skipped");
  run->add_option("--only", ra.only,
                  "run only this model (label, model or plugin name; repeatable)");
  run->add_flag("--no-reference", ra.noReference, "do not run the scene's reference");
  auto* cacheOpt = run->add_option("--cache-dir", ra.cacheDir, "precomputation cache folder");
  auto* noCacheOpt = run->add_flag("--no-cache", ra.noCache, "do not read or write the cache");
  cacheOpt->excludes(noCacheOpt);
  run->add_option("--steps", ra.steps, "stop every run after this many steps (quick tries)")
      ->check(positiveValue(true));
  run->add_option("--calibration", ra.calibrations,
                  "calibration.json of `deformbench calibrate`: its model takes those parameters "
                  "where the scene writes none (repeatable, one file per model)")
      ->allow_extra_args(false);
  run->add_flag("--reuse-reference", ra.reuseReference,
                "read the reference from the cache when an earlier run with this flag solved "
                "the same problem (calibration trials, the tables; its timings are that run's)")
      ->group("");
  run->add_flag("--reuse-model-solves", ra.reuseModelSolves,
                "with --reuse-reference: quasi-static models too (the tables' reference checks)")
      ->group("");
  run->add_flag("--write-compared", ra.writeCompared,
                "also write each run's surface at its last compared instant (converge's levels)")
      ->group("");
  run->add_flag("--in-process", ra.inProcess,
                "run the models in this process (a crash of one ends the command; debuggers)")
      ->group("");
  run->add_flag("--strict", ra.strict,
                "exit 1 when a model failed (one stderr line each; results.json still written)");

  std::string phName, phOut;
  double phRes = 1.0;
  bool phList = false;
  CLI::App* phantom = app.add_subcommand("phantom", "write a built-in organ phantom mesh");
  phantom->add_option("name", phName, "phantom name (see --list)");
  phantom->add_option("--out", phOut, "output mesh file (.obj, .off, .stl, .vtp)");
  phantom->add_option("--resolution", phRes, "vertex-count scale (1 = default)")
      ->check(positiveValue(false));
  phantom->add_flag("--list", phList, "list the phantoms");

  const auto addCommon = [](CLI::App* cmd, CommonArgs& c, bool quick) {
    if (quick) cmd->add_flag("--quick", c.quick, "fewer cases, shorter runs (CI)");
    auto* cd = cmd->add_option("--cache-dir", c.cacheDir, "precomputation cache folder");
    auto* nc = cmd->add_flag("--no-cache", c.noCache, "do not read or write the cache");
    cd->excludes(nc);
  };

  std::vector<std::string> tableNamesArg;
  TablesArgs ta;
  CLI::App* tables = app.add_subcommand(
      "tables",
      "regenerate the papers' tables (metaballs-construction, method-comparison, "
      "bem-timing, bem-accuracy, hybrid-accuracy, hybrid-timing, verification, truth-cube, "
      "or all)");
  tables->add_option("name", tableNamesArg, "table name(s) or all")->required();
  tables->add_option("--out", ta.common.out, "output folder")->required();
  tables
      ->add_option("--reference-elements", ta.referenceElements,
                   "target tets of the reference FEM, quadratic (default 20000; 4000 with --quick)")
      ->check(positiveValue(true));
  tables->add_flag("--no-reference-check", ta.noReferenceCheck,
                   "skip the convergence study of each table's reference (three solves at 2, "
                   "1.4 and 1 x its edge length; cached)");
  tables->add_flag("--surface-baselines", ta.surfaceBaselines,
                   "hybrid tables: PBD and mass-spring on the organ's surface mesh alone, as the "
                   "paper ran them (default: on its volume, network = volume)");
  tables->add_option(
      "--data", ta.truthCubeData,
      "truth-cube: a bead file of the layout of data/truth-cube/uniaxial_positions.csv "
      "(default: that file)");
  tables->add_flag("--explain", ta.common.explain,
                   "say what each case loaded, built, cached, skipped");
  tables
      ->add_option("--timeout", ta.timeout,
                   "seconds per case, each case running in its own process (default 900)")
      ->check(positiveValue(false));
  auto* tablesResume =
      tables->add_flag("--resume", ta.resume, "reuse the cases already finished in --out");
  tables
      ->add_flag("--retry-failed", ta.retryFailed,
                 "with --resume: run the cases with a failed run (crash, timeout) again")
      ->needs(tablesResume);
  tables->add_flag("--in-process", ta.inProcess,
                   "run the cases in this process (no time limit, a crash ends the command)");
  addCommon(tables, ta.common, true);
  addDispatch(tables, ta.dispatch);
  tables
      ->add_option("--calibration", ta.calibrations,
                   "calibration.json: its model runs at its defaults and calibrated in every "
                   "case, and the table 'calibration' shows both (repeatable)")
      ->allow_extra_args(false);

  std::string sweepScene;
  CommonArgs sa;
  bool sweepNoPlot = false;
  CLI::App* sweep = app.add_subcommand(
      "sweep", "error against run time: each model over its accuracy knob, with a plot");
  sweep->add_option("scene", sweepScene, "scene file with a reference")->required();
  sweep->add_option("--out", sa.out, "output folder")->required();
  sweep->add_flag("--no-plot", sweepNoPlot, "write the data only");
  std::vector<std::string> sweepCalibrations;
  sweep
      ->add_option("--calibration", sweepCalibrations,
                   "calibration.json: its model is swept at its defaults and calibrated "
                   "(repeatable)")
      ->allow_extra_args(false);
  sweep->add_flag("--explain", sa.explain, "say what was loaded, built, cached, skipped");
  addCommon(sweep, sa, true);
  ChildArgs sweepChild;
  addChildArgs(sweep, sweepChild, "point");

  CalibrateArgs cal;
  CLI::App* calibrate = app.add_subcommand(
      "calibrate", "fit a model's calibratable parameters to the reference of training scenes");
  calibrate->add_option("scenes", cal.train, "training scene files (with a reference)")->required();
  calibrate->add_option("--model", cal.model, "plugin to calibrate")->required();
  calibrate->add_option("--out", cal.common.out, "output folder (calibration.json)")->required();
  calibrate->add_option("--validate", cal.validate, "held-out scene (repeatable)")
      ->allow_extra_args(false);
  calibrate->add_option("--metric", cal.metric, "rmse_all (default), rmse_50 or loss_ratio");
  calibrate->add_option("--budget", cal.budget, "trials at most (default 40)");
  calibrate->add_option("--label", cal.label, "free text kept in calibration.json");
  calibrate
      ->add_option("--param", cal.params, "calibrate only this calibratable parameter (repeatable)")
      ->allow_extra_args(false);
  calibrate
      ->add_option("--timeout", cal.timeout,
                   "seconds per model run, each in its own process "
                   "(default 900)")
      ->check(positiveValue(false));
  addDispatch(calibrate, cal.dispatch);
  addCommon(calibrate, cal.common, false);

  StabilityArgs st;
  CLI::App* stability = app.add_subcommand(
      "stability", "every model over stiff and extreme cases, each in its own process");
  stability->add_option("--out", st.common.out, "output folder")->required();
  stability->add_flag("--resume", st.resume,
                      "skip the cases already finished in --out (with the same scenes)");
  stability->add_flag("--retry-failed", st.retryFailed,
                      "with --resume (implied): run the cases that failed again");
  stability->add_option("--model", st.models, "plugin to test (repeatable; default: all found)");
  stability->add_option("--case", st.cases, "case id to run (repeatable; default: the set)");
  stability->add_option("--timeout", st.timeout, "seconds per case (default 120, 60 with --quick)")
      ->check(positiveValue(false));
  addDispatch(stability, st.dispatch);
  stability->add_flag("--no-plot", st.noPlot, "write the data only");
  addCommon(stability, st.common, true);

  std::string reportDir, reportOut;
  CLI::App* report = app.add_subcommand(
      "report", "a self-contained HTML report of a results, tables, sweep or stability folder");
  report->add_option("dir", reportDir, "folder")->required();
  report->add_option("--out", reportOut, "HTML file (default DIR/report.html)");

  BenchArgs ba;
  CLI::App* bench = app.add_subcommand(
      "bench", "time a fixed set of model x scene cases, or compare two such files");
  bench->add_option("--out", ba.common.out, "bench file to write (JSON)");
  bench->add_option("--compare", ba.compare, "OLD.json NEW.json: print ratios, exit 1 on slowdown")
      ->expected(2);
  bench->add_option("--threshold", ba.threshold, "slowdown flagged above this fraction (0.25)")
      ->check(CLI::NonNegativeNumber);
  bench->add_option("--repeat", ba.repeat, "runs per case (median taken)")
      ->check(positiveValue(true));
  bench->add_option("--steps", ba.steps, "steps per run")->check(positiveValue(true));
  bench->add_option("--only", ba.only, "case id or plugin (repeatable)");
  addCommon(bench, ba.common, false);

  std::string convScene;
  CommonArgs ca;
  long long convElements = 0;
  double convEdgeLength = 0;
  CLI::App* converge = app.add_subcommand(
      "converge", "is the scene's reference converged? three mesh sizes + Richardson");
  converge->add_option("scene", convScene, "scene file with a reference")->required();
  converge->add_option("--out", ca.out, "output folder")->required();
  converge
      ->add_option("--edge-length", convEdgeLength,
                   "coarsest level's edge length h in m (levels h, h/1.4, h/2; default: the "
                   "reference's own)")
      ->check(positiveValue(false));
  converge
      ->add_option("--elements", convElements,
                   "coarsest level's h as the edge length of about this many tets")
      ->check(positiveValue(true));
  bool convOfReference = false;
  converge->add_flag("--of-reference", convOfReference,
                     "levels 2h, 1.4h and h of the reference's own size h: the estimate is the "
                     "error of the reference as the scene runs it (cached; `run` then prints it)");
  addCommon(converge, ca, false);
  ChildArgs convChild;
  addChildArgs(converge, convChild, "level");

  std::string verifyScene;
  CommonArgs va;
  int verifySteps = -1;
  CLI::App* verify = app.add_subcommand(
      "verify", "the scene's reference solved by reference_fem and by CalculiX (ccx) on one mesh");
  verify->add_option("scene", verifyScene, "scene file with a reference")->required();
  verify->add_option("--out", va.out, "output folder (verify.json)")->required();
  verify->add_option("--steps", verifySteps, "stop after this many steps")
      ->check(CLI::PositiveNumber);
  addCommon(verify, va, false);

  std::vector<std::string> workTasks;
  CLI::App* work =
      app.add_subcommand("work", "run task files written by --slurm (one array task each)");
  work->group("");  // internal: the Slurm array's command
  work->add_option("task", workTasks, "task file (JSON)")->required();

  ConformanceArgs cf;
  CLI::App* conformance = app.add_subcommand(
      "conformance",
      "run the conformance checks on plugins (with --plugin-dir: the plugins in those folders); "
      "one line per check, exit 0 only when none failed");
  conformance->add_option("--plugin", cf.plugins, "plugin to check (repeatable; default: all)");
  conformance->add_option("--model", cf.models, "model to check (repeatable; default: all)");
  conformance->add_option("--check", cf.checks, "check to run (repeatable; default: all)");
  conformance->add_option("--expect-fail", cf.expectedFailures,
                          "PLUGIN/CHECK or PLUGIN/MODEL/CHECK known to fail: reported xfail, "
                          "and a failure if it passes (repeatable)");
  conformance->add_option("--scenes", cf.scenes,
                          "folder of scenes for the 'scenes' check (default: the shipped ones)");
  {
    auto* cd = conformance->add_option("--cache-dir", cf.cacheDir, "precomputation cache folder");
    auto* nc = conformance->add_flag("--no-cache", cf.noCache, "do not read or write the cache");
    cd->excludes(nc);
  }

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    if (e.get_exit_code() == 0) return app.exit(e);
    std::cerr << "deformbench: " << oneLine(e.what()) << " (see deformbench --help)\n";
    return kExitBadInput;
  }
  if (*plugins) return cmdPlugins(pluginsJson, pluginDirs);
  if (*run) {
    ra.pluginDirs = pluginDirs;
    return cmdRun(ra);
  }
  if (*phantom) return cmdPhantom(phName, phOut, phRes, phList);
  if (*conformance) return cmdConformance(cf, pluginDirs);
  if (*tables) {
    ta.common.pluginDirs = pluginDirs;
    return cmdTables(tableNamesArg, ta);
  }
  if (*sweep) {
    sa.pluginDirs = pluginDirs;
    sweepChild.given = childArgsGiven(sweep);
    return cmdSweep(sweepScene, sa, sweepNoPlot, sweepCalibrations, sweepChild);
  }
  if (*calibrate) {
    cal.common.pluginDirs = pluginDirs;
    return cmdCalibrate(cal);
  }
  if (*stability) {
    st.common.pluginDirs = pluginDirs;
    return cmdStability(st);
  }
  if (*report) return cmdReport(reportDir, reportOut);
  if (*bench) {
    ba.common.pluginDirs = pluginDirs;
    return cmdBench(ba);
  }
  if (*work) {
    for (const std::string& f : workTasks) {
      std::ifstream in(f);
      if (!in) throw InputError(f, "", "cannot read the task file");
      nlohmann::ordered_json task;
      try {
        task = nlohmann::ordered_json::parse(in);
      } catch (const std::exception& e) {
        throw InputError(f, "", oneLine(e.what()));
      }
      try {
        executeTask(task);
      } catch (const std::invalid_argument& e) {
        throw InputError(f, "kind", e.what());
      }
    }
    return 0;
  }
  if (*verify) {
    va.pluginDirs = pluginDirs;
    return cmdVerify(verifyScene, va, verifySteps);
  }
  if (*converge) {
    ca.pluginDirs = pluginDirs;
    convChild.given = childArgsGiven(converge);
    if (convElements > 0 && convEdgeLength > 0)
      throw InputError("converge", "--elements", "give --elements or --edge-length, not both");
    return cmdConverge(convScene, ca, convElements, convEdgeLength, convOfReference, convChild);
  }
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
