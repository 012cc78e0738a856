// The runner: one model through one scene with timing and divergence checks, and the whole
// `deformbench run` pipeline around it.
#include <deform/engine/interaction.h>
#include <deform/internal/atomic_file.h>
#include <deform/sdk/contact.h>
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
  switch (s) {
    case RunStatus::Ok:
      return "ok";
    case RunStatus::Diverged:
      return "diverged";
    case RunStatus::Unsupported:
      return "unsupported";
    case RunStatus::Failed:
      return "failed";
  }
  return "failed";
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

void simulate(Model& model, const Scene& scene, const Organ& organ, const RunOptions& options,
              RunRecord& rec) {
  const int n =
      options.maxSteps >= 0 ? std::min(options.maxSteps, scene.numSteps()) : scene.numSteps();
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
  if (every > 0) rec.series.push_back({0, 0.0, model.surface()});

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
  // A compared instant: the surface, the plates' reaction forces, the markers and their errors.
  const auto snapshot = [&](int step, Real time, const MatX3& surface, const StepInput& in) {
    SurfaceSnapshot snap{step, time, surface};
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
        if (std::fabs(m.t - time) > 0.5 * scene.dt || snap.markers.rows() != m.points.rows())
          continue;
        const VecX d = (snap.markers - m.points).rowwise().norm();
        snap.markerRms = d.size() ? std::sqrt(d.squaredNorm() / double(d.size())) : 0.0;
        snap.markerMax = d.size() ? d.maxCoeff() : 0.0;
      }
    }
    return snap;
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
        residual2 += (surface.row(g.vertices[q]) - g.targets.row(Eigen::Index(q))).squaredNorm();
        ++residualCount;
      }
    }
    if (options.recordGraspForces && !in.grasps.empty()) {
      const std::vector<Vec3> forces = model.graspForces();
      for (size_t g = 0; g < forces.size() && g < in.grasps.size(); ++g)
        rec.graspForces.push_back({k + 1, in.grasps[g].tool, forces[g]});
    }
    if (every > 0 && (k + 1) % every == 0) rec.series.push_back({k + 1, tEnd, surface});
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
  rec.graspResidual = residualCount > 0 ? std::sqrt(residual2 / double(residualCount)) : -1.0;
  {
    const std::vector<Real> travel = interaction.graspTravel();
    rec.graspTravel = travel.empty() ? 0.0 : *std::max_element(travel.begin(), travel.end());
  }

  rec.stepStats = stepStatistics(rec.stepMs, sparse ? 0.0 : options.warmupFraction);
  rec.phaseMs.clear();
  for (auto& [phase, v] : phases) rec.phaseMs[phase] = median(v);
  rec.numeric = model.numericCounters();
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
  {
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
  // that is not the equilibrium or the step the scene asked for.
  if (const auto it = rec.numeric.find("unconverged_steps");
      rec.status == RunStatus::Ok && it != rec.numeric.end() && it->second > 0)
    invalid(std::to_string(it->second) + (it->second == 1 ? " solve" : " solves") +
            " did not converge");
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

namespace {

bool matchesOnly(const BenchmarkOptions& options, const PlannedRun& run) {
  if (options.only.empty()) return true;
  for (const std::string& o : options.only) {
    if (o == run.label || o == run.spec.model || o == run.spec.plugin) return true;
  }
  return false;
}

std::string eventName(Cache::EventKind k) {
  switch (k) {
    case Cache::EventKind::Hit:
      return "hit";
    case Cache::EventKind::Miss:
      return "miss";
    case Cache::EventKind::Corrupt:
      return "corrupt (deleted)";
    case Cache::EventKind::Stored:
      return "stored";
    case Cache::EventKind::Disabled:
      return "disabled";
    case Cache::EventKind::StoreFailed:
      return "store failed";
  }
  return "?";
}

}  // namespace

std::vector<PlannedRun> planRuns(const Scene& scene, PluginLoader& loader,
                                 const BenchmarkOptions& options) {
  const auto explain = [&](const std::string& s) {
    if (options.explain) options.explain(s);
  };
  std::vector<const ModelSpec*> specs;
  for (const ModelSpec& m : scene.models) specs.push_back(&m);
  if (scene.reference) {
    if (options.noReference) {
      explain("skipped the reference " + scene.reference->model + ": --no-reference");
    } else {
      specs.push_back(&*scene.reference);
    }
  }
  std::vector<PlannedRun> planned;
  std::set<std::string> labels;
  const std::string organ =
      calibrationOrgan(scene.organ.mesh, scene.organ.resolution, scene.organ.scale);
  for (const ModelSpec* spec : specs) {
    PlannedRun run;
    run.spec = *spec;
    run.isReference = scene.reference && spec == &*scene.reference;
    run.info = &loader.load(spec->plugin, spec->model);
    nlohmann::json given = spec->params;
    const CalibrationParams* calibration =
        run.isReference
            ? nullptr
            : calibrationFor(options.calibrations, spec->plugin, run.info->name, organ, false);
    if (calibration) {
      nlohmann::json merged = calibration->params;
      for (const auto& [k, v] : spec->params.items()) merged[k] = v;
      given = merged;
    }
    run.params = resolveParams(run.info->params, given, scene.file, spec->jsonPath + "/params");
    if (calibration)
      run.calibrationNote = calibrationDifferenceNote(*calibration, paramsToJson(run.params));
    if (options.explain) {
      // Where each parameter came from: the scene, a calibration file, or the default.
      std::string from;
      for (const ParamSpec& ps : run.info->params) {
        std::string source = "default";
        if (spec->params.contains(ps.key)) {
          source = "scene";
          if (calibration && calibration->params.contains(ps.key))
            source += ", over calibration " + calibration->file;
        } else if (calibration && calibration->params.contains(ps.key)) {
          source = "calibration " + calibration->file;
        }
        if (source == "default") continue;
        from += (from.empty() ? "" : "; ") + ps.key + " from " + source;
      }
      explain("params of " + spec->plugin + "/" + run.info->name + " at " + spec->jsonPath + ": " +
              (from.empty() ? std::string("all defaults") : from + "; the rest defaults"));
    }
    if (!spec->label.empty()) {
      run.label = spec->label;
    } else {
      const std::string nd = formatNonDefault(run.params, run.info->params);
      run.label = nd.empty() ? spec->model : spec->model + "(" + nd + ")";
      if (labels.count(run.label)) {
        int i = 2;
        while (labels.count(run.label + " #" + std::to_string(i))) ++i;
        run.label += " #" + std::to_string(i);
      }
    }
    labels.insert(run.label);
    planned.push_back(std::move(run));
  }
  std::vector<PlannedRun> kept;
  for (PlannedRun& run : planned) {
    if (!matchesOnly(options, run) && !run.isReference) {
      explain("skipped " + run.label + ": not selected by --only");
      continue;
    }
    kept.push_back(std::move(run));
  }
  if (!options.only.empty()) {
    const bool any =
        std::any_of(kept.begin(), kept.end(), [](const PlannedRun& r) { return !r.isReference; });
    if (!any) {
      std::string names;
      for (const PlannedRun& r : planned) names += (names.empty() ? "" : ", ") + r.label;
      std::string given;
      for (const auto& o : options.only) given += (given.empty() ? "" : ", ") + o;
      throw InputError(
          "--only", "",
          "no model of the scene matches '" + given + "' (the scene has: " + names + ")");
    }
  }
  for (const std::string& f : loader.loadedFiles()) explain("loaded plugin " + f);
  for (const PlannedRun& r : kept) {
    explain(std::string("built ") + (r.isReference ? "reference " : "model ") + r.label + " = " +
            r.spec.plugin + "/" + r.info->name + " " + paramsToJson(r.params).dump());
  }
  return kept;
}

namespace {

/// Marks every model run with whether its reference is valid (DESIGN "Metrics": reference_valid
/// false marks every error computed against a reference that is invalid, failed or not
/// converged; a reference whose solver gave up on a solve is invalid by assessValidity()).
void markReferenceValidity(const RunRecord& ref, std::vector<RunRecord>& runs) {
  const bool ok = ref.status == RunStatus::Ok && ref.valid;
  std::string why;
  if (!ok) {
    why = "the reference " + ref.label + " is " +
          (ref.status == RunStatus::Ok ? "invalid: " + ref.invalidReason : notRunReason(ref));
  }
  for (RunRecord& r : runs) {
    if (r.isReference) continue;
    r.referenceValid = ok;
    r.referenceInvalidReason = why;
  }
}

}  // namespace

void computeRunErrors(const Scene& scene, const Organ& organ, std::vector<RunRecord>& runs) {
  const auto ref =
      std::find_if(runs.begin(), runs.end(), [](const RunRecord& r) { return r.isReference; });
  if (ref == runs.end()) return;
  markReferenceValidity(*ref, runs);
  if (ref->status != RunStatus::Ok) {
    for (RunRecord& r : runs) {
      if (!r.isReference) r.notes.push_back("no error: the reference run is " + notRunReason(*ref));
    }
    return;
  }
  // A collapse (issue 35, as stability's verdict "collapsed"): where the reference moves the
  // organ by under 10% of its size, a model that went through its support or moved by more than
  // its size did not model the scene.
  if (ref->valid && relativeDisplacement(organ.surface.V, ref->finalSurface) >= 0 &&
      relativeDisplacement(organ.surface.V, ref->finalSurface) < 0.1) {
    const std::vector<int> held =
        organ.fixed.empty() ? std::vector<int>{}
                            : fixedNodeIndices(organ.surface.V, organ.fixed, organ.surface);
    for (RunRecord& r : runs) {
      if (r.isReference || r.status != RunStatus::Ok || !r.valid) continue;
      const std::string why = collapseProblem(
          organ.surface.V,
          r.finalSurface.topRows(std::min(r.finalSurface.rows(), organ.surface.V.rows())), held);
      if (why.empty()) continue;
      r.valid = false;
      r.invalidReason =
          "collapsed: " + why + ", while the reference moves the organ by under 10% of its size";
    }
  }
  const Interaction interaction(scene, organ.surface);
  const Vec3 focus = interaction.focusPoint();
  if (ref->compared.empty()) {
    for (RunRecord& r : runs) {
      if (!r.isReference)
        r.notes.push_back("no error: the run ended before every compared instant");
    }
    return;
  }
  std::vector<MatX3> refSurfaces;
  for (const auto& s : ref->compared) refSurfaces.push_back(s.positions);
  const std::vector<int> excluded = rmseExcludedVertices(scene, organ.surface.V);
  for (RunRecord& r : runs) {
    if (r.isReference || r.status != RunStatus::Ok) continue;
    if (r.compared.size() != refSurfaces.size()) {
      r.notes.push_back("no error: the run has surfaces at different instants than the reference");
      continue;
    }
    std::vector<MatX3> mine;
    for (const auto& s : r.compared) mine.push_back(s.positions);
    r.error = computeErrors(mine, refSurfaces, organ.surface.V, focus, scene.nearest, excluded);
    r.referenceModel = ref->model;
  }
}

namespace {

constexpr const char* kReferenceRunKind = "harness.reference_run";

/// The key of a solve that BenchmarkOptions::reuseReference may share: the problem (the scene
/// without its models, reference, name, description and output, a mesh file's path made
/// absolute, and the organ as loaded), the plugin file (SHA-256), model and resolved parameters,
/// and the step limit. Neither the run's label nor whether it runs as the reference or as a model
/// enters: a convergence level at the reference's own parameters is the same solve.
CacheKey solveKey(const std::string& sceneFile, const Scene& scene, const Organ& organ,
                  PluginLoader& loader, const PlannedRun& p, const RunOptions& run) {
  nlohmann::json doc;
  {
    std::ifstream in(sceneFile);
    doc = nlohmann::json::parse(in);
  }
  for (const char* k : {"models", "reference", "name", "description", "output"}) doc.erase(k);
  if (doc.contains("organ") && doc["organ"].contains("mesh") && doc["organ"]["mesh"].is_string()) {
    const std::string mesh = doc["organ"]["mesh"];
    if (mesh.rfind("phantom:", 0) != 0 && !fs::path(mesh).is_absolute())
      doc["organ"]["mesh"] =
          fs::absolute(fs::path(sceneFile).parent_path() / mesh).lexically_normal().string();
  }
  CacheKey key;
  // /3: the validity rules of wave 3 (supports, instruments) changed what a stored valid means.
  key.add("harness.reference_run/4").add(doc.dump());
  key.add(organ.surface.V).add(organ.surface.F);
  key.add(sha256File(loader.locate(p.spec.plugin))).add(p.info->name).add(p.info->version);
  key.add(paramsToJson(p.params).dump());
  key.add(static_cast<long long>(run.maxSteps < 0 ? scene.numSteps() : run.maxSteps));
  key.add(run.quasiStaticAtComparedInstants ? (*run.quasiStaticAtComparedInstants ? 1 : 0) : -1);
  return key;
}

/// What a later run needs of a solve: its surfaces, counts, timings and the checks' inputs.
void storeCachedSolve(Cache& cache, const CacheKey& key, const RunRecord& r) {
  ByteWriter w;
  w.pod(static_cast<int>(r.steps));
  w.pod(static_cast<int>(r.plannedSteps));
  w.pod(static_cast<int>(r.solvedSteps));
  w.pod(static_cast<int>(r.fixedNodes));
  w.pod(static_cast<int>(r.fixedRegion));
  w.pod(r.graspResidual);
  w.pod(r.graspTravel);
  w.pod(static_cast<int>(r.equilibrium));
  w.pod(static_cast<int>(r.settledAt.has_value()));
  w.pod(r.settledAt.value_or(0.0));
  w.pod(static_cast<int>(r.valid));
  w.string(r.invalidReason);
  w.pod(r.peakDisplacement);
  w.pod(r.motionFloor);
  w.pod(r.fixedDrift);
  w.pod(r.precomputeS);
  w.pod(r.stepStats);
  w.pod(static_cast<int>(r.counts.size()));
  for (const auto& [k, v] : r.counts) {
    w.string(k);
    w.pod(v);
  }
  w.pod(static_cast<int>(r.phaseMs.size()));
  for (const auto& [k, v] : r.phaseMs) {
    w.string(k);
    w.pod(v);
  }
  w.pod(static_cast<int>(r.notes.size()));
  for (const std::string& n : r.notes) w.string(n);
  w.pod(r.dt);
  w.matrix(r.finalSurface);
  w.matrix(r.finalFaces);
  w.pod(static_cast<int>(r.compared.size()));
  for (const SurfaceSnapshot& s : r.compared) putSnapshotExtras(w, s);
  w.string(r.markerStatus);
  w.string(r.markerReason);
  cache.put(kReferenceRunKind, key, w.bytes());
}

bool readCachedSolve(Cache& cache, const CacheKey& key, bool reference, RunRecord& r) {
  const auto hit = cache.get(kReferenceRunKind, key);
  if (!hit) return false;
  try {
    ByteReader b(*hit);
    r.steps = b.pod<int>();
    r.plannedSteps = b.pod<int>();
    r.solvedSteps = b.pod<int>();
    r.fixedNodes = b.pod<int>();
    r.fixedRegion = b.pod<int>() != 0;
    r.graspResidual = b.pod<double>();
    r.graspTravel = b.pod<double>();
    r.equilibrium = b.pod<int>() != 0;
    const bool settled = b.pod<int>() != 0;
    const double at = b.pod<double>();
    if (settled) r.settledAt = at;
    r.valid = b.pod<int>() != 0;
    r.invalidReason = b.string();
    r.peakDisplacement = b.pod<double>();
    r.motionFloor = b.pod<double>();
    r.fixedDrift = b.pod<double>();
    r.precomputeS = b.pod<double>();
    r.stepStats = b.pod<StepStats>();
    for (int i = 0, n = b.pod<int>(); i < n; ++i) {
      std::string k = b.string();
      r.counts[k] = b.pod<long long>();
    }
    for (int i = 0, n = b.pod<int>(); i < n; ++i) {
      std::string k = b.string();
      r.phaseMs[k] = b.pod<double>();
    }
    for (int i = 0, n = b.pod<int>(); i < n; ++i) r.notes.push_back(b.string());
    r.dt = b.pod<Real>();
    b.matrix(r.finalSurface);
    b.matrix(r.finalFaces);
    const int n = b.pod<int>();
    for (int i = 0; i < n; ++i) r.compared.push_back(getSnapshotExtras(b));
    r.markerStatus = b.string();
    r.markerReason = b.string();
    if (!b.atEnd()) throw std::runtime_error("trailing bytes");
  } catch (const std::exception&) {
    r = RunRecord();
    cache.reject(kReferenceRunKind, key);
    return false;  // unreadable: solve again
  }
  r.status = RunStatus::Ok;
  r.notes.push_back(std::string(reference ? "reference" : "model solve") +
                    " read from the cache (an earlier run solved the same problem with the same "
                    "plugin and parameters): its timings are that run's");
  return true;
}

/// The note a run gets for each cache entry it could not store (once per kind).
void noteCacheStoreFailures(RunRecord& rec) {
  std::set<std::string> kinds;
  for (const Cache::Event& e : rec.cacheEvents) {
    if (e.what != Cache::EventKind::StoreFailed || !kinds.insert(e.kind).second) continue;
    rec.notes.push_back("warning: the cache entry " + e.kind + " could not be stored (" + e.detail +
                        "); the run went on without the cache");
  }
}

/// Runs longer than this many steps get a warning before they start and progress lines.
constexpr long long kLongRunSteps = 1000000;

std::string longRunWarning(const Scene& scene, const RunOptions& run) {
  const long long n =
      run.maxSteps >= 0 ? std::min(run.maxSteps, scene.numSteps()) : scene.numSteps();
  if (n <= kLongRunSteps) return "";
  std::ostringstream s;
  s << "warning: " << n << " steps per run (dt " << scene.dt << " s over " << scene.duration
    << " s): each model steps that many times; progress is printed as it goes";
  return s.str();
}

/// Prints "LABEL: step K of N (P%)" at most every 10 s (and never for short runs).
std::function<void(int, int)> stepProgress(const std::string& label,
                                           const std::function<void(const std::string&)>& out) {
  auto last =
      std::make_shared<std::chrono::steady_clock::time_point>(std::chrono::steady_clock::now());
  return [label, out, last](int done, int total) {
    const auto now = std::chrono::steady_clock::now();
    if (now - *last < std::chrono::seconds(total > kLongRunSteps ? 2 : 10)) return;
    *last = now;
    std::ostringstream s;
    s << "  " << label << ": step " << done << " of " << total << " (" << std::setprecision(3)
      << 100.0 * done / std::max(total, 1) << "%)";
    out(s.str());
  };
}

/// The SHA-256 and vertex count of each written final surface, in results.json beside its path,
/// so that `report` can refuse a surface that is not the one this results.json describes.
void signSurfaces(const fs::path& dir, const std::vector<RunRecord>& runs,
                  nlohmann::ordered_json& doc) {
  for (size_t i = 0; i < runs.size() && i < doc["runs"].size(); ++i) {
    if (runs[i].finalSurfaceFile.empty()) continue;
    auto& j = doc["runs"][i];
    j["final_surface_vertices"] = runs[i].finalSurface.rows();
    j["final_surface_sha256"] = sha256File((dir / runs[i].finalSurfaceFile).string());
  }
}

/// The top-level entries of outDir that its results.json names (run folders, the rest surface,
/// .compared.bin files): what a new results.json replaces.
std::set<std::string> namedEntries(const fs::path& outDir) {
  std::set<std::string> out;
  std::error_code ec;
  for (fs::directory_iterator it(outDir, ec), end; !ec && it != end; it.increment(ec))
    if (it->path().filename().string().size() > 13 &&
        it->path().filename().string().rfind(".compared.bin") ==
            it->path().filename().string().size() - 13)
      out.insert(it->path().filename().string());
  try {
    std::ifstream in(outDir / "results.json");
    if (!in) return out;
    const nlohmann::json doc = nlohmann::json::parse(in);
    const auto add = [&](const nlohmann::json& v) {
      if (!v.is_string()) return;
      const fs::path p = fs::path(v.get<std::string>()).lexically_normal();
      if (p.empty() || p.is_absolute()) return;
      const std::string first = p.begin()->string();
      if (first != ".." && first != "." && first.rfind(".staging.", 0) != 0) out.insert(first);
    };
    if (doc.contains("organ") && doc["organ"].is_object())
      add(doc["organ"].value("rest_surface", nlohmann::json()));
    for (const auto& r : doc.value("runs", nlohmann::json::array()))
      if (r.is_object())
        for (const char* k : {"final_surface", "surface_series", "grasp_forces"})
          if (r.contains(k)) add(r[k]);
  } catch (const std::exception&) {
    // unreadable: only its results.json goes
  }
  return out;
}

/// Moves what `staging` holds into outDir: the old results.json first out, then the entries it
/// named, then the new entries in, results.json last.
void swapInResults(const fs::path& staging, const fs::path& outDir) {
  const std::set<std::string> stale = namedEntries(outDir);
  fs::remove(outDir / "results.json");
  for (const std::string& e : stale) fs::remove_all(outDir / e);
  for (const auto& entry : fs::directory_iterator(staging)) {
    const std::string name = entry.path().filename().string();
    if (name == "results.json") continue;
    fs::remove_all(outDir / name);
    fs::rename(entry.path(), outDir / name);
  }
  fs::rename(staging / "results.json", outDir / "results.json");
  fs::remove_all(staging);
}

}  // namespace

fs::path comparedSurfaceFile(const fs::path& outDir, const std::string& label) {
  return outDir / (sanitizeLabel(label) + ".compared.bin");
}

bool readComparedSurface(const fs::path& file, MatX3& positions) {
  std::ifstream in(file, std::ios::binary);
  if (!in) return false;
  const std::vector<char> bytes((std::istreambuf_iterator<char>(in)),
                                std::istreambuf_iterator<char>());
  try {
    ByteReader r(bytes);
    r.matrix(positions);
    return r.atEnd();
  } catch (const std::exception&) {
    return false;
  }
}

BenchmarkResult runBenchmark(const std::string& sceneFile, PluginLoader& loader,
                             const BenchmarkOptions& options) {
  const auto explain = [&](const std::string& s) {
    if (options.explain) options.explain(s);
  };
  const auto progress = [&](const std::string& s) {
    if (options.progress) options.progress(s);
  };
  BenchmarkResult result;
  result.scene = parseSceneFile(sceneFile);
  const Scene& scene = result.scene;
  result.organ = loadOrgan(scene, &result.organLog);
  for (const auto& line : result.organLog) explain("organ: " + line);
  explain("organ " + result.organ.source + ": " +
          std::to_string(result.organ.surface.numVertices()) + " vertices, " +
          std::to_string(result.organ.surface.numFaces()) + " triangles");

  const std::vector<PlannedRun> planned = planRuns(scene, loader, options);
  forceSingleThreadedNumerics();

  const fs::path cacheDir = options.cacheDir ? *options.cacheDir : Cache::defaultDir();
  Cache cache(cacheDir);
  explain(cacheDir.empty() ? std::string("cache disabled") : "cache folder " + cacheDir.string());

  // Output folder must be writable before hours of runs, not after.
  std::error_code ec;
  fs::create_directories(options.outDir, ec);
  if (ec || !fs::is_directory(options.outDir))
    throw InputError(options.outDir.string(), "", "cannot create the output folder");
  if (const std::string w = longRunWarning(scene, options.run); !w.empty()) progress(w);

  for (const PlannedRun& p : planned) {
    progress("running " + p.label + " ...");
    std::optional<CacheKey> refKey;
    RunRecord rec;
    bool fromCache = false;
    const bool shared = options.reuseReference && !cacheDir.empty() &&
                        (p.isReference || (options.reuseModelSolves &&
                                           solveOnlyAtComparedInstants(*p.info, p.params)));
    if (shared) {
      refKey = solveKey(sceneFile, scene, result.organ, loader, p, options.run);
      fromCache = readCachedSolve(cache, *refKey, p.isReference, rec);
      if (fromCache) {
        rec.model = p.info->name;
        rec.params = paramsToJson(p.params);
        explain((p.isReference ? "reference " : "model ") + p.label + " read from the cache " +
                kReferenceRunKind);
      }
    }
    if (!fromCache) {
      RunOptions ro = options.run;
      if (!ro.onStep && options.progress) ro.onStep = stepProgress(p.label, options.progress);
      rec = options.isolateRuns
                ? runModelIsolated(*p.info, p.params, scene, result.organ, cache, ro)
                : runModel(*p.info, p.params, scene, result.organ, cache, ro);
      if (refKey && rec.status == RunStatus::Ok) {
        cache.clearEvents();
        storeCachedSolve(cache, *refKey, rec);
        for (const auto& e : cache.events()) rec.cacheEvents.push_back(e);
      }
    }
    noteCacheStoreFailures(rec);
    rec.plugin = p.spec.plugin;
    rec.label = p.label;
    rec.jsonPath = p.spec.jsonPath;
    rec.isReference = p.isReference;
    for (const auto& e : rec.cacheEvents)
      explain("cache " + eventName(e.what) + ": " + p.label + " " + e.kind + " " + e.key);
    if (rec.status == RunStatus::Unsupported) explain("skipped " + p.label + ": " + rec.message);
    if (rec.status != RunStatus::Unsupported) {
      if (rec.worlds.empty()) {
        explain(p.label + ": no Bullet or ODE world (the scene's tools are kinematic)");
      } else {
        for (const auto& w : rec.worlds) explain(p.label + ": created " + w);
      }
      if (rec.contactPairs >= 0)
        explain(p.label + ": contact: " + std::to_string(rec.contactPairs) +
                " broadphase pairs tested, " + std::to_string(rec.contacts) +
                " penetrating proxies resolved");
    }
    if (rec.solvedSteps >= 0) {
      explain(p.label + ": quasi-static, solved at " + std::to_string(rec.solvedSteps) + " of " +
              std::to_string(rec.steps) +
              " steps (the compared instants and the grasp closings; the interaction was "
              "prepared every step)");
    }
    if (!p.calibrationNote.empty()) rec.notes.push_back(p.calibrationNote);
    for (const auto& note : rec.notes) explain(p.label + ": " + note);
    progress(p.label + ": " + statusName(rec.status) +
             (rec.message.empty() ? "" : " (" + rec.message + ")"));
    result.runs.push_back(std::move(rec));
  }
  computeRunErrors(scene, result.organ, result.runs);

  // Everything is written into a staging folder first and swapped in whole: a rerun that fails
  // while writing (a full disk) leaves the previous results as they were, never a results.json
  // beside surfaces of another run (docs/results-format.md, "Writing").
  const fs::path staging = options.outDir / (".staging." + std::to_string(::getpid()));
  fs::remove_all(staging, ec);
  try {
    fs::create_directories(staging);
    writeRunSurfaces(staging, scene, result.organ, result.runs);
    if (options.writeComparedSurface)
      for (const RunRecord& r : result.runs)
        if (r.status == RunStatus::Ok && !r.compared.empty()) {
          ByteWriter w;
          w.matrix(r.compared.back().positions);
          writeFileAtomic(comparedSurfaceFile(staging, r.label),
                          std::string_view(w.bytes().data(), w.bytes().size()));
        }
    auto doc = resultsJson(scene, result.organ, result.organLog, result.runs, machineInfo());
    signSurfaces(staging, result.runs, doc);
    writeResults(staging, doc);
    swapInResults(staging, options.outDir);
  } catch (const std::exception& e) {
    fs::remove_all(staging, ec);
    if (dynamic_cast<const InputError*>(&e)) throw;
    throw InputError(options.outDir.string(), "",
                     std::string("cannot write the results: ") + e.what());
  }
  result.resultsPath = options.outDir / "results.json";
  return result;
}

}  // namespace deform::harness
