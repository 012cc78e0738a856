// deformbench report: a self-contained HTML report of an output folder.
#include "cli.h"

#include <deform_harness/scripts.h>

#include <iostream>

namespace deform::harness::cli {

namespace {

struct ReportArgs {
  std::string dir, out;
};

int cmdReport(const std::string& dir, const std::string& out);

}  // namespace

Verb addReport(CLI::App& app) {
  auto args = std::make_shared<ReportArgs>();
  CLI::App* report = app.add_subcommand(
      "report", "a self-contained HTML report of a results, tables, sweep or stability folder");
  report->add_option("dir", args->dir, "folder")->required();
  report->add_option("--out", args->out, "HTML file (default DIR/report.html)");
  return {report,
          [args](const std::vector<std::string>&) { return cmdReport(args->dir, args->out); }};
}

namespace {

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

}  // namespace

}  // namespace deform::harness::cli
