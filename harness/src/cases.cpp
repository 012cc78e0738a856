// Generated scenes run through the loader and runner, and the table writers (see cases.h).
#include <deform/cache.h>
#include <deform_harness/cases.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
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

CaseResult runSceneCase(const ojson& scene, const fs::path& sceneFile, const fs::path& outDir,
                        PluginLoader& loader, const CaseOptions& options) {
  CaseResult c;
  c.sceneFile = sceneFile;
  c.outDir = outDir;
  std::error_code ec;
  fs::create_directories(sceneFile.parent_path(), ec);
  writeFileAtomic(sceneFile, scene.dump(2) + "\n");

  ojson pruned = scene;
  ojson kept = ojson::array();
  for (const auto& m : scene.value("models", ojson::array())) {
    const std::string plugin = m.value("plugin", "");
    const std::string why = pluginProblem(loader, plugin);
    if (why.empty()) {
      kept.push_back(m);
    } else {
      c.missing[plugin] = why;
    }
  }
  pruned["models"] = kept;
  if (scene.contains("reference")) {
    const std::string plugin = scene["reference"].value("plugin", "");
    const std::string why = pluginProblem(loader, plugin);
    if (!why.empty()) {
      c.missing[plugin] = why;
      pruned.erase("reference");
    }
  }
  if (kept.empty()) {
    c.error = "no plugin of this case could be loaded";
    return c;
  }
  fs::create_directories(outDir, ec);
  const fs::path runScene = outDir / "scene.json";
  writeFileAtomic(runScene, pruned.dump(2) + "\n");
  BenchmarkOptions o;
  o.cacheDir = options.cacheDir;
  o.outDir = outDir;
  o.run = options.run;
  o.explain = options.explain;
  o.progress = options.progress;
  try {
    c.result = runBenchmark(runScene.string(), loader, o);
  } catch (const std::exception& e) {
    c.error = e.what();
  }
  return c;
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
