#include <deform/sdk/params.h>

#include <cassert>
#include <cmath>
#include <cstdio>
#include <stdexcept>

namespace deform {

namespace {

const char* typeName(const ParamValue& v) {
  switch (v.index()) {
    case 0:
      return "bool";
    case 1:
      return "integer";
    case 2:
      return "real";
    default:
      return "string";
  }
}

// Undeclared keys and wrong types are programmer errors (the model asked for something it did
// not declare, or under another type): assert in debug builds, throw in release builds so the
// harness can still report one clean line and tests can check the behaviour.
template <class T>
const T& typed(const std::map<std::string, ParamValue>& values, const std::string& key,
               const char* wanted) {
  auto it = values.find(key);
  if (it == values.end()) {
    assert(false && "ParamValues: undeclared parameter key");
    throw std::logic_error("parameter '" + key + "' was not declared");
  }
  if (!std::holds_alternative<T>(it->second)) {
    assert(false && "ParamValues: parameter read with the wrong type");
    throw std::logic_error("parameter '" + key + "' is " + typeName(it->second) + ", read as " +
                           wanted);
  }
  return std::get<T>(it->second);
}

std::string formatValue(const ParamValue& v) {
  char buf[64];
  switch (v.index()) {
    case 0:
      return std::get<bool>(v) ? "true" : "false";
    case 1:
      std::snprintf(buf, sizeof buf, "%lld", std::get<long long>(v));
      return buf;
    case 2:
      std::snprintf(buf, sizeof buf, "%g", std::get<double>(v));
      return buf;
    default:
      return std::get<std::string>(v);
  }
}

}  // namespace

double ParamValues::real(const std::string& key) const {
  return typed<double>(m_values, key, "real");
}

long long ParamValues::integer(const std::string& key) const {
  return typed<long long>(m_values, key, "integer");
}

bool ParamValues::flag(const std::string& key) const {
  return typed<bool>(m_values, key, "bool");
}

const std::string& ParamValues::choice(const std::string& key) const {
  return typed<std::string>(m_values, key, "choice");
}

ParamValues ParamValues::defaults(const std::vector<ParamSpec>& specs) {
  std::map<std::string, ParamValue> values;
  for (const ParamSpec& s : specs) values[s.key] = s.defaultValue;
  return ParamValues(std::move(values));
}

std::string formatNonDefault(const ParamValues& values, const std::vector<ParamSpec>& specs) {
  std::string out;
  for (const ParamSpec& s : specs) {
    auto it = values.all().find(s.key);
    if (it == values.all().end() || it->second == s.defaultValue) continue;
    if (!out.empty()) out += ',';
    out += s.key + '=' + formatValue(it->second);
  }
  return out;
}

}  // namespace deform

namespace deform {

std::string calibrationDeclarationProblem(const ParamSpec& spec) {
  if (!spec.calibratable) return "";
  if (spec.type != ParamType::Real) return "only real parameters can be calibratable";
  if (!(std::isfinite(spec.calibMin) && std::isfinite(spec.calibMax) &&
        spec.calibMin < spec.calibMax))
    return "calibration bounds must be finite with min < max";
  if (spec.calibMin < spec.min || spec.calibMax > spec.max)
    return "calibration bounds must lie inside the valid range";
  if (spec.calibScale == ParamScale::Log && spec.calibMin <= 0)
    return "a log-scale calibration needs bounds > 0";
  return "";
}

}  // namespace deform
