// deformbench work: the task files written by --slurm, one array task each (an internal verb).
#include "cli.h"

#include <fstream>
#include <stdexcept>

namespace deform::harness::cli {

namespace {

struct WorkArgs {
  std::vector<std::string> tasks;

  void declare(CLI::App* work) {
    work->group("");  // internal: the Slurm array's command
    work->add_option("task", tasks, "task file (JSON)")->required();
  }
};

int cmdWork(const WorkArgs& a) {
  for (const std::string& f : a.tasks) {
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

}  // namespace

Verb addWork(CLI::App& app) {
  return makeVerb<WorkArgs>(app, "work", "run task files written by --slurm (one array task each)",
                            cmdWork);
}

}  // namespace deform::harness::cli
