// The scene reader's JSON helpers (internal to libdeform_engine): values checked against their
// expected type and range, objects against their allowed keys, every error naming the file and
// the place (scene.cpp reads scene files with them, parameters too).
#pragma once

#include <deform/sdk/error.h>
#include <deform/sdk/mesh.h>
#include <deform/sdk/types.h>

#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

namespace deform::scene_json {

using nlohmann::json;

/// Shortest decimal that reads back as the same double.
std::string num(double v);

/// "number", "string", ... with integers called numbers too (JSON has one number type).
std::string typeName(const json& j);

/// "did you mean 'young'? " when one allowed name is near the unknown one: at most 2 edits, or
/// a third of the name's length for long names; the first of equally near names wins. Else "".
std::string didYouMean(const std::string& key, const std::vector<std::string>& allowed);

/// Reads one JSON object, refusing keys that are not in the allowed list, and remembers the path
/// of every value it hands out so that errors name it.
class ObjectReader {
 public:
  ObjectReader(const json& j, std::string path, const std::string& file,
               std::vector<std::string> allowed)
      : m_j(j), m_path(std::move(path)), m_file(file), m_allowed(std::move(allowed)) {
    if (!j.is_object())
      throw InputError(m_file, placeOf(m_path), "expected an object, got " + typeName(j));
    for (const auto& [key, value] : j.items()) {
      if (std::find(m_allowed.begin(), m_allowed.end(), key) == m_allowed.end()) {
        std::string known;
        for (const auto& a : m_allowed) known += (known.empty() ? "" : ", ") + a;
        throw InputError(m_file, child(key),
                         "unknown key '" + key + "' (" + didYouMean(key, m_allowed) +
                             "allowed here: " + known + ")");
      }
    }
  }

  static std::string placeOf(const std::string& path) { return path.empty() ? "/" : path; }
  std::string child(const std::string& key) const { return m_path + "/" + key; }
  const std::string& path() const { return m_path; }
  bool has(const std::string& key) const { return m_j.contains(key); }

  const json& required(const std::string& key) const {
    if (!m_j.contains(key)) throw InputError(m_file, child(key), "required key is missing");
    return m_j.at(key);
  }
  const json* optional(const std::string& key) const {
    return m_j.contains(key) ? &m_j.at(key) : nullptr;
  }

 private:
  const json& m_j;
  std::string m_path;
  const std::string& m_file;
  std::vector<std::string> m_allowed;
};

struct Ctx {
  const std::string& file;

  [[noreturn]] void fail(const std::string& path, const std::string& problem) const {
    throw InputError(file, ObjectReader::placeOf(path), problem);
  }

  double number(const json& j, const std::string& path) const {
    if (!j.is_number()) fail(path, "expected a number, got " + typeName(j));
    const double v = j.get<double>();
    if (!std::isfinite(v)) fail(path, "expected a finite number, got " + num(v));
    return v;
  }
  double positive(const json& j, const std::string& path) const {
    const double v = number(j, path);
    if (!(v > 0)) fail(path, "must be > 0, got " + num(v));
    return v;
  }
  long long integer(const json& j, const std::string& path) const {
    if (!j.is_number()) fail(path, "expected an integer, got " + typeName(j));
    if (j.is_number_integer()) return j.get<long long>();
    const double v = j.get<double>();
    if (!std::isfinite(v) || std::floor(v) != v || std::fabs(v) > 9.0e15)
      fail(path, "expected an integer, got " + num(v));
    return static_cast<long long>(v);
  }
  bool boolean(const json& j, const std::string& path) const {
    if (!j.is_boolean()) fail(path, "expected true or false, got " + typeName(j));
    return j.get<bool>();
  }
  std::string string(const json& j, const std::string& path) const {
    if (!j.is_string()) fail(path, "expected a string, got " + typeName(j));
    return j.get<std::string>();
  }
  const json& array(const json& j, const std::string& path) const {
    if (!j.is_array()) fail(path, "expected an array, got " + typeName(j));
    return j;
  }
  /// j as an array of n elements; what it expected (expected) and got otherwise.
  const json& arrayOf(const json& j, size_t n, const std::string& expected,
                      const std::string& path) const {
    if (!j.is_array() || j.size() != n) {
      fail(path, "expected " + expected + ", got " +
                     (j.is_array() ? "an array of " + std::to_string(j.size()) : typeName(j)));
    }
    return j;
  }
  Vec3 vec3(const json& j, const std::string& path) const {
    arrayOf(j, 3, "an array of 3 numbers", path);
    Vec3 v;
    for (int i = 0; i < 3; ++i) v[i] = number(j[i], path + "/" + std::to_string(i));
    return v;
  }
  Box box(const json& j, const std::string& path) const {
    arrayOf(j, 2, "a box [[xlo, ylo, zlo], [xhi, yhi, zhi]]", path);
    Box b;
    b.lo = vec3(j[0], path + "/0");
    b.hi = vec3(j[1], path + "/1");
    for (int i = 0; i < 3; ++i) {
      if (!(b.lo[i] <= b.hi[i]))
        fail(path, "box corner " + std::string(1, char('x' + i)) + " low " + num(b.lo[i]) +
                       " > high " + num(b.hi[i]));
    }
    return b;
  }
};

}  // namespace deform::scene_json
