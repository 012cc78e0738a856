// deformbench SDK: the names of an enum's values as one table that serves both ways (the name of
// a value, the value of a name), instead of a switch per direction.
#pragma once

#include <cstddef>
#include <string>

namespace deform {

template <class Enum>
struct EnumName {
  Enum value;
  const char* name;
};

/// The name of `value` in `table`, or `unknown` when the table does not list it.
template <class Enum, std::size_t N>
const char* enumName(const EnumName<Enum> (&table)[N], Enum value, const char* unknown) {
  for (const EnumName<Enum>& e : table)
    if (e.value == value) return e.name;
  return unknown;
}

/// The value named `name` in `table` into `out`; false (out untouched) when none is.
template <class Enum, std::size_t N>
bool enumFromName(const EnumName<Enum> (&table)[N], const std::string& name, Enum& out) {
  for (const EnumName<Enum>& e : table)
    if (name == e.name) {
      out = e.value;
      return true;
    }
  return false;
}

}  // namespace deform
