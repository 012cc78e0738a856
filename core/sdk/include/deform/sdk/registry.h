// deformbench SDK: plugin registration. A plugin is a shared object exporting two C symbols:
//
//   extern "C" int  deform_abi_version();               // must equal DEFORM_ABI_VERSION
//   extern "C" void deform_register(deform::Registry&); // registers one or more model factories
//
// Use the DEFORM_PLUGIN macro below to define both. Registration is explicit, in one place; no
// static self-registration.
//
// Besides the model itself, a registration may declare what the harness's fixed case sets need
// to know about it (ModelInfo::knob, ::presets) and measures that need more than a model run
// (ModelInfo::measures), so that the harness never names a plugin in code.
#pragma once

#include <deform/sdk/model.h>
#include <deform/sdk/params.h>

#include <nlohmann/json.hpp>

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

/// Bumped whenever model.h, registry.h or anything they include changes layout.
// 2: StepInput::contact (rigid instruments, deform/sdk/contact.h) and Capability::Contact.
// Capability::ContactReaction was appended to the enum without a bump: no layout changed, the
// existing enumerators keep their values, and a plugin built before it simply never declares it
// (the harness then reports it unsupported on scenes with rigid objects, as for any capability
// it lacks). Append new capabilities at the end; never reorder or renumber them.
// 3: interaction on the surface (issue G1): GraspInput holds organ surface vertices, PointLoad
// carries the harness's per-surface-vertex spread.
// 4: ParamSpec gains the calibration fields (calibratable, bounds, scale; issue G2), appended
// after the existing ones, and ModelInfo gains knob, presets and measures (issue G6): plugin
// sources compile unchanged, binaries must be rebuilt.
// 5: the contact responses of deform/sdk/contact.h become one proxy description (ContactProxy) and
// two calls, respondToContact() and solveWithContactConstraints(), in place of ten functions
// (issue G6): plugins with the contact capability port their calls.
// 6: FixedRegion gains `rollers` (roller supports: boxes holding some axes only) and Capability
// gains RollerSupport (issue 33): plugin sources compile unchanged, binaries must be rebuilt.
// 7: Model gains bindMarkers() and markers() (interior markers, issue 34) and Capability gains
// Markers: the vtable changed, binaries must be rebuilt; plugin sources compile unchanged.
// 8: ModelInfo gains `resolution` and `effort`, the two cost axes of `deformbench sweep` (issue
// H4), appended after `measures`: plugin sources compile unchanged, binaries must be rebuilt.
// 9: GraspInput and NodeGrasp gain `slideNormal` (sliding plates, issue 34: only the normal
// displacement prescribed) and Capability gains Sliding: plugin sources compile unchanged,
// binaries must be rebuilt.
#define DEFORM_ABI_VERSION 9

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
  /// "roller_support": honours FixedRegion::rollers (boxes holding some axes only); required by
  /// scenes with a fixed region that has "axes".
  RollerSupport,
  /// "markers": implements Model::bindMarkers() / markers() (interior points through the
  /// model's own interior mapping). Without it a scene's markers are reported unsupported for
  /// the model (its run goes on).
  Markers,
  /// "sliding": honours GraspInput::slideNormal (a sliding plate: only the held vertices'
  /// normal displacement prescribed, the tangential free). Scenes with a sliding plate are
  /// reported unsupported for models without it (never held bonded in silence).
  Sliding,
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

  /// A parameter that trades accuracy for run time, and the values `deformbench sweep` runs
  /// (quickValues with --quick), in the order of increasing cost. An empty param: none.
  struct Knob {
    std::string param;
    std::vector<ParamValue> values, quickValues;
  };
  Knob knob;
  /// Parameter sets the harness's fixed case sets run the model with, by name; each is a list
  /// (one run per set). Absent: the set does not include the model (bench) or uses the
  /// defaults (stability). Names in use:
  ///   "bench"                 deformbench bench: the ~2.2k-vertex liver grasp and the cube poke
  ///   "bench_8k"              deformbench bench: the 8k-vertex liver of the default scene
  ///   "stability", "stability_quick"  deformbench stability (without and with --quick)
  /// (The stability sweep's reference is reference_fem at its defaults, quadratic tets: no preset
  /// names or changes it.)
  using ParamSet = std::map<std::string, ParamValue>;
  std::map<std::string, std::vector<ParamSet>> presets;
  /// Optional measures that need more than a model run (a table column from the method's own
  /// numerics, without a scene), by name: request and reply are JSON documents the measure
  /// documents; bad requests throw InputError. Example: particle_bem's "static_accuracy".
  std::map<std::string, std::function<nlohmann::json(const nlohmann::json& request)>> measures;
  /// The two cost axes of `deformbench sweep`, which runs their grid (each resolution value with
  /// each effort value): `resolution`, the parameter that sets the model's discretisation (tets,
  /// hexahedra, spheres, coarse vertices; none for a model on the organ's own surface mesh), and
  /// `effort`, its solver's work per step (iterations, substeps, a tolerance). A model that
  /// declares neither is swept over `knob` (the single axis of plugins older than ABI 8).
  Knob resolution, effort;

  bool has(Capability c) const;
  const ParamSpec* param(const std::string& key) const;
};

/// The fields every plugin's ModelInfo sets: name, description, citation, version "1.0",
/// capabilities, parameter declarations and create(), the model's factory (for a model class
/// its plugin keeps in one source file). The plugin adds knob, presets, measures, resolution and
/// effort itself.
inline ModelInfo modelInfo(std::string name, std::string description, std::string citation,
                           std::vector<Capability> capabilities, std::vector<ParamSpec> params,
                           std::function<std::unique_ptr<Model>()> create) {
  ModelInfo info;
  info.name = std::move(name);
  info.description = std::move(description);
  info.citation = std::move(citation);
  info.version = "1.0";
  info.capabilities = std::move(capabilities);
  info.params = std::move(params);
  info.create = std::move(create);
  return info;
}

/// The same with create() default-constructing ModelT.
template <class ModelT>
ModelInfo modelInfo(std::string name, std::string description, std::string citation,
                    std::vector<Capability> capabilities, std::vector<ParamSpec> params) {
  return modelInfo(std::move(name), std::move(description), std::move(citation),
                   std::move(capabilities), std::move(params),
                   [] { return std::make_unique<ModelT>(); });
}

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
///
/// A plugin's plugin.cpp (its parameters, config and registration) may also be compiled into the
/// static library its tests link, so that they reach the parameters and the config: that library
/// defines DEFORM_PLUGIN_STATIC, and the registration there is an unused internal function (no
/// entry point, so that a program linking several such libraries has no clash).
#ifdef DEFORM_PLUGIN_STATIC
#define DEFORM_PLUGIN(registryName) \
  [[maybe_unused]] static void deformRegisterUnused(deform::Registry& registryName)
#else
#define DEFORM_PLUGIN(registryName)               \
  DEFORM_PLUGIN_EXPORT int deform_abi_version() { \
    return DEFORM_ABI_VERSION;                    \
  }                                               \
  DEFORM_PLUGIN_EXPORT void deform_register(deform::Registry& registryName)
#endif
