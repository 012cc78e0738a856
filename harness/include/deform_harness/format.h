// deformbench harness: how numbers and vectors are written into labels, file names, command
// lines and JSON documents, once for every writer.
#pragma once

#include <deform/sdk/types.h>

#include <nlohmann/json.hpp>
#include <string>

namespace deform::harness {

/// v as printf's "%g" writes it: six significant digits, fixed or exponent, whichever is
/// shorter ("0.5", "1e-06").
std::string formatG(double v);

/// A vector as a JSON array [x, y, z].
nlohmann::ordered_json vecJson(const Vec3& v);

}  // namespace deform::harness
