// deformbench harness: the Python scripts the project ships (harness/scripts: plots with
// matplotlib, the HTML report) and running them with /usr/bin/python3 (Debian's
// python3-matplotlib installs for that interpreter, which need not be the first python3 on PATH).
#pragma once

#include <string>
#include <vector>

namespace deform::harness {

/// Folder of the shipped scripts: $DEFORM_SCRIPTS_DIR, else the source tree's harness/scripts,
/// else <prefix>/share/deformbench/scripts beside the installed program. "" when none exists.
std::string scriptsDir();

/// The interpreter: $DEFORM_PYTHON, else /usr/bin/python3, else "python3".
std::string pythonInterpreter();

struct ScriptResult {
  int exitCode = -1;   ///< the script's exit code; -1: could not start
  std::string output;  ///< stdout and stderr
};

/// Runs `python script args...` (script relative to scriptsDir()) and collects its output.
/// Exit code 3 is the scripts' convention for "matplotlib is not installed".
ScriptResult runScript(const std::string& script, const std::vector<std::string>& args);

/// The exit code the scripts use when matplotlib is missing.
inline constexpr int kScriptNoMatplotlib = 3;

}  // namespace deform::harness
