// Generated scenes run through the loader and runner, and the table writers (see cases.h).
#include <deform/internal/atomic_file.h>
#include <deform/sdk/cache.h>
#include <deform_harness/cases.h>
#include <deform_harness/child_process.h>
#include <deform_harness/dispatch.h>
#include <deform_harness/results.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

namespace deform::harness {

namespace fs = std::filesystem;
using ojson = nlohmann::ordered_json;

std::string pluginProblem(PluginLoader& loader, const std::string& plugin) {
  try {
    loader.loadFile(loader.locate(plugin));
    return "";
  } catch (const PluginError& e) {
    std::string s = e.what();
    std::replace(s.begin(), s.end(), '\n', ' ');
    return s;
  }
}

const RunRecord* CaseResult::run(const std::string& label) const {
  if (!result) return nullptr;
  for (const RunRecord& r : result->runs)
    if (r.label == label) return &r;
  return nullptr;
}

namespace {

using Clock = std::chrono::steady_clock;

std::string readText(const fs::path& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

/// A failed record for a run a failed child took down.
RunRecord failedRun(const ojson& spec, bool isReference, const std::string& message) {
  RunRecord r;
  r.plugin = spec.value("plugin", "");
  r.model = r.plugin;
  r.label = spec.value("label", r.plugin);
  r.isReference = isReference;
  r.status = RunStatus::Failed;
  r.message = message;
  invalidateIfNotOk(r);
  return r;
}

/// Fills c.result from outDir/results.json (when present) and the failed runs of case.json.
void readCase(CaseResult& c, const ojson& caseDoc) {
  BenchmarkResult b;
  const fs::path results = c.outDir / "results.json";
  if (fs::exists(results)) {
    const nlohmann::json doc = nlohmann::json::parse(readText(results));
    for (const auto& run : doc.at("runs")) b.runs.push_back(runFromJson(run));
    if (doc.contains("organ")) {
      c.organVertices = doc["organ"].value("vertices", -1);
      c.organFaces = doc["organ"].value("triangles", -1);
    }
    b.resultsPath = results;
  }
  for (const auto& f : caseDoc.value("failed_runs", ojson::array()))
    b.runs.push_back(failedRun(f, f.value("role", "model") == "reference", f.value("message", "")));
  c.wallS = caseDoc.value("wall_s", 0.0);
  c.result = std::move(b);
}

/// Label and plugin of a model or reference entry.
ojson runEntry(const ojson& m) {
  return {{"label", m.value("label", m.value("plugin", ""))}, {"plugin", m.value("plugin", "")}};
}

/// The task of a case in a child process (see ChildCaseOptions and dispatch.h).
ojson caseTask(const ojson& pruned, const fs::path& runScene, const fs::path& outDir,
               const CaseOptions& options) {
  const ChildCaseOptions& co = *options.child;
  std::vector<std::string> argv = {co.executable};
  argv.insert(argv.end(), co.pluginArgs.begin(), co.pluginArgs.end());
  argv.insert(argv.end(),
              {"run", fs::absolute(runScene).string(), "--out", fs::absolute(outDir).string()});
  if (options.cacheDir) {
    if (options.cacheDir->empty()) {
      argv.push_back("--no-cache");
    } else {
      argv.insert(argv.end(), {"--cache-dir", fs::absolute(*options.cacheDir).string()});
    }
  }
  if (options.explain) argv.push_back("--explain");
  argv.insert(argv.end(), co.runArgs.begin(), co.runArgs.end());
  const auto flag = [&](bool on, const char* name) {
    if (on && std::find(argv.begin(), argv.end(), name) == argv.end()) argv.push_back(name);
  };
  flag(options.reuseReference || options.reuseModelSolves, "--reuse-reference");
  flag(options.reuseModelSolves, "--reuse-model-solves");
  if (options.run.maxSteps > 0)
    argv.insert(argv.end(), {"--steps", std::to_string(options.run.maxSteps)});
  ojson models = ojson::array();
  for (const auto& m : pruned["models"]) models.push_back(runEntry(m));
  ojson task = {
      {"kind", "case"},
      {"argv", argv},
      {"out", fs::absolute(outDir).string()},
      {"timeout_s", co.timeoutS},
      {"models", models},
      {"reference", pruned.contains("reference") ? runEntry(pruned["reference"]) : ojson()}};
  if (options.stage != 0) task["stage"] = options.stage;
  return task;
}

/// The --explain lines of the case's children (their logs), to the caller's explain.
void forwardExplain(const CaseResult& c, const ojson& caseDoc, const CaseOptions& options) {
  if (!options.explain) return;
  std::vector<std::string> logs = {"log.txt"};
  if (caseDoc.contains("child_no_reference")) logs.push_back("log_no_reference.txt");
  for (const std::string& log : logs) {
    std::istringstream lines(readText(c.outDir / log));
    for (std::string line; std::getline(lines, line);)
      if (line.rfind("explain: ", 0) == 0) options.explain(line.substr(9));
  }
}

/// A case prepared in the calling thread: either finished (resumed, not runnable) or a task.
struct Prepared {
  CaseResult c;
  ojson task;  ///< null: c is final
};

Prepared prepareCase(const SceneCase& sc, PluginLoader& loader) {
  Prepared p;
  CaseResult& c = p.c;
  const CaseOptions& options = sc.options;
  c.sceneFile = sc.sceneFile;
  c.outDir = sc.outDir;
  std::error_code ec;
  fs::create_directories(sc.sceneFile.parent_path(), ec);
  writeFileAtomic(sc.sceneFile, sc.scene.dump(2) + "\n");

  ojson pruned = sc.scene;
  ojson kept = ojson::array();
  for (const auto& m : sc.scene.value("models", ojson::array())) {
    const std::string plugin = m.value("plugin", "");
    const std::string why = pluginProblem(loader, plugin);
    if (why.empty()) {
      kept.push_back(m);
    } else {
      c.missing[plugin] = why;
    }
  }
  pruned["models"] = kept;
  if (sc.scene.contains("reference")) {
    const std::string plugin = sc.scene["reference"].value("plugin", "");
    const std::string why = pluginProblem(loader, plugin);
    if (!why.empty()) {
      c.missing[plugin] = why;
      pruned.erase("reference");
    }
  }
  if (kept.empty()) {
    c.error = "no plugin of this case could be loaded";
    return p;
  }
  fs::create_directories(sc.outDir, ec);
  const fs::path runScene = sc.outDir / "scene.json";
  const std::string prunedText = pruned.dump(2) + "\n";
  if (options.child && options.child->resume && fs::exists(sc.outDir / "case.json") &&
      readText(runScene) == prunedText) {
    try {
      readCase(c, ojson::parse(readText(sc.outDir / "case.json")));
      const bool failed =
          c.result && std::any_of(c.result->runs.begin(), c.result->runs.end(),
                                  [](const RunRecord& r) { return r.status == RunStatus::Failed; });
      if (!(options.child->retryFailed && failed)) {
        c.resumed = true;
        return p;
      }
      c.result.reset();  // --retry-failed: run it again
      c.wallS = 0;
    } catch (const std::exception&) {
      c.result.reset();  // unreadable: run it again
    }
  }
  fs::remove(sc.outDir / "case.json");
  writeFileAtomic(runScene, prunedText);
  if (options.child) {
    p.task = caseTask(pruned, runScene, sc.outDir, options);
    return p;
  }
  const BenchmarkOptions o{.only = {},  // every model
                           .cacheDir = options.cacheDir,
                           .outDir = sc.outDir,
                           .run = options.run,
                           .explain = options.explain,
                           .progress = options.progress,
                           .reuseReference = options.reuseReference || options.reuseModelSolves,
                           .reuseModelSolves = options.reuseModelSolves,
                           .calibrations = {}};
  const auto start = Clock::now();
  try {
    c.result = runBenchmark(runScene.string(), loader, o);
    c.organVertices = c.result->organ.surface.numVertices();
    c.organFaces = c.result->organ.surface.numFaces();
  } catch (const std::exception& e) {
    c.error = e.what();
  }
  c.wallS = std::chrono::duration<double>(Clock::now() - start).count();
  return p;
}

void finishCase(CaseResult& c, const ojson& caseDoc, const CaseOptions& options) {
  try {
    forwardExplain(c, caseDoc, options);
    readCase(c, caseDoc);
  } catch (const std::exception& e) {
    c.error = e.what();
  }
}

}  // namespace

ojson runCaseTask(const ojson& task) {
  const fs::path outDir = task.at("out").get<std::string>();
  const double timeoutS = task.at("timeout_s").get<double>();
  const auto start = Clock::now();
  const auto job = [&](bool noReference, const std::string& log) {
    ChildJob j;
    j.argv = task.at("argv").get<std::vector<std::string>>();
    if (noReference) j.argv.push_back("--no-reference");
    j.log = outDir / log;
    return j;
  };
  const auto failureOf = [&](const ChildOutcome& o, const ChildJob& j) {
    std::string f = childFailure(o, timeoutS, lastLogLine(j.log, 300));
    if (f.empty() && !fs::exists(outDir / "results.json")) f = "exit code 0 without results.json";
    return f;
  };
  const auto failedEntry = [](const ojson& e, const char* role, const std::string& message) {
    return ojson{{"label", e.value("label", "")},
                 {"plugin", e.value("plugin", "")},
                 {"role", role},
                 {"message", message}};
  };

  ojson caseDoc = {{"format", "deformbench-case/1"}, {"failed_runs", ojson::array()}};
  fs::remove(outDir / "results.json");
  const ChildJob first = job(false, "log.txt");
  const std::string failure = failureOf(runChild(first, timeoutS), first);
  caseDoc["child"] = failure.empty() ? "ok" : failure;
  if (!failure.empty()) {
    const ojson& reference = task.at("reference");
    const bool hasReference = !reference.is_null();
    std::string second;
    if (hasReference) {
      const ChildJob retry = job(true, "log_no_reference.txt");
      second = failureOf(runChild(retry, timeoutS), retry);
      caseDoc["child_no_reference"] = second.empty() ? "ok" : second;
    }
    if (hasReference && second.empty()) {
      caseDoc["failed_runs"].push_back(
          failedEntry(reference, "reference",
                      failure + " (with the reference; the models then ran without it)"));
    } else {
      fs::remove(outDir / "results.json");
      for (const auto& m : task.at("models"))
        caseDoc["failed_runs"].push_back(failedEntry(m, "model", failure));
      if (hasReference)
        caseDoc["failed_runs"].push_back(failedEntry(reference, "reference", failure));
    }
  }
  caseDoc["wall_s"] = std::chrono::duration<double>(Clock::now() - start).count();
  writeFileAtomic(outDir / "case.json", caseDoc.dump(2) + "\n");
  return caseDoc;
}

ojson lostCaseDoc(const ojson& task, const std::string& message) {
  ojson caseDoc = {{"format", "deformbench-case/1"}, {"failed_runs", ojson::array()}};
  caseDoc["child"] = message;
  for (const auto& m : task.at("models"))
    caseDoc["failed_runs"].push_back({{"label", m.value("label", "")},
                                      {"plugin", m.value("plugin", "")},
                                      {"role", "model"},
                                      {"message", message}});
  const ojson& reference = task.at("reference");
  if (!reference.is_null())
    caseDoc["failed_runs"].push_back({{"label", reference.value("label", "")},
                                      {"plugin", reference.value("plugin", "")},
                                      {"role", "reference"},
                                      {"message", message}});
  caseDoc["wall_s"] = 0.0;
  return caseDoc;
}

void runSceneCases(const std::vector<SceneCase>& cases, PluginLoader& loader,
                   Dispatcher* dispatcher, const std::function<void(size_t)>& onStart,
                   const std::function<void(size_t, CaseResult&&)>& onDone) {
  std::vector<Prepared> prepared;
  std::vector<ojson> tasks;
  std::vector<size_t> taskCase;
  for (size_t i = 0; i < cases.size(); ++i) {
    // In-process cases run in prepareCase: announce them first.
    const bool inProcess = !cases[i].options.child;
    if (inProcess && onStart) onStart(i);
    prepared.push_back(prepareCase(cases[i], loader));
    if (prepared.back().task.is_null()) {
      if (!inProcess && onStart) onStart(i);
      if (onDone) onDone(i, std::move(prepared.back().c));
    } else {
      tasks.push_back(prepared.back().task);
      taskCase.push_back(i);
    }
  }
  if (tasks.empty()) return;
  std::unique_ptr<Dispatcher> serial;
  if (!dispatcher) {
    serial = localDispatcher(1);
    dispatcher = serial.get();
  }
  dispatcher->run(
      tasks,
      [&](size_t t) {
        if (onStart) onStart(taskCase[t]);
      },
      [&](size_t t, const ojson& caseDoc) {
        const size_t i = taskCase[t];
        finishCase(prepared[i].c, caseDoc, cases[i].options);
        if (onDone) onDone(i, std::move(prepared[i].c));
      });
}

CaseResult runSceneCase(const ojson& scene, const fs::path& sceneFile, const fs::path& outDir,
                        PluginLoader& loader, const CaseOptions& options) {
  CaseResult out;
  runSceneCases({SceneCase{scene, sceneFile, outDir, options}}, loader, options.dispatcher, nullptr,
                [&](size_t, CaseResult&& c) { out = std::move(c); });
  return out;
}

ojson numberOrNull(double v) {
  return std::isfinite(v) ? ojson(v) : ojson(nullptr);
}

std::string cellText(const ojson& v) {
  if (v.is_null()) return "-";
  if (v.is_string()) return v.get<std::string>();
  if (v.is_boolean()) return v.get<bool>() ? "yes" : "no";
  if (v.is_number_integer() || v.is_number_unsigned()) return v.dump();
  if (v.is_number_float()) {
    const double d = v.get<double>();
    char buf[32];
    if (d != 0 && (std::fabs(d) >= 1e6 || std::fabs(d) < 1e-3)) {
      std::snprintf(buf, sizeof buf, "%.3e", d);
    } else {
      std::snprintf(buf, sizeof buf, "%.4g", d);
    }
    return buf;
  }
  return v.dump();
}

namespace {

std::string csvField(const ojson& v) {
  std::string s;
  if (v.is_null()) return "";
  if (v.is_string()) {
    s = v.get<std::string>();
  } else if (v.is_number_float()) {
    char buf[40];
    std::snprintf(buf, sizeof buf, "%.10g", v.get<double>());
    s = buf;
  } else {
    s = v.dump();
  }
  if (s.find_first_of(",\"\n") != std::string::npos) {
    std::string q = "\"";
    for (char ch : s) q += ch == '"' ? std::string("\"\"") : std::string(1, ch);
    return q + "\"";
  }
  return s;
}

std::string mdCell(std::string s) {
  std::string out;
  for (char ch : s) {
    if (ch == '|') {
      out += "\\|";
    } else if (ch == '\n') {
      out += ' ';
    } else {
      out += ch;
    }
  }
  return out;
}

}  // namespace

void writeTable(const Table& t, const fs::path& dir) {
  std::error_code ec;
  fs::create_directories(dir, ec);
  std::ostringstream md;
  md << "# " << t.name << ": " << t.title << "\n\n";
  if (!t.source.empty()) md << "Paper columns: " << t.source << "\n\n";
  md << "|";
  for (const auto& c : t.columns) md << " " << mdCell(c.header) << " |";
  md << "\n|";
  for (size_t i = 0; i < t.columns.size(); ++i) md << "---|";
  md << "\n";
  for (const auto& row : t.rows) {
    md << "|";
    for (const auto& c : t.columns)
      md << " " << mdCell(cellText(row.contains(c.key) ? row[c.key] : ojson(nullptr))) << " |";
    md << "\n";
  }
  if (!t.notes.empty()) {
    md << "\n";
    for (const auto& n : t.notes) md << "- " << mdCell(n) << "\n";
  }
  writeFileAtomic(dir / (t.name + ".md"), md.str());

  std::ostringstream csv;
  for (size_t i = 0; i < t.columns.size(); ++i)
    csv << (i ? "," : "") << csvField(ojson(t.columns[i].key));
  csv << "\n";
  for (const auto& row : t.rows) {
    for (size_t i = 0; i < t.columns.size(); ++i) {
      const auto& key = t.columns[i].key;
      csv << (i ? "," : "") << csvField(row.contains(key) ? row[key] : ojson(nullptr));
    }
    csv << "\n";
  }
  writeFileAtomic(dir / (t.name + ".csv"), csv.str());

  ojson j;
  j["format"] = "deformbench-table/1";
  j["table"] = t.name;
  j["title"] = t.title;
  j["source"] = t.source;
  j["notes"] = t.notes;
  j["columns"] = ojson::array();
  for (const auto& c : t.columns) j["columns"].push_back({{"key", c.key}, {"header", c.header}});
  j["rows"] = t.rows;
  writeFileAtomic(dir / (t.name + ".json"), j.dump(2) + "\n");
}

}  // namespace deform::harness
