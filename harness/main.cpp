// deformbench: the command-line program. Verbs: plugins, run, phantom (DESIGN.md "Command
// line"). Bad input ends with one line "deformbench: FILE: PLACE: PROBLEM" on stderr and exit
// code 2; an unexpected internal error exits 3.
#include <deform/mesh_io.h>
#include <deform/phantom.h>
#include <deform/plugin_loader.h>
#include <deform/scene.h>
#include <deform_harness/results.h>
#include <deform_harness/runner.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <iostream>
#include <sstream>

namespace {

namespace fs = std::filesystem;
using namespace deform;
using namespace deform::harness;
using nlohmann::json;

constexpr int kExitBadInput = 2;
constexpr int kExitInternal = 3;

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
    row.push_back(statusName(run.status));
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
        for (const auto& kv : run.error->rmseNearest) row.push_back(fmt(1e3 * kv.second));
        row.push_back(fmt(1e3 * run.error->rmseAll));
        row.push_back(fmt(1e3 * run.error->max));
        row.push_back(fmt(run.error->lossRatio));
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
  std::vector<std::string> pluginDirs;
};

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
  if (a.explain)
    options.explain = [](const std::string& s) { std::cout << "explain: " << s << "\n"; };
  options.progress = [](const std::string& s) { std::cout << s << "\n" << std::flush; };
  const BenchmarkResult result = runBenchmark(a.scene, loader, options);
  std::cout << "\n";
  printTable(result);
  std::cout << "results: " << result.resultsPath.string() << "\n";
  return 0;
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

int realMain(int argc, char** argv) {
  CLI::App app{"deformbench: compares soft-tissue deformation models on equal terms"};
  app.require_subcommand(1);

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
      ->check(CLI::PositiveNumber);

  std::string phName, phOut;
  double phRes = 1.0;
  bool phList = false;
  CLI::App* phantom = app.add_subcommand("phantom", "write a built-in organ phantom mesh");
  phantom->add_option("name", phName, "phantom name (see --list)");
  phantom->add_option("--out", phOut, "output mesh file (.obj, .off, .stl, .vtp)");
  phantom->add_option("--resolution", phRes, "vertex-count scale (1 = default)")
      ->check(CLI::PositiveNumber);
  phantom->add_flag("--list", phList, "list the phantoms");

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
  return kExitBadInput;
}

}  // namespace

int main(int argc, char** argv) {
  // Before anything starts threads: timings are single-threaded by contract.
  forceSingleThreadedNumerics();
  try {
    return realMain(argc, argv);
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
