// A model's run in a forked child (see run_isolation.h).
#include <deform_harness/child_process.h>
#include <deform_harness/run_isolation.h>

#include <fcntl.h>
#include <signal.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <iostream>

namespace deform::harness {

namespace {

// Every field of RunRecord is either carried below or documented as not filled by runModel();
// a new field changes the size and stops the build here until it is carried too.
static_assert(sizeof(RunRecord) == 1224,
              "RunRecord changed: carry the new field in serializeRunRecord/deserializeRunRecord "
              "(run_isolation.cpp), then update this size");

void putVec3(ByteWriter& w, const Vec3& v) {
  w.pod(v.x());
  w.pod(v.y());
  w.pod(v.z());
}

Vec3 getVec3(ByteReader& r) {
  Vec3 v;
  v.x() = r.pod<double>();
  v.y() = r.pod<double>();
  v.z() = r.pod<double>();
  return v;
}

template <class V>
void putMap(ByteWriter& w, const std::map<std::string, V>& m) {
  w.pod(static_cast<long long>(m.size()));
  for (const auto& [k, v] : m) {
    w.string(k);
    w.pod(v);
  }
}

template <class V>
void getMap(ByteReader& r, std::map<std::string, V>& m) {
  m.clear();
  for (long long i = 0, n = r.pod<long long>(); i < n; ++i) {
    std::string k = r.string();
    m[k] = r.pod<V>();
  }
}

// A list: its length, then put(element) for each element; get() reads one element back.
template <class T, class Put>
void putList(ByteWriter& w, const std::vector<T>& v, Put put) {
  w.pod(static_cast<long long>(v.size()));
  for (const T& e : v) put(e);
}

template <class T, class Get>
std::vector<T> getList(ByteReader& r, Get get) {
  std::vector<T> v;
  for (long long i = 0, n = r.pod<long long>(); i < n; ++i) v.push_back(get());
  return v;
}

void putStrings(ByteWriter& w, const std::vector<std::string>& v) {
  putList(w, v, [&](const std::string& s) { w.string(s); });
}

std::vector<std::string> getStrings(ByteReader& r) {
  return getList<std::string>(r, [&] { return r.string(); });
}

void putSnapshots(ByteWriter& w, const std::vector<SurfaceSnapshot>& v) {
  putList(w, v, [&](const SurfaceSnapshot& s) { putSnapshotExtras(w, s); });
}

std::vector<SurfaceSnapshot> getSnapshots(ByteReader& r) {
  return getList<SurfaceSnapshot>(r, [&] { return getSnapshotExtras(r); });
}

void putCacheEvent(ByteWriter& w, const Cache::Event& e) {
  w.string(e.kind);
  w.string(e.key);
  w.pod(static_cast<int>(e.what));
  w.string(e.detail);
}

Cache::Event getCacheEvent(ByteReader& b) {
  Cache::Event e;
  e.kind = b.string();
  e.key = b.string();
  const int what = b.pod<int>();
  if (what < 0 || what > static_cast<int>(Cache::EventKind::StoreFailed))
    throw std::runtime_error("run record: bad cache event");
  e.what = static_cast<Cache::EventKind>(what);
  e.detail = b.string();
  return e;
}

void putGraspForce(ByteWriter& w, const GraspForceSample& g) {
  w.pod(g.step);
  w.pod(g.tool);
  putVec3(w, g.force);
}

// (A braced list is evaluated left to right: the fields are read in their order.)
GraspForceSample getGraspForce(ByteReader& b) {
  return {.step = b.pod<int>(), .tool = b.pod<int>(), .force = getVec3(b)};
}

void putHandForce(ByteWriter& w, const HandForceSample& h) {
  w.pod(h.step);
  w.pod(h.instrument);
  putVec3(w, h.force);
  putVec3(w, h.position);
}

HandForceSample getHandForce(ByteReader& b) {
  return {.step = b.pod<int>(),
          .instrument = b.pod<int>(),
          .force = getVec3(b),
          .position = getVec3(b)};
}

bool writeAll(int fd, const char* p, size_t n) {
  while (n > 0) {
    const ssize_t k = ::write(fd, p, n);
    if (k < 0 && errno == EINTR) continue;
    if (k <= 0) return false;
    p += k;
    n -= size_t(k);
  }
  return true;
}

RunRecord failedRecord(const ModelInfo& info, const ParamValues& params, const Scene& scene,
                       const RunOptions& options, const std::string& why) {
  RunRecord rec = newRunRecord(info, params, scene, options);
  rec.status = RunStatus::Failed;
  rec.message = why;
  assessValidity(scene, rec);
  return rec;
}

}  // namespace

std::vector<char> serializeRunRecord(const RunRecord& r) {
  ByteWriter w;
  w.string("deformbench.run_record/1");
  w.string(r.plugin);
  w.string(r.model);
  w.string(r.label);
  w.string(r.jsonPath);
  w.pod(static_cast<int>(r.isReference));
  w.string(r.params.dump());
  w.pod(static_cast<int>(r.status));
  w.string(r.message);
  putStrings(w, r.notes);
  w.string(r.calibration);
  putMap(w, r.counts);
  w.pod(r.precomputeS);
  w.pod(r.steps);
  w.pod(r.plannedSteps);
  w.pod(r.solvedSteps);
  w.pod(static_cast<long long>(r.stepMs.size()));
  for (double v : r.stepMs) w.pod(v);
  for (double v : {r.stepStats.median, r.stepStats.p95, r.stepStats.max, r.stepStats.mean})
    w.pod(v);  // field by field: the struct's padding is not data
  w.pod(r.stepStats.samples);
  putMap(w, r.phaseMs);
  putMap(w, r.numeric);
  w.pod(r.fixedNodes);
  putList(w, r.emptyGrasps, [&](int v) { w.pod(v); });
  w.pod(r.graspResidual);
  w.pod(r.graspTravel);
  w.pod(static_cast<int>(r.settledAt.has_value()));
  w.pod(r.settledAt.value_or(0.0));
  w.pod(static_cast<int>(r.equilibrium));
  w.pod(static_cast<int>(r.valid));
  w.string(r.invalidReason);
  w.pod(r.peakDisplacement);
  w.pod(r.motionFloor);
  w.pod(r.fixedDrift);
  w.pod(static_cast<int>(r.fixedRegion));
  w.pod(r.prescribedMotion);
  putList(w, r.cacheEvents, [&](const Cache::Event& e) { putCacheEvent(w, e); });
  w.matrix(r.finalSurface);
  w.matrix(r.finalFaces);
  putSnapshots(w, r.compared);
  putSnapshots(w, r.series);
  putList(w, r.graspForces, [&](const GraspForceSample& g) { putGraspForce(w, g); });
  putStrings(w, r.worlds);
  putStrings(w, r.instruments);
  putList(w, r.handForces, [&](const HandForceSample& h) { putHandForce(w, h); });
  w.pod(r.dt);
  putList(w, r.objectsFinal, [&](const Vec3& p) { putVec3(w, p); });
  w.pod(r.contactPairs);
  w.pod(r.contacts);
  w.string(r.markerStatus);
  w.string(r.markerReason);
  // Not carried (runModel() does not fill them): error, referenceModel, referenceValid and
  // referenceInvalidReason (markReferenceValidity() sets them after every run) and the output
  // files.
  return std::move(w.bytes());
}

RunRecord deserializeRunRecord(const std::vector<char>& bytes) {
  ByteReader b(bytes);
  if (b.string() != "deformbench.run_record/1")
    throw std::runtime_error("run record: unknown format");
  RunRecord r;
  r.plugin = b.string();
  r.model = b.string();
  r.label = b.string();
  r.jsonPath = b.string();
  r.isReference = b.pod<int>() != 0;
  r.params = nlohmann::json::parse(b.string());
  const int status = b.pod<int>();
  if (status < 0 || status > static_cast<int>(RunStatus::Failed))
    throw std::runtime_error("run record: bad status");
  r.status = static_cast<RunStatus>(status);
  r.message = b.string();
  r.notes = getStrings(b);
  r.calibration = b.string();
  getMap(b, r.counts);
  r.precomputeS = b.pod<double>();
  r.steps = b.pod<int>();
  r.plannedSteps = b.pod<int>();
  r.solvedSteps = b.pod<int>();
  {
    const long long n = b.pod<long long>();
    if (n < 0 || size_t(n) > bytes.size()) throw std::runtime_error("run record: bad size");
    r.stepMs.resize(size_t(n));
    for (double& v : r.stepMs) v = b.pod<double>();
  }
  for (double* v : {&r.stepStats.median, &r.stepStats.p95, &r.stepStats.max, &r.stepStats.mean})
    *v = b.pod<double>();
  r.stepStats.samples = b.pod<int>();
  getMap(b, r.phaseMs);
  getMap(b, r.numeric);
  r.fixedNodes = b.pod<int>();
  r.emptyGrasps = getList<int>(b, [&] { return b.pod<int>(); });
  r.graspResidual = b.pod<double>();
  r.graspTravel = b.pod<double>();
  const bool settled = b.pod<int>() != 0;
  const double at = b.pod<double>();
  if (settled) r.settledAt = at;
  r.equilibrium = b.pod<int>() != 0;
  r.valid = b.pod<int>() != 0;
  r.invalidReason = b.string();
  r.peakDisplacement = b.pod<double>();
  r.motionFloor = b.pod<double>();
  r.fixedDrift = b.pod<double>();
  r.fixedRegion = b.pod<int>() != 0;
  r.prescribedMotion = b.pod<double>();
  r.cacheEvents = getList<Cache::Event>(b, [&] { return getCacheEvent(b); });
  b.matrix(r.finalSurface);
  b.matrix(r.finalFaces);
  r.compared = getSnapshots(b);
  r.series = getSnapshots(b);
  r.graspForces = getList<GraspForceSample>(b, [&] { return getGraspForce(b); });
  r.worlds = getStrings(b);
  r.instruments = getStrings(b);
  r.handForces = getList<HandForceSample>(b, [&] { return getHandForce(b); });
  r.dt = b.pod<Real>();
  r.objectsFinal = getList<Vec3>(b, [&] { return getVec3(b); });
  r.contactPairs = b.pod<long long>();
  r.contacts = b.pod<long long>();
  r.markerStatus = b.string();
  r.markerReason = b.string();
  if (!b.atEnd()) throw std::runtime_error("run record: trailing bytes");
  return r;
}

RunRecord runModelIsolated(const ModelInfo& info, const ParamValues& params, const Scene& scene,
                           const Organ& organ, Cache& cache, const RunOptions& options) {
  int fds[2];
  if (::pipe2(fds, O_CLOEXEC) != 0)
    return failedRecord(info, params, scene, options,
                        std::string("cannot isolate the run: pipe: ") + std::strerror(errno));
  // Output buffered now would be written twice (by the parent and by the child).
  std::cout.flush();
  std::cerr.flush();
  std::fflush(nullptr);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0) {
    const int err = errno;
    ::close(fds[0]);
    ::close(fds[1]);
    return failedRecord(info, params, scene, options,
                        std::string("cannot isolate the run: fork: ") + std::strerror(err));
  }
  if (pid == 0) {
    // The child: the run, its record into the pipe, and out without the parent's exit handlers
    // (they belong to the parent: temporary folders, MPI, open output files).
    ::close(fds[0]);
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) ::_exit(127);
    int code = 0;
    try {
      const RunRecord rec = runModel(info, params, scene, organ, cache, options);
      const std::vector<char> bytes = serializeRunRecord(rec);
      const unsigned long long n = bytes.size();
      if (!writeAll(fds[1], reinterpret_cast<const char*>(&n), sizeof n) ||
          !writeAll(fds[1], bytes.data(), bytes.size()))
        code = 4;
    } catch (...) {
      code = 5;
    }
    std::cout.flush();
    std::cerr.flush();
    std::fflush(nullptr);
    ::_exit(code);
  }
  ::close(fds[1]);
  std::vector<char> bytes;
  {
    char buf[1 << 16];
    for (;;) {
      const ssize_t k = ::read(fds[0], buf, sizeof buf);
      if (k < 0 && errno == EINTR) continue;
      if (k <= 0) break;
      bytes.insert(bytes.end(), buf, buf + k);
    }
  }
  ::close(fds[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (WIFSIGNALED(status))
    return failedRecord(info, params, scene, options, signalText(WTERMSIG(status)));
  if (!WIFEXITED(status) || WEXITSTATUS(status) != 0)
    return failedRecord(info, params, scene, options,
                        "the run's process exited with code " +
                            std::to_string(WIFEXITED(status) ? WEXITSTATUS(status) : -1) +
                            " before it reported");
  unsigned long long n = 0;
  if (bytes.size() >= sizeof n) std::memcpy(&n, bytes.data(), sizeof n);
  if (bytes.size() < sizeof n || bytes.size() - sizeof n != n)
    return failedRecord(info, params, scene, options,
                        "the run's process sent an incomplete record");
  try {
    return deserializeRunRecord(std::vector<char>(bytes.begin() + sizeof n, bytes.end()));
  } catch (const std::exception& e) {
    return failedRecord(info, params, scene, options,
                        std::string("the run's process sent an unreadable record: ") + e.what());
  }
}

}  // namespace deform::harness
