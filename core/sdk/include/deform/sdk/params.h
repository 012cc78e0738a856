// deformbench SDK: declared parameters. Each model declares every parameter once (key, SI unit,
// default, valid range, one-line description); the harness validates scenes against the list,
// prints it in `deformbench plugins` and writes the resolved values into results.json.
#pragma once

#include <deform/sdk/error.h>
#include <deform/sdk/types.h>

#include <limits>
#include <map>
#include <string>
#include <utility>
#include <variant>
#include <vector>

namespace deform {

// GCC's -Wshadow takes the scoped enumerator ParamType::Real for a shadow of the type
// deform::Real (clang does not); the SDK keeps the name.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wshadow"
enum class ParamType { Real, Int, Bool, Choice };
#pragma GCC diagnostic pop

/// How a calibrating optimiser moves a parameter between its bounds: Linear in the value, Log in
/// its logarithm (for stiffnesses and compliances spanning decades; bounds must then be > 0).
enum class ParamScale { Linear, Log };

/// "linear" | "log" (as `deformbench plugins` and calibration.json print it).
inline const char* paramScaleName(ParamScale s) {
  return s == ParamScale::Log ? "log" : "linear";
}

using ParamValue = std::variant<bool, long long, double, std::string>;

struct ParamSpec {
  std::string key;
  std::string unit;  ///< SI unit ("Pa", "m", "s", "1" for dimensionless, "" for counts/choices)
  ParamType type = ParamType::Real;
  ParamValue defaultValue = 0.0;
  double min = -std::numeric_limits<double>::infinity();  ///< inclusive, Real and Int
  double max = std::numeric_limits<double>::infinity();   ///< inclusive, Real and Int
  std::vector<std::string> choices;                       ///< Choice only
  std::string description;
  /// Calibratable (issue G2): the parameter stands in for material behaviour the model cannot
  /// take from (E, nu, rho) exactly, so `deformbench calibrate` may fit it to a reference within
  /// [calibMin, calibMax] (inside [min, max]) in calibScale. Real parameters only; the organ's E,
  /// nu and rho themselves are never calibratable. Appended in ABI 4.
  bool calibratable = false;
  double calibMin = 0, calibMax = 0;
  ParamScale calibScale = ParamScale::Linear;

  /// This declaration, marked calibratable between lo and hi in the given scale. Usage:
  ///   ParamSpec::real("stiffness", "1", 1, 0, 1, "...").calibrate(0.01, 1, ParamScale::Log)
  ParamSpec calibrate(double lo, double hi, ParamScale scale) const {
    ParamSpec p = *this;
    p.calibratable = true;
    p.calibMin = lo;
    p.calibMax = hi;
    p.calibScale = scale;
    return p;
  }

  static ParamSpec real(std::string key, std::string unit, double def, double lo, double hi,
                        std::string description) {
    return {std::move(key),        std::move(unit), ParamType::Real, def, lo, hi, {},
            std::move(description)};
  }
  static ParamSpec integer(std::string key, long long def, long long lo, long long hi,
                           std::string description) {
    return {std::move(key), "", ParamType::Int,        def, double(lo),
            double(hi),     {}, std::move(description)};
  }
  static ParamSpec flag(std::string key, bool def, std::string description) {
    return {std::move(key), "", ParamType::Bool, def, 0, 1, {}, std::move(description)};
  }
  static ParamSpec choice(std::string key, std::string def, std::vector<std::string> choices,
                          std::string description) {
    return {std::move(key),        "", ParamType::Choice, std::move(def), 0, 0, std::move(choices),
            std::move(description)};
  }
};

/// Declarations several plugins make alike: the same key, unit, lower bound and calibration
/// scale; each plugin gives its default, its upper bound and its own one-line description.
namespace common_params {

/// "iterations": solver sweeps per step, an integer in [1, max].
inline ParamSpec iterations(long long def, long long max, std::string description) {
  return ParamSpec::integer("iterations", def, 1, max, std::move(description));
}
/// "damping": a velocity damping rate (1/s) in [0, max], calibratable in [calibLo, 1000] (log).
inline ParamSpec damping(double def, double max, double calibLo, std::string description) {
  return ParamSpec::real("damping", "1/s", def, 0.0, max, std::move(description))
      .calibrate(calibLo, 1000, ParamScale::Log);
}
/// "thickness": the shell or membrane thickness (m) of a surface model, 0.01 in [1e-6, max],
/// calibratable in [1e-4, 0.3] (log).
inline ParamSpec thickness(double max, std::string description) {
  return ParamSpec::real("thickness", "m", 0.01, 1e-6, max, std::move(description))
      .calibrate(0.0001, 0.3, ParamScale::Log);
}
/// A classic PBD stiffness coefficient (dimensionless, in [0, 1]), calibratable in [calibLo, 1]
/// (log).
inline ParamSpec unitStiffness(std::string key, double def, double calibLo,
                               std::string description) {
  return ParamSpec::real(std::move(key), "1", def, 0.0, 1.0, std::move(description))
      .calibrate(calibLo, 1, ParamScale::Log);
}
/// "precision": float32 (the default) or float64, the number type of a model's hot loops.
inline ParamSpec precision(std::string description) {
  return ParamSpec::choice("precision", "float32", {"float32", "float64"}, std::move(description));
}
/// "bending_model": isometric (the default) or dihedral.
inline ParamSpec bendingModel(std::string description) {
  return ParamSpec::choice("bending_model", "isometric", {"isometric", "dihedral"},
                           std::move(description));
}
/// "network" (surface, the default, or volume) and "volume_elements" (the target number of tets
/// of the volume network), for a model that runs on the organ's surface or on tets.
inline ParamSpec network(std::string description) {
  return ParamSpec::choice("network", "surface", {"surface", "volume"}, std::move(description));
}
inline ParamSpec volumeElements() {
  return ParamSpec::integer("volume_elements", 4000, 100, 10000000,
                            "network = volume: target number of tets");
}

}  // namespace common_params

/// Why a declaration's calibration fields are inconsistent ("" when they are fine, or when it is
/// not calibratable): only Real parameters, calibMin < calibMax inside [min, max], and bounds > 0
/// on a log scale. The plugin loader refuses a plugin with such a declaration.
std::string calibrationDeclarationProblem(const ParamSpec& spec);

/// Resolved parameter values: every declared key present (scene value or default), already
/// validated. Accessors assert on a key that was not declared (a programmer error).
class ParamValues {
 public:
  ParamValues() = default;
  explicit ParamValues(std::map<std::string, ParamValue> values) : m_values(std::move(values)) {}

  double real(const std::string& key) const;
  long long integer(const std::string& key) const;
  bool flag(const std::string& key) const;
  const std::string& choice(const std::string& key) const;

  /// Maps a Choice value to an enum through a table; throws InputError on a value not in it
  /// (cannot happen after validation unless the table and the declared choices disagree).
  template <class Enum>
  Enum choiceAs(const std::string& key,
                const std::vector<std::pair<std::string, Enum>>& table) const {
    const std::string& v = choice(key);
    for (const auto& [name, e] : table) {
      if (name == v) return e;
    }
    throw InputError("", "params." + key, "unknown choice '" + v + "'");
  }

  bool has(const std::string& key) const { return m_values.count(key) != 0; }
  void set(const std::string& key, ParamValue v) { m_values[key] = std::move(v); }
  const std::map<std::string, ParamValue>& all() const { return m_values; }

  /// Defaults of a declaration list.
  static ParamValues defaults(const std::vector<ParamSpec>& specs);

 private:
  std::map<std::string, ParamValue> m_values;
};

/// "key=value,key=value" of the values that differ from the defaults, for run labels.
std::string formatNonDefault(const ParamValues& values, const std::vector<ParamSpec>& specs);

}  // namespace deform
