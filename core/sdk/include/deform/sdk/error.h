// deformbench SDK: typed errors. Bad input throws InputError carrying the file, the place in it
// (line, byte, JSON path, element index) and the problem; the harness prints what() as one line
// and exits non-zero. Programmer errors assert; numerical degeneracy is counted, not thrown.
#pragma once

#include <stdexcept>
#include <string>

/// Types thrown or caught across the plugin boundary keep default visibility (their typeinfo must
/// be one object process-wide) even when a plugin is compiled with -fvisibility=hidden.
#define DEFORM_VISIBLE __attribute__((visibility("default")))

namespace deform {

/// Bad input from a user-provided file or value: "FILE: PLACE: PROBLEM" (PLACE may be empty).
class DEFORM_VISIBLE InputError : public std::runtime_error {
 public:
  InputError(std::string file, std::string place, std::string problem)
      : std::runtime_error(format(file, place, problem)),
        m_file(std::move(file)),
        m_place(std::move(place)),
        m_problem(std::move(problem)) {}

  const std::string& file() const { return m_file; }
  const std::string& place() const { return m_place; }
  const std::string& problem() const { return m_problem; }

 private:
  static std::string format(const std::string& file, const std::string& place,
                            const std::string& problem) {
    std::string s = file.empty() ? std::string("<input>") : file;
    if (!place.empty()) s += ": " + place;
    return s + ": " + problem;
  }
  std::string m_file, m_place, m_problem;
};

/// A plugin could not be loaded or initialised. kind says which of the distinct failures it is.
class DEFORM_VISIBLE PluginError : public std::runtime_error {
 public:
  enum class Kind { FileNotFound, NotSharedObject, MissingSymbol, AbiMismatch, InitFailure };
  PluginError(Kind kind, std::string file, const std::string& problem)
      : std::runtime_error(file + ": " + problem), m_kind(kind), m_file(std::move(file)) {}
  Kind kind() const { return m_kind; }
  const std::string& file() const { return m_file; }

 private:
  Kind m_kind;
  std::string m_file;
};

/// A model was asked for something its capabilities do not include (e.g. cut()).
class DEFORM_VISIBLE UnsupportedError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

}  // namespace deform
