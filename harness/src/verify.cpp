// `deformbench verify`: reference_fem against CalculiX on one mesh (verify.h).
#include <deform/engine/scene.h>
#include <deform/geometry/organ_tets.h>
#include <deform/internal/atomic_file.h>
#include <deform/sdk/cache.h>
#include <deform/sdk/error.h>
#include <deform/sdk/mesh.h>
#include <deform_harness/cases.h>
#include <deform_harness/format.h>
#include <deform_harness/metrics.h>
#include <deform_harness/runner.h>
#include <deform_harness/verify.h>

#include <sys/resource.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <functional>
#include <map>
#include <memory>

namespace deform::harness {

namespace fs = std::filesystem;
using ojson = nlohmann::ordered_json;

namespace {

/// The parameters that fix the mesh and the constitutive model: both plugins declare them with
/// the same meaning, so the same values give the same tets: the material, the element order and
/// the organ's tet mesh parameters (organ_tets.h, which both plugins insert).
std::vector<std::string> sharedParams() {
  std::vector<std::string> keys = {"material", "element_order"};
  for (const ParamSpec& p : withOrganTetParams({}, 0)) keys.push_back(p.key);
  return keys;
}

double cpuSecondsNow() {
  double s = 0;
  for (int who : {RUSAGE_SELF, RUSAGE_CHILDREN}) {
    struct rusage u {};
    getrusage(who, &u);
    s += double(u.ru_utime.tv_sec) + 1e-6 * double(u.ru_utime.tv_usec) + double(u.ru_stime.tv_sec) +
         1e-6 * double(u.ru_stime.tv_usec);
  }
  return s;
}

/// One step() of a recorded run: its input, the nodes after it and the grasp forces.
struct RecordedSolve {
  StepInput input;
  MatX3 nodes;
  std::vector<Vec3> graspForces;
};

/// Forwards to a model and records the wall and CPU time of each step() (the CPU time includes
/// the child processes the step waited for: ccx).
class TimedModel final : public Model {
 public:
  explicit TimedModel(Model& m) : m_model(m) {}
  void init(const ModelSetup& setup) override { m_model.init(setup); }
  StepStatus step(const StepInput& in) override {
    const auto t0 = std::chrono::steady_clock::now();
    const double c0 = cpuSecondsNow();
    const StepStatus s = m_model.step(in);
    VerifySolverTimes t;
    t.wallS = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    t.cpuS = cpuSecondsNow() - c0;
    steps.push_back(t);
    if (record) {
      StepInput input = in;
      input.contact = nullptr;
      solves.push_back({std::move(input), m_model.nodes(), m_model.graspForces()});
    }
    return s;
  }
  const MatX3& nodes() const override { return m_model.nodes(); }
  const MatX3& surface() const override { return m_model.surface(); }
  void reset() override { m_model.reset(); }
  Counts counts() const override { return m_model.counts(); }
  PhaseTimes phaseTimes() const override { return m_model.phaseTimes(); }
  NumericCounters numericCounters() const override { return m_model.numericCounters(); }
  std::vector<Vec3> graspForces() const override { return m_model.graspForces(); }

  std::vector<VerifySolverTimes> steps;
  bool record = false;                ///< keep `solves`
  std::vector<RecordedSolve> solves;  ///< with `record`: one per step() call, in order

 private:
  Model& m_model;
};

struct SolverRun {
  RunRecord rec;
  std::vector<VerifySolverTimes> stepTimes;  ///< one per step() call, in order
  /// With `record` (solve()): the nodes at rest and, per step() call, the solve.
  MatX3 rest;
  std::vector<RecordedSolve> solves;
};

/// runModel() with each step timed (wall and CPU).
SolverRun solve(const ModelInfo& info, const ParamValues& params, const Scene& scene,
                const Organ& organ, Cache& cache, const VerifyOptions& options,
                bool record = false) {
  SolverRun out;
  RunRecord& rec = out.rec;
  rec.model = rec.plugin = rec.label = info.name;
  rec.params = paramsToJson(params);
  const std::string why = unsupportedReason(info, scene);
  if (!why.empty()) {
    rec.status = RunStatus::Unsupported;
    rec.message = why;
    return out;
  }
  std::unique_ptr<Model> model;
  try {
    model = info.create();
    const ModelSetup setup{organ, params, cache, scene.dt, scene.gravity};
    const auto t0 = std::chrono::steady_clock::now();
    model->init(setup);
    rec.precomputeS = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  } catch (const UnsupportedError& e) {
    rec.status = RunStatus::Unsupported;
    rec.message = e.what();
    return out;
  } catch (const std::exception& e) {
    rec.status = RunStatus::Failed;
    rec.message = std::string("init: ") + e.what();
    return out;
  }
  TimedModel timed(*model);
  timed.record = record;
  if (record) out.rest = model->nodes();
  try {
    rec.counts = model->counts();
    RunOptions o;
    o.maxSteps = options.maxSteps;
    o.keepSeries = false;
    o.quasiStaticAtComparedInstants = solveOnlyAtComparedInstants(info, params);
    simulate(timed, scene, organ, o, rec);
  } catch (const std::exception& e) {
    rec.status = RunStatus::Failed;
    rec.message = e.what();
  }
  out.stepTimes = timed.steps;
  out.solves = std::move(timed.solves);
  return out;
}

/// The equilibrium check of one compared instant (VerifyEquilibrium): CalculiX's elements at
/// reference_fem's answer. Every node but the fixed ones is prescribed where reference_fem put
/// it (a node constraint each, on top of the instant's grasps), so ccx solves nothing: its
/// reaction at a node is the node's internal force, and the calculix plugin reports minus that
/// net of the node's external force. At a node reference_fem left free that is the residual of
/// its answer under CalculiX's elements; at the held nodes it is the grasp's reaction.
class EquilibriumCheck {
 public:
  EquilibriumCheck(const ModelInfo& ccxInfo, ParamValues params, const Scene& scene,
                   const Organ& organ, Cache& cache, const MatX3& referenceRest)
      : m_info(ccxInfo),
        m_params(std::move(params)),
        m_scene(scene),
        m_organ(organ),
        m_cache(cache) {
    // One increment: the prescribed field is the answer, nothing to converge.
    m_params.set("initial_increment", 1.0);
    m_params.set("max_increment", 1.0);
    try {
      prepare(referenceRest);
    } catch (const std::exception& e) {
      m_problem = std::string("the nodes could not be matched: ") + e.what();
      return;
    }
    // One calculix model for every instant: each step is a ccx run of its own.
    try {
      m_model = m_info.create();
      m_model->init(ModelSetup{m_organ, m_params, m_cache, m_scene.dt, m_scene.gravity});
    } catch (const std::exception& e) {
      m_problem = std::string("calculix failed: ") + e.what();
    }
  }

  /// The check at one of reference_fem's recorded solves.
  VerifyEquilibrium check(int step, double time, const RecordedSolve& solve);

 private:
  /// The nodes as calculix numbers them, the held and fixed ones, and reference_fem's row of
  /// each.
  void prepare(const MatX3& referenceRest) {
    // The nodes as calculix numbers them (organ_tets.h, as the plugin builds them).
    const OrganTets tets = organTets(m_organ, organTetOptions(m_params), m_cache);
    std::function<int(int, int)> edgeNode;
    if (m_params.integer("element_order") == 2) {
      auto q = std::make_shared<QuadraticTetNodes>(addMidsideNodes(tets.mesh));
      m_nodes = q->V;
      edgeNode = [q](int a, int b) { return q->edgeNode(a, b); };
    } else {
      m_nodes = tets.mesh.V;
    }
    m_patch = std::make_unique<GraspedPatchNodes>(m_organ.surface, tets.surfaceNode, m_nodes,
                                                  tetBoundaryNodes(tets.mesh, edgeNode));
    m_weight = m_organ.material.density *
               std::abs(signedVolume(m_organ.surface.V, m_organ.surface.F));  // kg
    m_fixed.assign(size_t(m_nodes.rows()), 0);
    for (int n : fixedNodeIndices(m_nodes, m_organ.fixed, m_organ.surface)) m_fixed[size_t(n)] = 7;
    for (const auto& [n, axes] : rollerNodeAxes(m_nodes, m_organ.fixed)) m_fixed[size_t(n)] |= axes;
    // reference_fem's row of each of these nodes, by rest position (its isolated clamped nodes
    // come before its midside nodes).
    std::map<std::array<long long, 3>, int> at;
    const auto key = [](const MatX3& V, Eigen::Index i) {
      return std::array<long long, 3>{std::llround(V(i, 0) * 1e9), std::llround(V(i, 1) * 1e9),
                                      std::llround(V(i, 2) * 1e9)};
    };
    for (Eigen::Index i = 0; i < referenceRest.rows(); ++i)
      at.emplace(key(referenceRest, i), int(i));
    m_referenceRow.assign(size_t(m_nodes.rows()), -1);
    for (Eigen::Index i = 0; i < m_nodes.rows(); ++i) {
      const auto it = at.find(key(m_nodes, i));
      if (it == at.end() || (referenceRest.row(it->second) - m_nodes.row(i)).norm() > 1e-9) {
        m_problem = "reference_fem's nodes are not calculix's (node " + std::to_string(i) +
                    " has no counterpart)";
        return;
      }
      m_referenceRow[size_t(i)] = it->second;
    }
  }

  const ModelInfo& m_info;
  ParamValues m_params;
  const Scene& m_scene;
  const Organ& m_organ;
  Cache& m_cache;
  MatX3 m_nodes;
  std::unique_ptr<GraspedPatchNodes> m_patch;
  std::vector<int> m_fixed;         ///< per node: the axes a support holds (7: all)
  std::vector<int> m_referenceRow;  ///< per node: its row in reference_fem's nodes
  Real m_weight = 0;                ///< the organ's mass, kg
  std::unique_ptr<Model> m_model;   ///< the calculix model the checks step
  std::string m_problem;            ///< why no check can be made, if so
};

VerifyEquilibrium EquilibriumCheck::check(int step, double time, const RecordedSolve& solve) {
  const std::vector<Vec3>& referenceForces = solve.graspForces;
  VerifyEquilibrium e;
  e.step = step;
  e.time = time;
  if (!m_problem.empty()) {
    e.status = m_problem;
    return e;
  }
  StepInput in = solve.input;
  in.nodeConstraints.clear();
  std::vector<int> constrained;
  for (Eigen::Index n = 0; n < m_nodes.rows(); ++n) {
    if (m_fixed[size_t(n)] == 7) continue;
    NodeGrasp g;
    g.nodes = {int(n)};
    g.targets = solve.nodes.row(m_referenceRow[size_t(n)]);
    in.nodeConstraints.push_back(std::move(g));
    constrained.push_back(int(n));
  }
  std::vector<char> held(size_t(m_nodes.rows()), 0);
  for (const GraspInput& g : in.grasps)
    for (int n : m_patch->nodes(g.vertices)) held[size_t(n)] = 1;
  try {
    TimedModel timed(*m_model);
    const StepStatus status = timed.step(in);
    e.calculix = timed.steps.back();
    if (status != StepStatus::Ok) {
      e.status = "calculix's step did not end ok (non-finite nodes)";
      return e;
    }
  } catch (const std::exception& ex) {
    e.status = std::string("calculix failed: ") + ex.what();
    return e;
  }
  const std::vector<Vec3> forces = m_model->graspForces();
  const size_t grasps = in.grasps.size();
  if (forces.size() != grasps + constrained.size()) {
    e.status = "calculix reported " + std::to_string(forces.size()) + " forces, not " +
               std::to_string(grasps + constrained.size());
    return e;
  }
  // The force scale: the largest of the loads' total, the weight and the grasps' forces.
  double scale = 0;
  for (const PointLoad& l : in.loads) scale += l.force.norm();
  scale = std::max(scale, m_weight * in.gravity.norm());
  for (size_t g = 0; g < grasps; ++g) {
    scale = std::max(scale, forces[g].norm());
    if (g < referenceForces.size()) scale = std::max(scale, referenceForces[g].norm());
  }
  double r2 = 0, rmax = 0;
  for (size_t k = 0; k < constrained.size(); ++k) {
    const int n = constrained[k];
    if (held[size_t(n)]) continue;
    Vec3 r = -forces[grasps + k];
    for (int a = 0; a < 3; ++a)
      if (m_fixed[size_t(n)] & (1 << a)) r(a) = 0;  // a roller's reaction
    r2 += r.squaredNorm();
    rmax = std::max(rmax, r.norm());
    ++e.freeNodes;
  }
  e.forceScale = scale;
  if (!(scale > 0)) {
    e.status = "no load: nothing to compare the residual with";
    return e;
  }
  e.status = "ok";
  e.residualRelative = std::sqrt(r2) / scale;
  e.maxRelative = rmax / scale;
  if (grasps > 0) e.graspForceRelative = 0;
  for (size_t g = 0; g < grasps && g < referenceForces.size(); ++g)
    e.graspForceRelative =
        std::max(e.graspForceRelative, (forces[g] - referenceForces[g]).norm() / scale);
  return e;
}

VerifySolver describe(const SolverRun& run) {
  VerifySolver s;
  s.plugin = run.rec.model;
  s.params = ojson::parse(run.rec.params.dump());
  s.status = statusName(run.rec.status);
  s.message = run.rec.message;
  s.notes = run.rec.notes;
  s.counts = ojson::object();
  for (const auto& [k, v] : run.rec.counts) s.counts[k] = v;
  s.precomputeS = run.rec.precomputeS;
  for (const VerifySolverTimes& t : run.stepTimes) {
    s.total.wallS += t.wallS;
    s.total.cpuS += t.cpuS;
  }
  return s;
}

ojson timesJson(const VerifySolverTimes& t) {
  return {{"wall_s", t.wallS}, {"cpu_s", t.cpuS}};
}

ojson solverJson(const VerifySolver& s) {
  return {{"plugin", s.plugin},
          {"params", s.params},
          {"status", s.status},
          {"message", s.message},
          {"notes", s.notes},
          {"counts", s.counts},
          {"precompute_s", s.precomputeS},
          {"solve", timesJson(s.total)}};
}

}  // namespace

/// The two solvers' parameters: the scene's reference's, the other solver taking the shared
/// ones; reference_fem quasi-static; nearly incompressible, reference_fem compared in C3D10's
/// formulation with the scene's own (`scene`) solved beside it.
struct VerifyParams {
  ParamValues reference, calculix, scene;
  bool meanDilatation = false;  ///< the scene's reference has the mean-dilatation term
  std::vector<std::string> notes;
};

VerifyParams verifyParams(const std::string& sceneFile, const Scene& scene,
                          const ModelInfo& refInfo, const ModelInfo& ccxInfo) {
  VerifyParams out;
  const ModelSpec& spec = *scene.reference;
  std::vector<std::string>& notes = out.notes;
  // The scene's reference parameters; the other solver takes the shared ones.
  nlohmann::json shared = nlohmann::json::object();
  for (const std::string& k : sharedParams())
    if (spec.params.contains(k)) shared[k] = spec.params[k];
  nlohmann::json refGiven = spec.plugin == "reference_fem" ? spec.params : shared;
  const nlohmann::json ccxGiven = spec.plugin == "calculix" ? spec.params : shared;
  if (refGiven.contains("solve") && refGiven["solve"] != "quasi_static") {
    refGiven["solve"] = "quasi_static";
    notes.push_back("reference_fem solved quasi-statically (the scene's reference is dynamic)");
  }
  if (refGiven.contains("material") && refGiven["material"] == "corotational")
    throw InputError(sceneFile, spec.jsonPath + "/params/material",
                     "calculix has no corotational material: verify compares linear or "
                     "neo_hookean");
  // Nearly incompressible: compare C3D10's formulation, and solve the scene's beside it.
  out.scene = resolveParams(refInfo.params, refGiven, sceneFile, spec.jsonPath + "/params");
  out.meanDilatation =
      out.scene.integer("element_order") == 2 && out.scene.choice("material") == "neo_hookean" &&
      (out.scene.choice("volumetric") == "mean_dilatation" ||
       (out.scene.choice("volumetric") == "auto" && scene.organ.material.poisson >= 0.45));
  if (out.meanDilatation) {
    refGiven["volumetric"] = "displacement";
    notes.push_back(
        "nu " + formatG(scene.organ.material.poisson) +
        ": reference_fem compared with volumetric = displacement, CalculiX's C3D10 formulation "
        "(Debian's ccx has no hybrid elements); the scene's mean-dilatation reference was solved "
        "too, and its difference from that run is formulation_rms_relative (not part of the "
        "goal)");
  }
  out.reference = resolveParams(refInfo.params, refGiven, sceneFile, spec.jsonPath + "/params");
  out.calculix = resolveParams(ccxInfo.params, ccxGiven, sceneFile, spec.jsonPath + "/params");
  return out;
}

/// verify.json (format deformbench-verify/1) of a result.
ojson verifyJson(const VerifyResult& result, const Scene& scene, const std::string& sceneFile,
                 bool meanDilatation) {
  ojson doc;
  doc["format"] = "deformbench-verify/1";
  doc["scene"] = {{"name", scene.name}, {"file", sceneFile}};
  doc["goal_rms_relative"] = kVerifyGoal;
  doc["agrees"] = result.agrees;
  doc["message"] = result.message;
  doc["notes"] = result.notes;
  doc["solvers"] = {solverJson(result.reference), solverJson(result.calculix)};
  if (meanDilatation) doc["formulation"] = solverJson(result.formulation);
  doc["instants"] = ojson::array();
  for (const VerifyInstant& in : result.instants)
    doc["instants"].push_back(
        {{"step", in.step},
         {"time_s", in.time},
         {"vertices", in.vertices},
         {"reference_rms_displacement_m", in.referenceRms},
         {"rms_difference_m", in.rmsDifference},
         {"max_difference_m", in.maxDifference},
         {"rms_relative", numberOrNull(in.rmsRelative)},
         {"max_relative", numberOrNull(in.maxRelative)},
         {"formulation_rms_relative", numberOrNull(in.formulationRmsRelative)},
         {"formulation_max_relative", numberOrNull(in.formulationMaxRelative)},
         {"reference_fem", timesJson(in.reference)},
         {"calculix", timesJson(in.calculix)}});
  doc["equilibrium_goal"] = kEquilibriumGoal;
  doc["equilibrium_agrees"] = result.equilibriumAgrees;
  doc["equilibrium"] = ojson::array();
  for (const VerifyEquilibrium& e : result.equilibrium)
    doc["equilibrium"].push_back({{"step", e.step},
                                  {"time_s", e.time},
                                  {"status", e.status},
                                  {"free_nodes", e.freeNodes},
                                  {"force_scale_n", e.forceScale},
                                  {"residual_relative", numberOrNull(e.residualRelative)},
                                  {"max_residual_relative", numberOrNull(e.maxRelative)},
                                  {"grasp_force_relative", numberOrNull(e.graspForceRelative)},
                                  {"calculix", timesJson(e.calculix)}});
  return doc;
}

VerifyResult runVerify(const std::string& sceneFile, PluginLoader& loader,
                       const VerifyOptions& options) {
  VerifyResult result;
  result.sceneFile = sceneFile;
  const Scene scene = parseSceneFile(sceneFile);
  result.sceneName = scene.name;
  if (!scene.reference)
    throw InputError(sceneFile, "/reference", "verify needs a scene with a reference");
  const ModelSpec& spec = *scene.reference;
  if (spec.plugin != "reference_fem" && spec.plugin != "calculix")
    throw InputError(sceneFile, spec.jsonPath + "/plugin",
                     "verify compares reference_fem and calculix; the reference is " + spec.plugin);
  const ModelInfo& refInfo = loader.load("reference_fem");
  const ModelInfo& ccxInfo = loader.load("calculix");
  const VerifyParams params = verifyParams(sceneFile, scene, refInfo, ccxInfo);
  const bool meanDilatation = params.meanDilatation;
  std::vector<std::string> notes = params.notes;

  const Organ organ = loadOrgan(scene);
  std::error_code ec;
  fs::create_directories(options.outDir, ec);
  if (ec || !fs::is_directory(options.outDir))
    throw InputError(options.outDir.string(), "", "cannot create the output folder");
  Cache cache(options.cacheDir ? *options.cacheDir : Cache::defaultDir());

  // A scene calculix cannot run (contact: probes, instruments, objects) is not solved at all.
  SolverRun ref, ccx;
  if (const std::string why = unsupportedReason(ccxInfo, scene); !why.empty()) {
    ccx.rec.model = ccxInfo.name;
    ccx.rec.status = RunStatus::Unsupported;
    ccx.rec.message = why;
    ref.rec.model = refInfo.name;
    ref.rec.status = RunStatus::Unsupported;
    ref.rec.message = "not run: calculix cannot run this scene";
  } else {
    // reference_fem first: it meshes (or finds the mesh in the cache); calculix reads the same.
    ref = solve(refInfo, params.reference, scene, organ, cache, options, true);
    if (options.equilibriumOnly) {
      ccx.rec.model = ccxInfo.name;
      ccx.rec.status = RunStatus::Unsupported;
      ccx.rec.message = "its own solve not run (--equilibrium-only)";
    } else {
      ccx = solve(ccxInfo, params.calculix, scene, organ, cache, options);
    }
  }
  SolverRun formulation;
  formulation.rec.model = refInfo.name;
  formulation.rec.status = RunStatus::Unsupported;
  formulation.rec.message = "not run: the compared run is the scene's formulation";
  if (meanDilatation && ref.rec.status == RunStatus::Ok)
    formulation = solve(refInfo, params.scene, scene, organ, cache, options);
  result.reference = describe(ref);
  result.calculix = describe(ccx);
  result.formulation = describe(formulation);

  const int n =
      options.maxSteps >= 0 ? std::min(options.maxSteps, scene.numSteps()) : scene.numSteps();
  const std::vector<int> solveSteps = quasiStaticSolveSteps(scene, n);
  const auto timesAt = [&](const SolverRun& r, int step) {
    const auto it = std::find(solveSteps.begin(), solveSteps.end(), step);
    const size_t i = size_t(it - solveSteps.begin());
    return it != solveSteps.end() && i < r.stepTimes.size() ? r.stepTimes[i] : VerifySolverTimes{};
  };
  // The equilibrium check at each of reference_fem's compared instants, whether or not ccx's
  // own solve got there.
  if (ref.rec.status == RunStatus::Ok && !ref.rec.compared.empty()) {
    EquilibriumCheck check(ccxInfo, params.calculix, scene, organ, cache, ref.rest);
    result.equilibriumAgrees = true;
    for (const SurfaceSnapshot& a : ref.rec.compared) {
      const auto it = std::find(solveSteps.begin(), solveSteps.end(), a.step);
      const size_t i = size_t(it - solveSteps.begin());
      VerifyEquilibrium e;
      if (it != solveSteps.end() && i < ref.solves.size()) {
        e = check.check(a.step, a.time, ref.solves[i]);
      } else {
        e.step = a.step;
        e.time = a.time;
        e.status = "reference_fem's solve of this instant was not recorded";
      }
      result.equilibriumAgrees =
          result.equilibriumAgrees && e.status == "ok" && e.residualRelative <= kEquilibriumGoal;
      result.equilibrium.push_back(e);
    }
  }
  if (options.equilibriumOnly && ref.rec.status == RunStatus::Ok) {
    notes.push_back(
        "CalculiX's own solve skipped (--equilibrium-only): the equilibrium check only");
  } else if (ref.rec.status != RunStatus::Ok || ccx.rec.status != RunStatus::Ok) {
    result.message = "no comparison: reference_fem " + result.reference.status +
                     (ref.rec.message.empty() ? "" : " (" + ref.rec.message + ")") + ", calculix " +
                     result.calculix.status +
                     (ccx.rec.message.empty() ? "" : " (" + ccx.rec.message + ")");
  } else if (ref.rec.compared.size() != ccx.rec.compared.size()) {
    result.message = "no comparison: the solvers reached different compared instants";
  } else {
    if (ref.rec.counts.at("nodes") != ccx.rec.counts.at("nodes") ||
        ref.rec.counts.at("elements") != ccx.rec.counts.at("elements"))
      notes.push_back(
          "the solvers' meshes differ in size (nodes, elements): the comparison "
          "includes the mesh difference");
    const MatX3& rest = organ.surface.V;
    const std::vector<int> held = graspedSurfaceVertices(scene, rest);
    std::vector<int> compared;
    for (int v = 0; v < int(rest.rows()); ++v)
      if (!std::binary_search(held.begin(), held.end(), v)) compared.push_back(v);
    result.agrees = true;
    for (size_t i = 0; i < ref.rec.compared.size(); ++i) {
      const SurfaceSnapshot& a = ref.rec.compared[i];
      const SurfaceSnapshot& b = ccx.rec.compared[i];
      VerifyInstant in;
      in.step = a.step;
      in.time = a.time;
      in.vertices = int(compared.size());
      double u2 = 0, d2 = 0, dmax = 0;
      for (int v : compared) {
        u2 += (a.positions.row(v) - rest.row(v)).squaredNorm();
        const double d = (a.positions.row(v) - b.positions.row(v)).norm();
        d2 += d * d;
        dmax = std::max(dmax, d);
      }
      const double m = std::max<double>(1.0, double(compared.size()));
      in.referenceRms = std::sqrt(u2 / m);
      in.rmsDifference = std::sqrt(d2 / m);
      in.maxDifference = dmax;
      in.rmsRelative = in.referenceRms > 0 ? in.rmsDifference / in.referenceRms : NAN;
      in.maxRelative = in.referenceRms > 0 ? in.maxDifference / in.referenceRms : NAN;
      in.reference = timesAt(ref, a.step);
      in.calculix = timesAt(ccx, b.step);
      if (formulation.rec.status == RunStatus::Ok && i < formulation.rec.compared.size()) {
        const MatX3& f = formulation.rec.compared[i].positions;
        double f2 = 0, fmax = 0;
        for (int v : compared) {
          const double d = (f.row(v) - a.positions.row(v)).norm();
          f2 += d * d;
          fmax = std::max(fmax, d);
        }
        if (in.referenceRms > 0) {
          in.formulationRmsRelative = std::sqrt(f2 / m) / in.referenceRms;
          in.formulationMaxRelative = fmax / in.referenceRms;
        }
      }
      result.agrees = result.agrees && in.rmsRelative <= kVerifyGoal;
      result.instants.push_back(in);
    }
    if (result.instants.empty()) {
      result.agrees = false;
      result.message = "no comparison: no compared instant";
    }
  }

  result.notes = notes;
  const ojson doc = verifyJson(result, scene, sceneFile, meanDilatation);
  result.jsonPath = options.outDir / "verify.json";
  writeFileAtomic(result.jsonPath, doc.dump(2) + "\n");
  return result;
}

}  // namespace deform::harness
