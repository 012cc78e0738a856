// The scene reader's JSON helpers (scene_json.h).
#include "scene_json.h"

#include <charconv>

namespace deform::scene_json {

namespace {

/// Levenshtein distance between two names (insertions, deletions, substitutions, each 1).
size_t editDistance(const std::string& a, const std::string& b) {
  std::vector<size_t> row(b.size() + 1);
  for (size_t j = 0; j <= b.size(); ++j) row[j] = j;
  for (size_t i = 1; i <= a.size(); ++i) {
    size_t diag = row[0];
    row[0] = i;
    for (size_t j = 1; j <= b.size(); ++j) {
      const size_t up = row[j];
      row[j] = std::min({row[j] + 1, row[j - 1] + 1, diag + (a[i - 1] == b[j - 1] ? 0 : 1)});
      diag = up;
    }
  }
  return row[b.size()];
}

}  // namespace

/// Shortest decimal that reads back as the same double.
std::string num(double v) {
  if (std::isnan(v)) return "nan";
  if (std::isinf(v)) return v > 0 ? "inf" : "-inf";
  char buf[64];
  const auto r = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, r.ptr);
}

/// "number", "string", ... with integers called numbers too (JSON has one number type).
std::string typeName(const json& j) {
  if (j.is_number()) return "number";
  if (j.is_boolean()) return "boolean";
  return j.type_name();
}

/// "did you mean 'young'? " when one allowed name is near the unknown one: at most 2 edits, or
/// a third of the name's length for long names; the first of equally near names wins. Else "".
std::string didYouMean(const std::string& key, const std::vector<std::string>& allowed) {
  const size_t limit = std::max<size_t>(2, key.size() / 3);
  size_t best = limit + 1;
  std::string name;
  for (const std::string& a : allowed) {
    const size_t d = editDistance(key, a);
    if (d < best) {
      best = d;
      name = a;
    }
  }
  return name.empty() ? "" : "did you mean '" + name + "'? ";
}

}  // namespace deform::scene_json
