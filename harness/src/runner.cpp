// The runner: one model through one scene, the step loop with its timing and divergence checks,
// and the validity of the run. Planning a scene's runs: run_plan.cpp; the solve cache:
// solve_cache.cpp; the `deformbench run` pipeline around them: pipeline.cpp.
#include <deform/engine/interaction.h>
#include <deform/internal/atomic_file.h>
#include <deform/sdk/contact.h>
#include <deform/sdk/enum_names.h>
#include <deform_harness/results.h>
#include <deform_harness/run_isolation.h>
#include <deform_harness/runner.h>
#include <deform_harness/stability.h>

#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <iomanip>
#include <iterator>
#include <memory>
#include <set>
#include <sstream>
#include <variant>

namespace deform::harness {

namespace fs = std::filesystem;

const char* statusName(RunStatus s) {
  static constexpr EnumName<RunStatus> kNames[] = {{RunStatus::Ok, "ok"},
                                                   {RunStatus::Diverged, "diverged"},
                                                   {RunStatus::Unsupported, "unsupported"},
                                                   {RunStatus::Failed, "failed"}};
  return enumName(kNames, s, "failed");
}

void forceSingleThreadedNumerics() {
  for (const char* var : {"OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS",
                          "GOTO_NUM_THREADS", "BLIS_NUM_THREADS"})
    setenv(var, "1", 1);
  // Libraries already loaded read their environment at load time; tell them directly. Looked up
  // at run time so the harness does not depend on which BLAS is installed.
  using SetThreads = void (*)(int);
  for (const char* fn : {"openblas_set_num_threads", "goto_set_num_threads", "omp_set_num_threads",
                         "bli_thread_set_num_threads"}) {
    if (void* sym = dlsym(RTLD_DEFAULT, fn)) reinterpret_cast<SetThreads>(sym)(1);
  }
}

std::vector<int> comparedSteps(const Scene& scene, int lastStep) {
  const int n = lastStep >= 0 ? std::min(lastStep, scene.numSteps()) : scene.numSteps();
  std::vector<int> steps;
  for (Real t : scene.compareAt) {
    const int k = std::max(static_cast<int>(std::llround(t / scene.dt)), 1);
    if (k > n) break;  // the run stops before this instant (--steps)
    if (steps.empty() || k > steps.back()) steps.push_back(k);
  }
  if (scene.compareAt.empty() && n >= 1) steps.push_back(n);
  return steps;
}

namespace {

/// The time after which a scene's interaction no longer changes: the last tool keyframe that
/// moves the tool or changes its jaws, and the last load start or end inside the run. Settling
/// is only looked for after it.
Real interactionSteadyTime(const Scene& scene) {
  Real t = 0;
  for (const ToolSpec& tool : scene.tools)
    for (size_t k = 1; k < tool.trajectory.size(); ++k) {
      const KeyFrame &a = tool.trajectory[k - 1], &b = tool.trajectory[k];
      if (a.pos != b.pos || a.jawClosed != b.jawClosed) t = std::max(t, b.t);
    }
  for (const LoadSpec& load : scene.loads) {
    t = std::max(t, load.start);
    if (load.end < scene.duration) t = std::max(t, load.end);
    if (!load.path.empty()) t = std::max(t, load.path.back().t);
  }
  return t;
}

}  // namespace

void putSnapshotExtras(ByteWriter& w, const SurfaceSnapshot& s) {
  w.pod(s.step);
  w.pod(s.time);
  w.matrix(s.positions);
  w.pod(static_cast<long long>(s.plateForces.size()));
  for (const Vec3& f : s.plateForces) {
    w.pod(f.x());
    w.pod(f.y());
    w.pod(f.z());
  }
  w.matrix(s.markers);
  w.pod(s.markerRms);
  w.pod(s.markerMax);
  w.pod(s.markerRmsTranslation);
}

SurfaceSnapshot getSnapshotExtras(ByteReader& r) {
  SurfaceSnapshot s;
  s.step = r.pod<int>();
  s.time = r.pod<Real>();
  r.matrix(s.positions);
  for (long long i = 0, n = r.pod<long long>(); i < n; ++i) {
    Vec3 f;
    f.x() = r.pod<double>();
    f.y() = r.pod<double>();
    f.z() = r.pod<double>();
    s.plateForces.push_back(f);
  }
  r.matrix(s.markers);
  s.markerRms = r.pod<double>();
  s.markerMax = r.pod<double>();
  s.markerRmsTranslation = r.pod<double>();
  return s;
}

bool solveOnlyAtComparedInstants(const ModelInfo& info, const ParamValues& params) {
  if (!info.has(Capability::QuasiStatic)) return false;
  const auto it = params.all().find("solve");
  if (it != params.all().end() && std::holds_alternative<std::string>(it->second))
    return std::get<std::string>(it->second) == "quasi_static";
  return true;
}

std::vector<int> quasiStaticSolveSteps(const Scene& scene, int lastStep) {
  const int n = lastStep >= 0 ? std::min(lastStep, scene.numSteps()) : scene.numSteps();
  if (scene.needsDynamics()) {
    // Instruments or objects with dynamics (ODE) take the tissue's reaction every step: a model
    // left idle between compared instants holds no reaction there, so a box pushed by its
    // coupling falls through the organ and the next solve finds it deep inside (issue 35).
    std::vector<int> every(size_t(std::max(n, 0)));
    for (int k = 0; k < n; ++k) every[size_t(k)] = k + 1;
    return every;
  }
  std::vector<int> steps = comparedSteps(scene, n);
  // Same slack as the interaction's keyframe test, so "closes at step k" means the same here.
  const Real slack = 1e-6 * scene.dt;
  for (const ToolSpec& tool : scene.tools) {
    if (tool.type != ToolType::Grasper) continue;
    bool was = jawClosed(tool.trajectory, slack);
    for (int k = 1; k < n; ++k) {
      const bool now = jawClosed(tool.trajectory, k * scene.dt + slack);
      if (now && !was) steps.push_back(k);
      was = now;
    }
  }
  std::sort(steps.begin(), steps.end());
  steps.erase(std::unique(steps.begin(), steps.end()), steps.end());
  return steps;
}

std::string unsupportedReason(const ModelInfo& info, const Scene& scene) {
  const auto lacks = [&](const std::string& what, Capability c) {
    return what + " needs the " + capabilityName(c) + " capability, which " + info.name +
           " does not have";
  };
  for (size_t i = 0; i < scene.tools.size(); ++i) {
    const ToolSpec& t = scene.tools[i];
    const std::string name = "the scene's tool " + std::to_string(i);
    if (t.type == ToolType::Grasper && !info.has(Capability::Grasp))
      return lacks(name + " (grasper)", Capability::Grasp);
    if (t.type == ToolType::Probe && !info.has(Capability::Contact))
      return lacks(name + " (probe)", Capability::Contact);
    if (t.type == ToolType::Grasper && t.dynamics && !info.has(Capability::ReactionForce))
      return lacks(name + " (a grasper with dynamics: the hand feels the grasp force)",
                   Capability::ReactionForce);
  }
  if (!scene.plates.empty() && !info.has(Capability::Grasp))
    return lacks("the scene's plates (held as grasps of their surface vertices)",
                 Capability::Grasp);
  for (size_t i = 0; i < scene.plates.size(); ++i)
    if (scene.plates[i].contact == PlateContact::Sliding && !info.has(Capability::Sliding))
      return lacks("the scene's plate " + std::to_string(i) +
                       " (sliding: the normal displacement prescribed, the tangential free)",
                   Capability::Sliding);
  if (!scene.objects.empty() && !info.has(Capability::Contact))
    return lacks("the scene's rigid objects", Capability::Contact);
  // A free object is held up only by the reaction the model reports: without it the object falls
  // through the organ, which would be scored as the model's behaviour.
  if (!scene.objects.empty() && !info.has(Capability::ContactReaction))
    return lacks("the scene's rigid objects (a free object rests on the reported contact reaction)",
                 Capability::ContactReaction);
  if (!scene.organ.fixed.rollers.empty() && !info.has(Capability::RollerSupport))
    return lacks("the scene's roller supports (fixed boxes holding some axes only)",
                 Capability::RollerSupport);
  if (!scene.loads.empty() && !info.has(Capability::PointForce)) {
    return "the scene's loads need the point_force capability, which " + info.name +
           " does not have";
  }
  return "";
}

namespace {

/// Divergence test after a step: NaN/Inf, or a vertex outside the box kDivergenceBoxFactor times
/// the organ's size around its centre (a cube, so that flat organs get room too).
std::string divergenceProblem(const MatX3& surface, const Vec3& centre, Real halfSide) {
  for (Eigen::Index i = 0; i < surface.rows(); ++i) {
    const Vec3 p = surface.row(i).transpose();
    if (!p.allFinite()) return "vertex " + std::to_string(i) + " is NaN or Inf";
    if (((p - centre).cwiseAbs().array() > halfSide).any()) {
      std::ostringstream s;
      s << "vertex " << i << " left the divergence box (" << tol::kDivergenceBoxFactor
        << " x the organ's size)";
      return s.str();
    }
  }
  return "";
}

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

/// How far (infinity norm, m) the scene itself places its ODE bodies from the organ's centre:
/// the keyframes of its tools and the start and keyframes of its objects.
Real sceneReach(const Scene& scene, const Vec3& centre) {
  Real reach = 0;
  const auto take = [&](const Vec3& p) {
    reach = std::max(reach, (p - centre).cwiseAbs().maxCoeff());
  };
  for (const ToolSpec& t : scene.tools)
    for (const KeyFrame& k : t.trajectory) take(k.pos);
  for (const ObjectSpec& o : scene.objects) {
    take(o.pos);
    for (const KeyFrame& k : o.trajectory) take(k.pos);
  }
  return reach;
}

/// Divergence of the scene's ODE bodies (dynamic tools, objects) after the interaction was
/// prepared for the step ending at tEnd: a position or hand force that is NaN or Inf, or a body
/// outside the divergence box grown by the scene's own reach and a free fall over tEnd (a free
/// object may fall off the organ; it cannot reach 1e200 m). "" when every body is sane. A body
/// that explodes (an unstable coupling or contact loop: objects at 1e204 m, hand forces at
/// 1e209 N) would otherwise feed the model forces that no scene asked for.
std::string instrumentDivergence(const Interaction& interaction, const Scene& scene, Real tEnd,
                                 const Vec3& centre, Real halfSide, Real reach) {
  const Real allowed = halfSide + reach + 0.5 * scene.gravity.norm() * tEnd * tEnd;
  const auto problem = [&](const std::string& who, const Vec3& p, const Vec3* force) {
    std::ostringstream s;
    if (!p.allFinite() || (force && !force->allFinite())) {
      s << who << " is NaN or Inf";
    } else if ((p - centre).cwiseAbs().maxCoeff() > allowed) {
      s << who << " is " << (p - centre).norm() << " m from the organ's centre";
      if (force) s << " (hand force " << force->norm() << " N)";
    } else {
      return std::string();
    }
    return s.str();
  };
  for (const Interaction::HandForce& h : interaction.handForces())
    if (std::string p = problem(h.instrument, h.position, &h.force); !p.empty()) return p;
  const std::vector<Vec3> objects = interaction.objectPositions();
  for (size_t j = 0; j < objects.size(); ++j)
    if (std::string p = problem("objects/" + std::to_string(j), objects[j], nullptr); !p.empty())
      return p;
  return "";
}

/// The largest motion (m) a scene prescribes besides the grasps (whose travel the interaction
/// measures): a probe's or a driven object's keyframes from their first, a pin_head's pin from
/// its anchor.
Real prescribedMotionBesidesGrasps(const Scene& scene) {
  Real m = 0;
  const auto travel = [&](const std::vector<KeyFrame>& path, const Vec3& from) {
    for (const KeyFrame& k : path) m = std::max(m, (k.pos - from).norm());
  };
  for (const ToolSpec& t : scene.tools)
    if (t.type == ToolType::Probe && !t.trajectory.empty())
      travel(t.trajectory, t.trajectory.front().pos);
  for (const ObjectSpec& o : scene.objects)
    if (!o.trajectory.empty()) travel(o.trajectory, o.trajectory.front().pos);
  for (const LoadSpec& l : scene.loads)
    if (l.type == LoadType::PinHead) travel(l.path, l.at);
  return m;
}

/// Nodes a model holds in the fixed region: its own count when it reports counts "fixed_nodes"
/// (a model that pins by its own rule, e.g. the sphere carrying each fixed surface vertex),
/// else those of its nodes (at rest) inside the region.
int fixedNodeCount(const Model& model, const Organ& organ) {
  if (organ.fixed.empty()) return 0;
  const Counts counts = model.counts();
  if (const auto it = counts.find("fixed_nodes"); it != counts.end())
    return static_cast<int>(it->second);
  return static_cast<int>(fixedNodeIndices(model.nodes(), organ.fixed, organ.surface).size());
}

}  // namespace

namespace {

/// simulate()'s record before the first step: planned steps, no results yet.
void startRecord(const Scene& scene, int n, RunRecord& rec) {
  rec.plannedSteps = n;
  rec.steps = 0;
  rec.stepMs.clear();
  rec.stepMs.reserve(static_cast<size_t>(n));
  rec.compared.clear();
  rec.series.clear();
  rec.graspForces.clear();
  rec.handForces.clear();
  rec.dt = scene.dt;
  rec.status = RunStatus::Ok;
}

/// A compared instant: the surface, the plates' reaction forces, the markers and their errors.
SurfaceSnapshot comparedSnapshot(Model& model, const Scene& scene, bool withMarkers, int step,
                                 Real time, const MatX3& surface, const StepInput& in) {
  SurfaceSnapshot snap = snapshotAt(step, time, surface);
  if (!scene.plates.empty()) {
    const std::vector<Vec3> forces = model.graspForces();
    if (forces.size() >= in.grasps.size()) {
      snap.plateForces.assign(scene.plates.size(), Vec3::Zero());
      for (size_t g = 0; g < in.grasps.size(); ++g) {
        const int p = in.grasps[g].tool - static_cast<int>(scene.tools.size());
        if (p >= 0 && p < static_cast<int>(scene.plates.size()))
          snap.plateForces[size_t(p)] = forces[g];
      }
    }
  }
  if (withMarkers) {
    snap.markers = model.markers();
    for (const MarkerFrame& m : scene.markers.measured) {
      const bool now =
          m.atEquilibrium ? scene.compareAtEquilibrium : std::fabs(m.t - time) <= 0.5 * scene.dt;
      if (!now || snap.markers.rows() != m.points.rows() || m.points.rows() == 0) continue;
      const MatX3 diff = snap.markers - m.points;
      const VecX d = diff.rowwise().norm();
      const double n = double(d.size());
      snap.markerRms = std::sqrt(d.squaredNorm() / n);
      snap.markerMax = d.maxCoeff();
      const MatX3 registered = diff.rowwise() - diff.colwise().mean();
      snap.markerRmsTranslation = std::sqrt(registered.squaredNorm() / n);
    }
  }
  return snap;
}

/// The motion measures after the run: peak displacement, the motion floor, the fixed region's
/// drift, the prescribed motion, and the support and outrun notes.
void measureMotion(const Scene& scene, const Organ& organ, RunRecord& rec) {
  const MatX3& rest = organ.surface.V;
  auto peak = [&](const MatX3& x) {
    return x.rows() >= rest.rows() && rest.rows() > 0
               ? (x.topRows(rest.rows()) - rest).rowwise().norm().maxCoeff()
               : Real(0);
  };
  rec.peakDisplacement = peak(rec.finalSurface);
  for (const SurfaceSnapshot& c : rec.compared)
    rec.peakDisplacement = std::max<double>(rec.peakDisplacement, peak(c.positions));
  const bool loaded =
      scene.gravity.squaredNorm() > 0 || !scene.loads.empty() || rec.graspTravel > 0;
  rec.motionFloor = loaded && rest.rows() > 0 ? 1e-6 * boundingBox(rest).diagonal() : 0.0;
  // The organ's own surface inside the fixed region must stay (however the model holds it).
  rec.fixedDrift = 0;
  if (!organ.fixed.empty() && rest.rows() > 0) {
    const std::vector<int> held = fixedNodeIndices(rest, organ.fixed, organ.surface);
    const auto drift = [&](const MatX3& x) {
      Real d = 0;
      for (int v : held)
        if (v < x.rows()) d = std::max(d, (x.row(v) - rest.row(v)).norm());
      return d;
    };
    Real d = drift(rec.finalSurface);
    for (const SurfaceSnapshot& c : rec.compared) d = std::max(d, drift(c.positions));
    if (d > 1e-6 * boundingBox(rest).diagonal()) rec.fixedDrift = d;
  }
  if (const std::string p = supportProblem(scene, rec); !p.empty()) rec.notes.push_back(p);
  rec.prescribedMotion = std::max<double>(rec.graspTravel, prescribedMotionBesidesGrasps(scene));
  if (const std::string note = outrunNote(scene, rec); !note.empty()) rec.notes.push_back(note);
}

/// simulate()'s record after the last step: grasp residual and travel, timings, the model's
/// counters and final surface, the interaction's leftovers, notes and the motion measures.
void finishRecord(Model& model, const Scene& scene, const Organ& organ, Interaction& interaction,
                  const RunOptions& options, bool sparse,
                  const std::map<std::string, std::vector<double>>& phases, double residual2,
                  long long residualCount, RunRecord& rec) {
  const bool equilibrium = scene.compareAtEquilibrium;
  rec.graspResidual = residualCount > 0 ? std::sqrt(residual2 / double(residualCount)) : -1.0;
  {
    const std::vector<Real> travel = interaction.graspTravel();
    rec.graspTravel = travel.empty() ? 0.0 : *std::max_element(travel.begin(), travel.end());
  }

  rec.stepStats = stepStatistics(rec.stepMs, sparse ? 0.0 : options.warmupFraction);
  rec.phaseMs.clear();
  for (auto& [phase, v] : phases) rec.phaseMs[phase] = median(v);
  rec.numeric = model.numericCounters();
  if (const int n = interaction.forcelessGraspSteps(); n > 0)
    rec.numeric["forceless_grasp_steps"] = n;
  rec.finalSurface = model.surface();
  const MatX3i faces = model.surfaceFaces();
  rec.finalFaces = faces.rows() > 0 ? faces : organ.surface.F;
  rec.emptyGrasps = interaction.emptyGrasps();
  rec.objectsFinal = interaction.objectPositions();
  if (const ContactWorld* cw = interaction.contactWorld()) {
    rec.contactPairs = cw->pairsTested();
    rec.contacts = cw->contactsFound();
  }
  for (int tool : rec.emptyGrasps) {
    rec.notes.push_back("the grasp of tool " + std::to_string(tool) +
                        " closed on no surface vertex");
  }
  if (equilibrium && rec.status == RunStatus::Ok && !rec.settledAt)
    rec.notes.push_back("did not settle by the end of the run (largest surface speed above " +
                        std::to_string(scene.settleSpeed) + " m/s)");
  measureMotion(scene, organ, rec);
}

}  // namespace

void simulate(Model& model, const Scene& scene, const Organ& organ, const RunOptions& options,
              RunRecord& rec) {
  const int n =
      options.maxSteps >= 0 ? std::min(options.maxSteps, scene.numSteps()) : scene.numSteps();
  startRecord(scene, n, rec);

  // The support rules judge clamps (boxes, listed vertices); roller boxes hold single axes and
  // are not counted in fixed_nodes.
  rec.fixedRegion = !organ.fixed.boxes.empty() || !organ.fixed.surfaceVertices.empty();
  rec.fixedNodes = fixedNodeCount(model, organ);  // nodes() are at rest after init / reset
  const Box box = boundingBox(organ.surface.V);
  const Real halfSide = 0.5 * tol::kDivergenceBoxFactor * std::max(box.size().maxCoeff(), 1e-9);
  const Real reach = sceneReach(scene, box.center());
  const std::vector<int> compareSteps = comparedSteps(scene, n);
  const int every =
      options.keepSeries && scene.surfaces == SurfaceOutput::Every ? scene.surfaceEvery : 0;
  const int nv = organ.surface.numVertices();

  Interaction interaction(scene, organ.surface);
  rec.worlds = interaction.describeWorlds();
  std::map<std::string, std::vector<double>> phases;
  const bool sparse = options.quasiStaticAtComparedInstants.value_or(false);
  const std::vector<int> solveSteps = sparse ? quasiStaticSolveSteps(scene, n) : std::vector<int>{};
  rec.solvedSteps = sparse ? 0 : -1;
  const int warmup = sparse ? 0 : static_cast<int>(std::floor(options.warmupFraction * n));
  if (every > 0) rec.series.push_back(snapshotAt(0, 0.0, model.surface()));

  // Equilibrium comparisons: a dynamic model stops once it settled after the interaction stopped
  // changing; a quasi-static one is at equilibrium at its (last) solve.
  const bool equilibrium = scene.compareAtEquilibrium;
  const Real steadyTime = interactionSteadyTime(scene);
  int quietSteps = 0;
  MatX3 previous = model.surface();
  rec.settledAt.reset();
  rec.equilibrium = equilibrium;
  double residual2 = 0;
  long long residualCount = 0;
  const bool withMarkers = rec.markerStatus == "ok";
  const auto snapshot = [&](int step, Real time, const MatX3& surface, const StepInput& in) {
    return comparedSnapshot(model, scene, withMarkers, step, time, surface, in);
  };

  for (int k = 0; k < n; ++k) {
    if (options.onStep && k > 0 && (k & 4095) == 0) options.onStep(k, n);
    const Real t = k * scene.dt;
    const StepInput in = interaction.prepare(t, scene.dt, model);
    const auto& hands = interaction.handForces();
    if (k == 0) {
      rec.instruments.clear();
      for (const auto& h : hands) rec.instruments.push_back(h.instrument);
    }
    for (size_t h = 0; h < hands.size(); ++h)
      rec.handForces.push_back({k + 1, static_cast<int>(h), hands[h].force, hands[h].position});
    if (const std::string bad = instrumentDivergence(interaction, scene, (k + 1) * scene.dt,
                                                     box.center(), halfSide, reach);
        !bad.empty()) {
      // Not the model's own divergence, but its run is no longer the scene's: stop it here.
      rec.status = RunStatus::Diverged;
      std::ostringstream s;
      s << "diverged at step " << k + 1 << " (t = " << (k + 1) * scene.dt
        << " s): an object or instrument diverged: " << bad;
      rec.message = s.str();
      break;
    }
    if (sparse && !std::binary_search(solveSteps.begin(), solveSteps.end(), k + 1)) {
      // Not an instant anyone looks at: the quasi-static state between solves is not needed.
      rec.steps = k + 1;
      continue;
    }
    if (sparse) ++rec.solvedSteps;
    StepStatus status;
    const auto t0 = std::chrono::steady_clock::now();
    try {
      status = model.step(in);
    } catch (const std::exception& e) {
      rec.status = RunStatus::Failed;
      rec.message = "step " + std::to_string(k + 1) + ": " + e.what();
      break;
    } catch (...) {
      rec.status = RunStatus::Failed;
      rec.message = "step " + std::to_string(k + 1) + ": unknown exception";
      break;
    }
    rec.stepMs.push_back(1e3 * secondsSince(t0));
    rec.steps = k + 1;
    interaction.finishStep(in, model);
    const Real tEnd = (k + 1) * scene.dt;

    const MatX3& surface = model.surface();
    std::string problem;
    if (status == StepStatus::Diverged) {
      problem = "the model reported divergence";
    } else if (surface.rows() < nv) {
      rec.status = RunStatus::Failed;
      rec.message = "step " + std::to_string(k + 1) + ": surface() has " +
                    std::to_string(surface.rows()) + " rows, the organ has " + std::to_string(nv) +
                    " vertices";
      break;
    } else {
      problem = divergenceProblem(surface, box.center(), halfSide);
    }
    if (!problem.empty()) {
      rec.status = RunStatus::Diverged;
      std::ostringstream s;
      s << "diverged at step " << k + 1 << " (t = " << tEnd << " s): " << problem;
      rec.message = s.str();
      break;
    }

    if (k >= warmup) {
      for (const auto& [phase, ms] : model.phaseTimes()) phases[phase].push_back(ms);
    }
    for (const GraspInput& g : in.grasps) {
      for (size_t q = 0; q < g.vertices.size(); ++q) {
        const Vec3 miss = (surface.row(g.vertices[q]) - g.targets.row(Eigen::Index(q))).transpose();
        // A sliding plate prescribes the normal component only.
        residual2 += g.sliding() ? std::pow(miss.dot(g.slideNormal), 2) : miss.squaredNorm();
        ++residualCount;
      }
    }
    if (options.recordGraspForces && !in.grasps.empty()) {
      const std::vector<Vec3> forces = model.graspForces();
      for (size_t g = 0; g < forces.size() && g < in.grasps.size(); ++g)
        rec.graspForces.push_back({k + 1, in.grasps[g].tool, forces[g]});
    }
    if (every > 0 && (k + 1) % every == 0) rec.series.push_back(snapshotAt(k + 1, tEnd, surface));
    if (equilibrium && !sparse) {
      const Real speed =
          (surface.topRows(nv) - previous.topRows(nv)).rowwise().norm().maxCoeff() / scene.dt;
      previous = surface;
      quietSteps =
          tEnd > steadyTime + 0.5 * scene.dt && speed < scene.settleSpeed ? quietSteps + 1 : 0;
      if (quietSteps >= scene.settleSteps) {
        rec.settledAt = tEnd;
        rec.compared.push_back(snapshot(k + 1, tEnd, surface, in));
        break;
      }
      if (k + 1 == n) rec.compared.push_back(snapshot(k + 1, tEnd, surface, in));  // the cap
      continue;
    }
    if (std::binary_search(compareSteps.begin(), compareSteps.end(), k + 1)) {
      rec.compared.push_back(snapshot(k + 1, tEnd, surface, in));
      if (equilibrium) rec.settledAt = tEnd;
    }
  }
  finishRecord(model, scene, organ, interaction, options, sparse, phases, residual2, residualCount,
               rec);
  assessValidity(scene, rec);
}

std::string supportProblem(const Scene&, const RunRecord& rec) {
  if (!rec.fixedRegion || rec.status != RunStatus::Ok) return "";
  if (rec.fixedNodes == 0)
    return "the fixed region holds none of the model's nodes (fixed_nodes 0): nothing supports "
           "the organ";
  if (rec.fixedDrift > 0 && rec.fixedDrift > 0.05 * rec.peakDisplacement) {
    std::ostringstream s;
    s << "the fixed region did not hold: its surface moved " << rec.fixedDrift * 1e3
      << " mm, over 5% of the largest displacement (" << rec.peakDisplacement * 1e3 << " mm)";
    return s.str();
  }
  return "";
}

std::string outrunNote(const Scene& scene, const RunRecord& rec) {
  if (rec.status != RunStatus::Ok || rec.prescribedMotion <= 0 || rec.peakDisplacement <= 0)
    return "";
  // Driven by prescribed motion alone: a point force moves the organ as far as its stiffness
  // lets it, which no tool bounds.
  for (const LoadSpec& l : scene.loads)
    if (l.type == LoadType::PointForce) return "";
  const double ratio = rec.peakDisplacement / rec.prescribedMotion;
  if (ratio <= 1.5) return "";
  std::ostringstream s;
  s.precision(3);
  s << "the surface outran the tool: surface points moved up to " << rec.peakDisplacement * 1e3
    << " mm, " << ratio << "x the largest prescribed motion (" << rec.prescribedMotion * 1e3
    << " mm; over 1.5x in a quasi-static scene)";
  return s.str();
}

std::string notRunReason(const RunRecord& rec) {
  if (rec.status == RunStatus::Ok) return "";
  const std::string status = statusName(rec.status);
  if (rec.message.empty()) return status;
  // "diverged at step ...": the message already says it.
  if (rec.message.rfind(status, 0) == 0) return rec.message;
  return status + " (" + rec.message + ")";
}

void assessValidity(const Scene& scene, RunRecord& rec) {
  rec.valid = true;
  rec.invalidReason.clear();
  const auto invalid = [&](const std::string& why) {
    if (!rec.valid) return;
    rec.valid = false;
    rec.invalidReason = why;
  };
  if (rec.status != RunStatus::Ok) invalid(notRunReason(rec));
  if (!rec.emptyGrasps.empty()) invalid("grasp held nothing");
  // A dynamic instrument is moved by the tissue's force on its grasp: without one it felt none.
  if (const auto it = rec.numeric.find("forceless_grasp_steps");
      it != rec.numeric.end() && it->second > 0)
    invalid("the model reported no force for a grasp of a dynamic instrument (" +
            std::to_string(it->second) + " steps): the instrument felt no tissue");
  // Scale of the residual test: the tool's travel, at least its jaw radius (a grasp that holds
  // still is judged against the size of what it holds).
  Real radius = 0;
  for (const ToolSpec& t : scene.tools)
    if (t.type == ToolType::Grasper) radius = std::max(radius, t.radius);
  const double scale = std::max<double>(rec.graspTravel, radius);
  if (rec.graspResidual > 0.1 * scale && scale > 0) {
    std::ostringstream s;
    s << "grasp residual " << rec.graspResidual * 1e3 << " mm exceeds 10% of the tool's travel ("
      << 0.1 * scale * 1e3 << " mm)";
    invalid(s.str());
  }
  if (scene.compareAtEquilibrium && rec.status == RunStatus::Ok && !rec.settledAt)
    invalid("did not settle");
  // A solver that counts the solves it gave up on (numeric "unconverged_steps") left a state
  // that is not the equilibrium or the step the scene asked for; those it stopped where the
  // surface passed through itself (numeric "solves_stopped_at_fold", reference_fem) and those that
  // spent their budget of Newton iterations ("solves_out_of_budget") are named.
  if (const auto it = rec.numeric.find("unconverged_steps");
      rec.status == RunStatus::Ok && it != rec.numeric.end() && it->second > 0) {
    const auto count = [&](const char* key) {
      const auto c = rec.numeric.find(key);
      return c == rec.numeric.end() ? 0LL : c->second;
    };
    std::string why;
    const auto because = [&why](const std::string& part) {
      why += (why.empty() ? "" : "; ") + part;
    };
    if (const long long folded = count("solves_stopped_at_fold"); folded > 0)
      because(std::to_string(folded) +
              " stopped short of its load where the surface passed through itself, "
              "away from the held nodes");
    if (const long long spent = count("solves_out_of_budget"); spent > 0)
      because(std::to_string(spent) +
              " gave up at its budget of Newton iterations (max_solve_newton_iterations)");
    invalid(std::to_string(it->second) + (it->second == 1 ? " solve" : " solves") +
            " did not converge" + (why.empty() ? std::string() : " (" + why + ")"));
  }
  // A tet network that turned over 0.5% of its tets inside out (numeric "inverted_tets" against
  // counts "elements") has folded through itself: its state is no deformation of the solid it
  // models, and its error measures the fold. A few slivers inverted under a load stay valid (the
  // hybrid tables note them). In the hybrid tables (4000-tet networks) the rows pressing up, and
  // those at 0.5-2 N whose error is below the displacement, invert at most 0.4%; those whose
  // error exceeds the displacement at least 0.9%.
  if (const auto it = rec.numeric.find("inverted_tets");
      rec.status == RunStatus::Ok && it != rec.numeric.end() && it->second > 0) {
    const auto elements = rec.counts.find("elements");
    if (elements != rec.counts.end() && it->second * 200 > elements->second) {
      std::ostringstream s;
      s << it->second << " of " << elements->second
        << " tets inverted (over 0.5%): the network folded through itself";
      invalid(s.str());
    }
  }
  if (rec.status == RunStatus::Ok && rec.peakDisplacement >= 0 &&
      rec.peakDisplacement < rec.motionFloor) {
    std::ostringstream s;
    s << "did not move: largest surface displacement " << rec.peakDisplacement
      << " m although the scene loads the organ";
    invalid(s.str());
  }
  if (const std::string p = supportProblem(scene, rec); !p.empty()) invalid(p);
}

void invalidateIfNotOk(RunRecord& rec) {
  if (rec.status == RunStatus::Ok) return;
  if (rec.valid || rec.invalidReason.empty()) rec.invalidReason = notRunReason(rec);
  rec.valid = false;
}

namespace {

/// Binds the scene's markers to the model (Model::bindMarkers) and says whether it could.
void bindSceneMarkers(const ModelInfo& info, Model& model, const Scene& scene, RunRecord& rec) {
  rec.markerStatus.clear();
  rec.markerReason.clear();
  if (scene.markers.points.rows() == 0) return;
  rec.markerStatus = "unsupported";
  if (!info.has(Capability::Markers)) {
    rec.markerReason = info.name + " does not have the markers capability (no interior mapping)";
    return;
  }
  try {
    model.bindMarkers(scene.markers.points);
    if (model.markers().rows() != scene.markers.points.rows()) {
      rec.markerReason = "markers() returned " + std::to_string(model.markers().rows()) +
                         " rows for " + std::to_string(scene.markers.points.rows()) + " markers";
      return;
    }
    rec.markerStatus = "ok";
  } catch (const std::exception& e) {
    rec.markerReason = e.what();
  }
}

/// runModel() without the final validity guard: its early returns (unsupported, init threw,
/// a surface of the wrong size) skip simulate() and with it assessValidity().
RunRecord runModelUnguarded(const ModelInfo& info, const ParamValues& params, const Scene& scene,
                            const Organ& organ, Cache& cache, const RunOptions& options) {
  RunRecord rec = newRunRecord(info, params, scene, options);

  const std::string why = unsupportedReason(info, scene);
  if (!why.empty()) {
    rec.status = RunStatus::Unsupported;
    rec.message = why;
    return rec;
  }
  if (scene.gravity.squaredNorm() > 0 && !info.has(Capability::Gravity))
    rec.notes.push_back("gravity ignored: the model has no gravity capability");

  std::unique_ptr<Model> model;
  cache.clearEvents();
  try {
    model = info.create();
    if (!model) throw std::runtime_error("the plugin's factory returned no model");
    const ModelSetup setup{organ, params, cache, scene.dt, scene.gravity};
    const auto t0 = std::chrono::steady_clock::now();
    model->init(setup);
    rec.precomputeS = secondsSince(t0);
  } catch (const UnsupportedError& e) {
    // The model cannot run here at all (a program or library it needs is missing).
    rec.status = RunStatus::Unsupported;
    rec.message = e.what();
    rec.cacheEvents = cache.events();
    return rec;
  } catch (const std::exception& e) {
    rec.status = RunStatus::Failed;
    rec.message = std::string("init: ") + e.what();
    rec.cacheEvents = cache.events();
    return rec;
  } catch (...) {
    rec.status = RunStatus::Failed;
    rec.message = "init: unknown exception";
    rec.cacheEvents = cache.events();
    return rec;
  }
  rec.cacheEvents = cache.events();

  try {
    rec.counts = model->counts();
    if (model->surface().rows() != organ.surface.numVertices()) {
      rec.status = RunStatus::Failed;
      rec.message = "after init, surface() has " + std::to_string(model->surface().rows()) +
                    " rows, the organ has " + std::to_string(organ.surface.numVertices()) +
                    " vertices";
      return rec;
    }
    bindSceneMarkers(info, *model, scene, rec);
    RunOptions o = options;
    if (!o.quasiStaticAtComparedInstants)
      o.quasiStaticAtComparedInstants = solveOnlyAtComparedInstants(info, params);
    simulate(*model, scene, organ, o, rec);
  } catch (const std::exception& e) {
    rec.status = RunStatus::Failed;
    rec.message = e.what();
  } catch (...) {
    rec.status = RunStatus::Failed;
    rec.message = "unknown exception";
  }
  return rec;
}

}  // namespace

RunRecord newRunRecord(const ModelInfo& info, const ParamValues& params, const Scene& scene,
                       const RunOptions& options) {
  RunRecord rec;
  rec.model = info.name;
  rec.plugin = info.name;
  rec.label = info.name;
  rec.params = paramsToJson(params);
  rec.plannedSteps =
      options.maxSteps >= 0 ? std::min(options.maxSteps, scene.numSteps()) : scene.numSteps();
  return rec;
}

RunRecord runModel(const ModelInfo& info, const ParamValues& params, const Scene& scene,
                   const Organ& organ, Cache& cache, const RunOptions& options) {
  RunRecord rec = runModelUnguarded(info, params, scene, organ, cache, options);
  invalidateIfNotOk(rec);  // every early return too: a failed or unsupported run is never valid
  return rec;
}

}  // namespace deform::harness
