// deformbench SDK: scene files (JSON, SI units; see docs/scene-format.md). Parsing is strict:
// an unknown key, a wrong type or an out-of-range value is an InputError naming the file and the
// JSON path (e.g. "scenes/x.json: /models/0/params/iterations: must be >= 1, got 0").
#pragma once

#include <deform/engine/instruments.h>
#include <deform/sdk/contact.h>
#include <deform/sdk/model.h>
#include <deform/sdk/params.h>

#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

namespace deform {

struct KeyFrame {
  Real t = 0;               ///< s
  Vec3 pos = Vec3::Zero();  ///< m
  bool jawClosed = false;   ///< grasper jaws ("open" | "closed"); held until the next frame
};

enum class ToolType { Grasper, Probe };

/// "dynamics": the tool is a rigid body (ODE) driven towards its trajectory by a virtual
/// coupling (deform/engine/instruments.h) instead of following it exactly.
struct ToolDynamics {
  Real mass = 0.05;        ///< kg (a grasper's shaft; each jaw adds a tenth)
  Real jawLength = 0.015;  ///< m, grasper jaws
  Real shaftLength = 0.3;  ///< m, grasper shaft (inertia only)
  CouplingParams coupling;
};

struct ToolSpec {
  ToolType type = ToolType::Grasper;
  Real radius = 0.005;               ///< m: grasp radius (grasper) or tip radius (probe)
  std::vector<KeyFrame> trajectory;  ///< times strictly increasing
  /// Probe shaft (a cylinder with rounded end, from the tip centre along shaftAxis), m.
  Real shaftLength = 0.1;
  Real shaftRadius = 0;  ///< 0: the tip radius
  Vec3 shaftAxis = Vec3::UnitZ();
  std::optional<ToolDynamics> dynamics;
};

/// A rigid object (ODE body under gravity) that collides with the organ: it rests on it, or is
/// pushed into it when it has a trajectory (then it is driven by a virtual coupling).
struct ObjectSpec {
  RigidShape shape;                  ///< one sphere or one box, centred at the body origin
  std::string shapeName;             ///< "sphere" | "box"
  Real mass = 0.01;                  ///< kg
  Vec3 pos = Vec3::Zero();           ///< m, initial centre
  std::vector<KeyFrame> trajectory;  ///< empty: free
  CouplingParams coupling;
};

enum class LoadType { PointForce, PinHead, Traction };

/// point_force: constant `force` at the surface vertex nearest `at`, between start and end.
/// pin_head: f = k (x(t) - x0) at the vertex nearest `at`, where x(t) is the keyframed pin
/// position and x0 = `at` (hybrid paper's experiments).
/// Either acts as a traction over the surface patch of `radius` around that vertex, spread by
/// the harness (interaction.h, pressurePatch), the same for every model.
/// traction: the constant total `force` spread as a uniform traction over the organ's surface
/// triangles inside `region` (interaction.h, regionPatch: consistent area weights); `at` is the
/// region's centre.
struct LoadSpec {
  LoadType type = LoadType::PointForce;
  Vec3 at = Vec3::Zero();
  Vec3 force = Vec3::Zero();   ///< N (point_force)
  Real stiffness = 0;          ///< N/m (pin_head)
  std::vector<KeyFrame> path;  ///< pin positions (pin_head)
  Real radius = 0.01;          ///< m, the pressure patch ("radius", default 1 cm)
  Box region;                  ///< traction: the surface triangles inside this box are loaded
  Real start = 0, end = 1e30;  ///< s
};

struct ModelSpec {
  std::string plugin;  ///< plugin file name (deform_<plugin>.so)
  std::string model;   ///< model within the plugin (default: plugin)
  std::string label;   ///< optional; default "model(nondefault params)"
  nlohmann::json params = nlohmann::json::object();
  std::string jsonPath;  ///< where this spec sits in the scene, for error messages
};

struct OrganSpec {
  std::string mesh;       ///< "phantom:NAME" or a path (resolved relative to the scene file)
  Real scale = 1.0;       ///< mesh units -> metres
  Real resolution = 1.0;  ///< phantoms only
  bool repair = false;
  Material material;
  FixedRegion fixed;
};

/// "plates": a rigid plate bonded to the organ surface vertices inside `region` (picked by the
/// harness on the rest surface, the same set for every model), which it moves by a prescribed
/// rigid offset: those vertices' targets are rest + offset(t) (piecewise linear between frames,
/// held before the first and after the last). The harness hands each plate to the models as a
/// grasp (GraspInput::tool = number of tools + plate index), so every model follows it through
/// its surface mapping and the reference solvers take it as Dirichlet conditions.
/// A sliding plate prescribes only the normal displacement (GraspInput::slideNormal); its normal
/// is "normal" or the direction of the trajectory's largest offset, a coordinate axis for now.
enum class PlateContact { Bonded, Sliding };
struct PlateSpec {
  Box region;
  PlateContact contact = PlateContact::Bonded;
  Vec3 normal = Vec3::Zero();        ///< sliding: unit, along an axis; bonded: zero
  std::vector<KeyFrame> trajectory;  ///< pos = the offset, m; times increasing
};

/// "markers": interior points (rest positions, m) whose current positions every model reports
/// through its own interior mapping (Model::bindMarkers), with optional measured positions at
/// compared instants (then results.json gets their errors).
struct MarkerFrame {
  Real t = 0;  ///< s, one of the compared instants
  /// "t": "equilibrium": the one compared instant of a scene compared at equilibrium (t unused).
  bool atEquilibrium = false;
  MatX3 points;  ///< #markers by 3, m
};
struct MarkerSpec {
  MatX3 points;                       ///< #markers by 3, m; empty: no markers
  std::vector<MarkerFrame> measured;  ///< in time order
};

enum class SurfaceOutput { Final, Every, None };

struct Scene {
  std::string name;
  std::string file;    ///< path of the scene file ("" when parsed from memory)
  std::string sha256;  ///< of the file's bytes
  OrganSpec organ;
  Vec3 gravity = Vec3(0, 0, -9.81);
  Real dt = 1e-3;
  Real duration = 1.0;
  std::vector<ToolSpec> tools;
  std::vector<ObjectSpec> objects;
  ContactParams contact;  ///< "contact": the same for every model
  std::vector<LoadSpec> loads;
  std::vector<PlateSpec> plates;
  MarkerSpec markers;
  std::vector<ModelSpec> models;
  std::optional<ModelSpec> reference;
  std::vector<int> nearest = {10, 50};
  std::vector<Real> compareAt;  ///< empty: the end of the run
  /// "compare_at": "equilibrium": each dynamic model runs until it settles (its largest
  /// surface-vertex speed stays below settleSpeed for settleSteps steps, once the interaction
  /// has stopped changing; the duration is the cap) and is compared then, against the
  /// quasi-static reference at the end of the run.
  bool compareAtEquilibrium = false;
  Real settleSpeed = 1e-4;  ///< m/s
  int settleSteps = 20;
  SurfaceOutput surfaces = SurfaceOutput::Final;
  int surfaceEvery = 0;  ///< for SurfaceOutput::Every

  int numSteps() const;  ///< round(duration / dt)
  /// A probe or an object: models need the "contact" capability and the run a Bullet world.
  bool needsContact() const;
  /// A tool with "dynamics" or an object: the run needs an ODE world.
  bool needsDynamics() const;
};

/// Parses and validates a scene file. Throws InputError.
Scene parseSceneFile(const std::string& path);
/// Same from a JSON value; `file` names it in errors and resolves relative mesh paths.
Scene parseScene(const nlohmann::json& j, const std::string& file);

/// Validates a model's params object against its declaration; fills defaults. jsonPath is the
/// params object's path in the scene (e.g. "/models/0/params"). Throws InputError.
ParamValues resolveParams(const std::vector<ParamSpec>& specs, const nlohmann::json& given,
                          const std::string& file, const std::string& jsonPath);

/// Loads the organ: phantom or file, scaled to metres, validated (or repaired when the scene
/// asks; each change is appended to repairLog). Throws InputError naming the mesh file.
/// Also checks every grasp and load against the loaded organ (checkGraspsReachOrgan,
/// checkLoadsReachOrgan).
Organ loadOrgan(const Scene& scene, std::vector<std::string>* repairLog = nullptr);

/// Throws InputError(scene.file, "/tools/I/trajectory/K/pos", ...) when a grasper's jaws close
/// (a "closed" keyframe after an "open" one, or the first keyframe) at a point outside the
/// organ farther than the tool's radius from its surface: that grasp would attach nothing.
/// Closing inside the organ is allowed (volumetric models grasp interior nodes).
void checkGraspsReachOrgan(const Scene& scene, const Organ& organ);

/// Throws InputError(scene.file, "/plates/I/region/box", ...) when a plate's box holds no
/// surface vertex of the organ (it would hold nothing). Called by loadOrgan().
void checkPlatesReachOrgan(const Scene& scene, const Organ& organ);

/// Throws InputError(scene.file, "/loads/I/at", ...) when a load's point lies farther than its
/// patch radius from the organ's surface (outside or inside): the harness would apply it at the
/// nearest surface vertex, somewhere the scene did not say. Called by loadOrgan().
void checkLoadsReachOrgan(const Scene& scene, const Organ& organ);

/// Stability of a virtual coupling F = k (x_hand - x) + c (v_hand - v) on a body of mass m
/// under ODE's dWorldStep, a semi-implicit (symplectic) Euler step with the coupling force taken
/// at the start of the step: v' = v + dt F(x, v) / m, x' = x + dt v'. On x'' = -(k x + c x') / m
/// with a = k dt^2 / m and b = c dt / m one step maps (x, dt v) by [[1 - a, 1 - b], [-a, 1 - b]]
/// (trace 2 - a - b, determinant 1 - b); by the Schur-Cohn (Jury) conditions both eigenvalues
/// lie inside the unit circle iff 0 < b < 2, a > 0 and a + 2 b < 4. Without damping this is the
/// familiar omega dt < 2 of symplectic Euler (Hairer, Lubich, Wanner, Geometric Numerical
/// Integration, 2nd ed., Springer 2006, ch. I.1 and I.5); damping taken explicitly narrows it.
/// couplingStabilityNumber() is a + 2 b; at or above kCouplingStabilityLimit the body's motion
/// grows every step whatever touches it.
constexpr Real kCouplingStabilityLimit = 4.0;
Real couplingStabilityNumber(const CouplingParams& coupling, Real mass, Real dt);

/// Throws InputError(scene.file, "/tools/I/dynamics" or "/objects/J", ...) naming k, c, m, dt
/// and the number when a dynamic tool's or a driven object's coupling is unstable at the
/// scene's dt (couplingStabilityNumber() >= 4). Called by parseScene().
void checkCouplingStability(const Scene& scene);

/// JSON of resolved parameter values (for results.json).
nlohmann::json paramsToJson(const ParamValues& values);
/// JSON description of a parameter declaration (for `deformbench plugins --json`).
nlohmann::json paramSpecToJson(const ParamSpec& spec);

}  // namespace deform
