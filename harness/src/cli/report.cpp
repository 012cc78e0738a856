// deformbench report: a self-contained HTML report of an output folder.
#include "cli.h"

#include <deform_harness/scripts.h>

#include <iostream>

namespace deform::harness::cli {

namespace {

struct ReportArgs {
  std::string dir, out;

  void declare(CLI::App* report) {
    report->add_option("dir", dir, "folder")->required();
    report->add_option("--out", out, "HTML file (default DIR/report.html)");
  }
};

int cmdReport(const ReportArgs& a) {
  const std::string &dir = a.dir, &out = a.out;
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

}  // namespace

Verb addReport(CLI::App& app) {
  return makeVerb<ReportArgs>(
      app, "report", "a self-contained HTML report of a results, tables, sweep or stability folder",
      cmdReport);
}

}  // namespace deform::harness::cli
