// deformbench plugins: every plugin found, with its models and parameters.
#include "cli.h"

#include <deform/engine/plugin_loader.h>

#include <iomanip>
#include <iostream>
#include <sstream>

namespace deform::harness::cli {

namespace {

struct PluginsArgs {
  bool json = false;
  std::vector<std::string> pluginDirs;

  void declare(CLI::App* plugins) { plugins->add_flag("--json", json, "print JSON"); }
};

std::string valueText(const json& v) {
  if (v.is_null()) return "";
  if (v.is_string()) return v.get<std::string>();
  return v.dump();
}

// ---------------------------------------------------------------------------------- plugins

int cmdPlugins(const PluginsArgs& a) {
  PluginLoader loader(searchPath(a.pluginDirs));
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
  if (a.json) {
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

}  // namespace

Verb addPlugins(CLI::App& app) {
  return makeVerb<PluginsArgs>(app, "plugins", "list every plugin found, with its parameters",
                               cmdPlugins);
}

}  // namespace deform::harness::cli
