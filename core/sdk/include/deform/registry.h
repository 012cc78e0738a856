// deformbench SDK: plugin registration. A plugin is a shared object exporting two C symbols:
//
//   extern "C" int  deform_abi_version();               // must equal DEFORM_ABI_VERSION
//   extern "C" void deform_register(deform::Registry&); // registers one or more model factories
//
// Use the DEFORM_PLUGIN macro below to define both. Registration is explicit, in one place; no
// static self-registration.
//
// A plugin may export further, optional C symbols for a table that needs more than a model run;
// the harness looks them up with dlsym and does without them when absent (blank columns and a
// note). The one in use: particle_bem's
//   extern "C" const char* deform_particle_bem_static_accuracy(const char* requestJson);
// (the BEM loss ratio of the paper's Table 2 without a model run; request and reply are JSON,
// the reply string is owned by the plugin: see plugins/particle_bem/README.md).
#pragma once

#include <deform/model.h>
#include <deform/params.h>

#include <functional>
#include <memory>
#include <string>
#include <vector>

/// Bumped whenever model.h, registry.h or anything they include changes layout.
// 2: StepInput::contact (rigid instruments, deform/contact.h) and Capability::Contact.
// Capability::ContactReaction was appended to the enum without a bump: no layout changed, the
// existing enumerators keep their values, and a plugin built before it simply never declares it
// (the harness then reports it unsupported on scenes with rigid objects, as for any capability
// it lacks). Append new capabilities at the end; never reorder or renumber them.
// 3: interaction on the surface (issue G1): GraspInput holds organ surface vertices, PointLoad
// carries the harness's per-surface-vertex spread.
#define DEFORM_ABI_VERSION 3

namespace deform {

enum class Capability {
  Grasp,            ///< "grasp": honours GraspInput
  PointForce,       ///< "point_force": honours PointLoad
  Gravity,          ///< "gravity": honours StepInput::gravity
  Cut,              ///< "cut": implements cut()
  ReactionForce,    ///< "reaction_force": implements graspForces()
  NeedsPrecompute,  ///< "needs_precompute": init() does expensive, cached work
  TetInput,         ///< "tet_input": uses Organ::volume when present
  QuasiStatic,      ///< "quasi_static": each step is an equilibrium solve (no inertia)
  Contact,          ///< "contact": keeps its proxy out of StepInput::contact's instruments
  /// "contact_reaction": the whole force its contact response exerts on the instruments is
  /// reported to StepInput::contact (ContactWorld::addReaction), so a free rigid object rests on
  /// the organ and a probe feels the tissue. Required by scenes with rigid objects.
  ContactReaction,
};

/// The capability named `name` (the spelling capabilityName() gives); false when unknown.
bool capabilityFromName(const std::string& name, Capability& out);

/// Name used in scene files, `deformbench plugins` and results.json ("point_force", ...).
const char* capabilityName(Capability c);

struct ModelInfo {
  std::string name;         ///< as named in scenes ("pbd")
  std::string description;  ///< one line
  std::string citation;     ///< paper (+ DOI where one exists)
  std::string version;      ///< plugin version, e.g. "1.0"
  std::vector<Capability> capabilities;
  std::vector<ParamSpec> params;
  std::function<std::unique_ptr<Model>()> create;

  bool has(Capability c) const;
  const ParamSpec* param(const std::string& key) const;
};

class Registry {
 public:
  /// Adds a model; asserts on a duplicate name within one registry.
  void add(ModelInfo info);
  const std::vector<ModelInfo>& models() const { return m_models; }
  const ModelInfo* find(const std::string& name) const;

 private:
  std::vector<ModelInfo> m_models;
};

}  // namespace deform

#define DEFORM_PLUGIN_EXPORT extern "C" __attribute__((visibility("default")))

/// Defines the two exported symbols. Usage: DEFORM_PLUGIN(registry) { registry.add({...}); }
#define DEFORM_PLUGIN(registryName)               \
  DEFORM_PLUGIN_EXPORT int deform_abi_version() { \
    return DEFORM_ABI_VERSION;                    \
  }                                               \
  DEFORM_PLUGIN_EXPORT void deform_register(deform::Registry& registryName)
