// deformbench conformance: the conformance checks on plugins, one line per check.
#include "cli.h"

#include <deform/engine/plugin_loader.h>
#include <deform/sdk/cache.h>
#include <deform_harness/conformance.h>

#include <iomanip>
#include <iostream>
#include <sstream>

namespace deform::harness::cli {

namespace {

struct ConformanceArgs {
  std::vector<std::string> plugins, models, checks, skipChecks, expectedFailures;
  std::string scenes;
  std::string cacheDir;
  bool noCache = false;
  std::vector<std::string> pluginDirs;

  void declare(CLI::App* conformance) {
    conformance->add_option("--plugin", plugins, "plugin to check (repeatable; default: all)");
    conformance->add_option("--model", models, "model to check (repeatable; default: all)");
    conformance->add_option("--check", checks, "check to run (repeatable; default: all)");
    conformance->add_option("--skip-check", skipChecks, "check not to run (repeatable)");
    conformance->add_option("--expect-fail", expectedFailures,
                            "PLUGIN/CHECK or PLUGIN/MODEL/CHECK known to fail: reported xfail, "
                            "and a failure if it passes (repeatable)");
    conformance->add_option("--scenes", scenes,
                            "folder of scenes for the 'scenes' check (default: the shipped ones)");
    {
      auto* cd = conformance->add_option("--cache-dir", cacheDir, "precomputation cache folder");
      auto* nc = conformance->add_flag("--no-cache", noCache, "do not read or write the cache");
      cd->excludes(nc);
    }
  }
};

int cmdConformance(const ConformanceArgs& a) {
  const std::vector<std::string>& pluginDirs = a.pluginDirs;
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
  o.skipChecks = a.skipChecks;
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

}  // namespace

Verb addConformance(CLI::App& app) {
  return makeVerb<ConformanceArgs>(
      app, "conformance",
      "run the conformance checks on plugins (with --plugin-dir: the plugins in those folders); "
      "one line per check, exit 0 only when none failed",
      cmdConformance);
}

}  // namespace deform::harness::cli
