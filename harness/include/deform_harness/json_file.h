// deformbench harness: reading a JSON file the user named (a scene, a bench or calibration file).
#pragma once

#include <deform/sdk/error.h>

#include <exception>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>

namespace deform::harness {

/// The document in `file`. InputError(file, "", "cannot read the " + what) when it cannot be
/// opened, InputError(file, "", "not JSON: ...") when it does not parse.
template <class Json = nlohmann::ordered_json>
Json readJsonFile(const std::string& file, const std::string& what) {
  std::ifstream in(file);
  if (!in) throw InputError(file, "", "cannot read the " + what);
  try {
    return Json::parse(in);
  } catch (const std::exception& e) {
    throw InputError(file, "", std::string("not JSON: ") + e.what());
  }
}

}  // namespace deform::harness
