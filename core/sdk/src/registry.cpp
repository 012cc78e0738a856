#include <deform/sdk/registry.h>

#include <deform/sdk/enum_names.h>

#include <cassert>
#include <cmath>
#include <set>
#include <stdexcept>

namespace deform {

namespace {

// Every capability with its name (capabilities are only ever appended, registry.h: so is this).
constexpr EnumName<Capability> kCapabilityNames[] = {
    {Capability::Grasp, "grasp"},
    {Capability::PointForce, "point_force"},
    {Capability::Gravity, "gravity"},
    {Capability::Cut, "cut"},
    {Capability::ReactionForce, "reaction_force"},
    {Capability::NeedsPrecompute, "needs_precompute"},
    {Capability::TetInput, "tet_input"},
    {Capability::QuasiStatic, "quasi_static"},
    {Capability::Contact, "contact"},
    {Capability::ContactReaction, "contact_reaction"},
    {Capability::RollerSupport, "roller_support"},
    {Capability::Markers, "markers"},
    {Capability::Sliding, "sliding"},
};

}  // namespace

const char* capabilityName(Capability c) {
  const char* name = enumName(kCapabilityNames, c, nullptr);
  assert(name && "unknown Capability");
  return name ? name : "unknown";
}

bool capabilityFromName(const std::string& name, Capability& out) {
  return enumFromName(kCapabilityNames, name, out);
}

bool ModelInfo::has(Capability c) const {
  for (Capability k : capabilities) {
    if (k == c) return true;
  }
  return false;
}

const ParamSpec* ModelInfo::param(const std::string& key) const {
  for (const ParamSpec& p : params) {
    if (p.key == key) return &p;
  }
  return nullptr;
}

namespace {

// A declaration the harness could not validate scenes against is the plugin author's mistake;
// it is reported (as std::logic_error, which the loader turns into an init failure) when the
// model is registered rather than when a scene first touches the parameter.
void checkSpec(const std::string& model, const ParamSpec& p) {
  auto fail = [&](const std::string& what) {
    throw std::logic_error("model '" + model + "': parameter '" + p.key + "': " + what);
  };
  if (p.key.empty()) fail("empty key");
  switch (p.type) {
    case ParamType::Real: {
      if (!std::holds_alternative<double>(p.defaultValue)) fail("default is not a real number");
      const double d = std::get<double>(p.defaultValue);
      if (std::isnan(p.min) || std::isnan(p.max) || p.min > p.max) fail("invalid range");
      if (!(d >= p.min && d <= p.max)) fail("default outside its range");
      break;
    }
    case ParamType::Int: {
      if (!std::holds_alternative<long long>(p.defaultValue)) fail("default is not an integer");
      const double d = double(std::get<long long>(p.defaultValue));
      if (std::isnan(p.min) || std::isnan(p.max) || p.min > p.max) fail("invalid range");
      if (!(d >= p.min && d <= p.max)) fail("default outside its range");
      break;
    }
    case ParamType::Bool:
      if (!std::holds_alternative<bool>(p.defaultValue)) fail("default is not a boolean");
      break;
    case ParamType::Choice: {
      if (!std::holds_alternative<std::string>(p.defaultValue)) fail("default is not a string");
      if (p.choices.empty()) fail("no choices declared");
      const std::string& d = std::get<std::string>(p.defaultValue);
      bool found = false;
      for (const std::string& c : p.choices) found = found || c == d;
      if (!found) fail("default '" + d + "' is not one of its choices");
      break;
    }
  }
}

}  // namespace

void Registry::add(ModelInfo info) {
  if (info.name.empty()) throw std::logic_error("Registry::add: model without a name");
  if (!info.create) throw std::logic_error("model '" + info.name + "': no create function");
  std::set<std::string> keys;
  for (const ParamSpec& p : info.params) {
    checkSpec(info.name, p);
    if (!keys.insert(p.key).second) {
      throw std::logic_error("model '" + info.name + "': parameter '" + p.key + "' declared twice");
    }
  }
  const bool duplicate = find(info.name) != nullptr;
  assert(!duplicate && "Registry::add: duplicate model name");
  if (duplicate) throw std::logic_error("model '" + info.name + "' registered twice");
  m_models.push_back(std::move(info));
}

const ModelInfo* Registry::find(const std::string& name) const {
  for (const ModelInfo& m : m_models) {
    if (m.name == name) return &m;
  }
  return nullptr;
}

}  // namespace deform
