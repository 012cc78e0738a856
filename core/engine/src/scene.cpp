// Scene files: strict parsing and validation (DESIGN.md "Scene file") and parameter resolution
// against a model's declarations. The JSON helpers: scene_json.h; loading the organ: organ.cpp.
#include "scene_json.h"

#include <deform/engine/interaction.h>
#include <deform/engine/scene.h>
#include <deform/geometry/mesh_check.h>
#include <deform/geometry/mesh_io.h>
#include <deform/geometry/phantom.h>
#include <deform/sdk/cache.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <set>
#include <sstream>

namespace deform {

namespace {

/// Longest model label accepted (its run folder is a file name, at most 255 bytes).
constexpr size_t kMaxLabelChars = 200;

namespace fs = std::filesystem;
using nlohmann::json;
using scene_json::Ctx;
using scene_json::didYouMean;
using scene_json::num;
using scene_json::ObjectReader;
using scene_json::typeName;

/// Keyframes; jaws allowed only for graspers. Missing "jaw" keeps the previous frame's state.
std::vector<KeyFrame> parseKeyFrames(const Ctx& c, const json& j, const std::string& path,
                                     bool allowJaw) {
  c.array(j, path);
  if (j.empty()) c.fail(path, "needs at least one keyframe");
  std::vector<KeyFrame> frames;
  bool closed = false;
  for (size_t i = 0; i < j.size(); ++i) {
    const std::string p = path + "/" + std::to_string(i);
    std::vector<std::string> keys = {"t", "pos"};
    if (allowJaw) keys.push_back("jaw");
    ObjectReader r(j[i], p, c.file, keys);
    KeyFrame k;
    k.t = c.number(r.required("t"), r.child("t"));
    if (k.t < 0) c.fail(r.child("t"), "must be >= 0, got " + num(k.t));
    if (!frames.empty() && !(k.t > frames.back().t)) {
      c.fail(r.child("t"), "keyframe times must be strictly increasing, got " + num(k.t) +
                               " after " + num(frames.back().t));
    }
    k.pos = c.vec3(r.required("pos"), r.child("pos"));
    if (const json* jaw = r.optional("jaw")) {
      const std::string s = c.string(*jaw, r.child("jaw"));
      if (s == "open") {
        closed = false;
      } else if (s == "closed") {
        closed = true;
      } else {
        c.fail(r.child("jaw"), "expected \"open\" or \"closed\", got \"" + s + "\"");
      }
    }
    k.jawClosed = closed;
    frames.push_back(k);
  }
  return frames;
}

ModelSpec parseModelSpec(const Ctx& c, const json& j, const std::string& path) {
  ObjectReader r(j, path, c.file, {"plugin", "model", "label", "params"});
  ModelSpec m;
  m.jsonPath = path;
  m.plugin = c.string(r.required("plugin"), r.child("plugin"));
  const auto nameOk = [](const std::string& s) {
    return !s.empty() && std::all_of(s.begin(), s.end(), [](char ch) {
      return std::isalnum(static_cast<unsigned char>(ch)) || ch == '_' || ch == '-';
    });
  };
  if (!nameOk(m.plugin))
    c.fail(r.child("plugin"),
           "plugin names are letters, digits, '_' and '-', got \"" + m.plugin + "\"");
  m.model = m.plugin;
  if (const json* v = r.optional("model")) {
    m.model = c.string(*v, r.child("model"));
    if (m.model.empty()) c.fail(r.child("model"), "must not be empty");
  }
  if (const json* v = r.optional("label")) {
    m.label = c.string(*v, r.child("label"));
    if (m.label.empty()) c.fail(r.child("label"), "must not be empty");
    // A label names the run's folder (a file name: 255 bytes at most) and a table row.
    if (m.label.size() > kMaxLabelChars)
      c.fail(r.child("label"), "longer than " + std::to_string(kMaxLabelChars) + " characters (" +
                                   std::to_string(m.label.size()) + ")");
  }
  if (const json* v = r.optional("params")) {
    if (!v->is_object()) c.fail(r.child("params"), "expected an object, got " + typeName(*v));
    m.params = *v;
  }
  return m;
}

/// "axes": a non-empty subset of "xyz" as bits (1 x, 2 y, 4 z).
int parseAxes(const Ctx& c, const json& j, const std::string& path) {
  const std::string s = c.string(j, path);
  int axes = 0;
  for (char ch : s) {
    const int bit = ch == 'x' ? 1 : ch == 'y' ? 2 : ch == 'z' ? 4 : 0;
    if (!bit) c.fail(path, "expected letters of \"xyz\" (the axes held), got \"" + s + "\"");
    if (axes & bit) c.fail(path, "axis '" + std::string(1, ch) + "' given twice in \"" + s + "\"");
    axes |= bit;
  }
  if (!axes) c.fail(path, "must name at least one axis (\"x\", \"yz\", \"xyz\", ...)");
  return axes;
}

/// One fixed region object, merged into f: "box"/"boxes" pinned fully, or held along "axes" only
/// (roller supports), and "vertices" pinned fully.
void parseFixedObject(const Ctx& c, const json& j, const std::string& path, FixedRegion& f) {
  ObjectReader r(j, path, c.file, {"box", "boxes", "vertices", "axes"});
  int axes = 7;
  if (const json* v = r.optional("axes")) {
    axes = parseAxes(c, *v, r.child("axes"));
    if (!r.has("box") && !r.has("boxes"))
      c.fail(r.child("axes"), "applies to \"box\" or \"boxes\", and this region has neither");
    if (axes != 7 && r.has("vertices"))
      c.fail(r.child("vertices"),
             "listed vertices are pinned fully; give them in a region without \"axes\"");
  }
  const auto add = [&](const Box& b) {
    if (axes == 7)
      f.boxes.push_back(b);
    else
      f.rollers.push_back({b, axes});
  };
  if (const json* v = r.optional("box")) add(c.box(*v, r.child("box")));
  if (const json* v = r.optional("boxes")) {
    c.array(*v, r.child("boxes"));
    for (size_t i = 0; i < v->size(); ++i)
      add(c.box((*v)[i], r.child("boxes") + "/" + std::to_string(i)));
  }
  if (const json* v = r.optional("vertices")) {
    c.array(*v, r.child("vertices"));
    for (size_t i = 0; i < v->size(); ++i) {
      const std::string p = r.child("vertices") + "/" + std::to_string(i);
      const long long idx = c.integer((*v)[i], p);
      if (idx < 0 || idx > 2147483647LL) c.fail(p, "vertex index must be >= 0, got " + num(idx));
      f.surfaceVertices.push_back(static_cast<int>(idx));
    }
  }
}

/// "fixed": one region object, or a list of them (e.g. a clamp and two roller faces).
FixedRegion parseFixed(const Ctx& c, const json& j, const std::string& path) {
  FixedRegion f;
  if (j.is_array()) {
    for (size_t i = 0; i < j.size(); ++i)
      parseFixedObject(c, j[i], path + "/" + std::to_string(i), f);
  } else {
    parseFixedObject(c, j, path, f);
  }
  return f;
}

OrganSpec parseOrgan(const Ctx& c, const json& j, const std::string& path) {
  ObjectReader r(j, path, c.file, {"mesh", "scale", "resolution", "repair", "material", "fixed"});
  OrganSpec o;
  o.mesh = c.string(r.required("mesh"), r.child("mesh"));
  if (o.mesh.empty()) c.fail(r.child("mesh"), "must not be empty");
  const bool phantom = o.mesh.rfind("phantom:", 0) == 0;
  if (phantom) {
    const std::string name = o.mesh.substr(8);
    const auto names = phantomNames();
    if (std::find(names.begin(), names.end(), name) == names.end()) {
      std::string known;
      for (const auto& n : names) known += (known.empty() ? "" : ", ") + n;
      c.fail(r.child("mesh"), "unknown phantom '" + name + "' (known: " + known + ")");
    }
  } else if (!c.file.empty() && fs::path(o.mesh).is_relative()) {
    o.mesh = (fs::path(c.file).parent_path() / o.mesh).lexically_normal().string();
  }
  if (const json* v = r.optional("scale")) o.scale = c.positive(*v, r.child("scale"));
  if (const json* v = r.optional("resolution")) {
    if (!phantom) c.fail(r.child("resolution"), "applies only to phantom meshes (phantom:NAME)");
    o.resolution = c.positive(*v, r.child("resolution"));
  }
  if (const json* v = r.optional("repair")) o.repair = c.boolean(*v, r.child("repair"));
  if (const json* v = r.optional("material")) {
    const std::string mp = r.child("material");
    ObjectReader m(*v, mp, c.file, {"young", "poisson", "density"});
    if (const json* x = m.optional("young")) o.material.young = c.positive(*x, m.child("young"));
    if (const json* x = m.optional("poisson")) {
      const double nu = c.number(*x, m.child("poisson"));
      if (!(nu > -1.0 && nu < 0.5))
        c.fail(m.child("poisson"), "must be in (-1, 0.5), got " + num(nu));
      o.material.poisson = nu;
    }
    if (const json* x = m.optional("density"))
      o.material.density = c.positive(*x, m.child("density"));
  }
  if (const json* v = r.optional("fixed")) o.fixed = parseFixed(c, *v, r.child("fixed"));
  return o;
}

CouplingParams parseCoupling(const Ctx& c, const ObjectReader& r, CouplingParams p) {
  if (const json* v = r.optional("stiffness")) p.stiffness = c.positive(*v, r.child("stiffness"));
  if (const json* v = r.optional("damping")) {
    p.damping = c.number(*v, r.child("damping"));
    if (p.damping < 0) c.fail(r.child("damping"), "must be >= 0, got " + num(p.damping));
  }
  return p;
}

/// An optional list of the scene (v: nullptr when absent) at path: each element read by
/// parse(c, element, path + "/" + index) and appended to out, in order.
template <class Parse, class T>
void appendList(const Ctx& c, const json* v, const std::string& path, Parse parse,
                std::vector<T>& out) {
  if (!v) return;
  c.array(*v, path);
  for (size_t i = 0; i < v->size(); ++i)
    out.push_back(parse(c, (*v)[i], path + "/" + std::to_string(i)));
}

ToolSpec parseTool(const Ctx& c, const json& j, const std::string& path) {
  ObjectReader r(j, path, c.file, {"type", "radius", "trajectory", "shaft", "dynamics"});
  ToolSpec t;
  const std::string type = c.string(r.required("type"), r.child("type"));
  if (type == "grasper") {
    t.type = ToolType::Grasper;
  } else if (type == "probe") {
    t.type = ToolType::Probe;
  } else {
    c.fail(r.child("type"), "expected \"grasper\" or \"probe\", got \"" + type + "\"");
  }
  if (const json* v = r.optional("radius")) t.radius = c.positive(*v, r.child("radius"));
  t.trajectory = parseKeyFrames(c, r.required("trajectory"), r.child("trajectory"),
                                t.type == ToolType::Grasper);
  if (const json* v = r.optional("shaft")) {
    if (t.type != ToolType::Probe) c.fail(r.child("shaft"), "applies only to probes");
    ObjectReader sr(*v, r.child("shaft"), c.file, {"length", "radius", "axis"});
    if (const json* x = sr.optional("length")) {
      t.shaftLength = c.number(*x, sr.child("length"));
      if (t.shaftLength < 0) c.fail(sr.child("length"), "must be >= 0, got " + num(t.shaftLength));
    }
    if (const json* x = sr.optional("radius")) t.shaftRadius = c.positive(*x, sr.child("radius"));
    if (const json* x = sr.optional("axis")) {
      t.shaftAxis = c.vec3(*x, sr.child("axis"));
      if (!(t.shaftAxis.norm() > 0)) c.fail(sr.child("axis"), "must not be the zero vector");
      t.shaftAxis.normalize();
    }
  }
  if (const json* v = r.optional("dynamics")) {
    std::vector<std::string> keys = {"mass", "stiffness", "damping"};
    if (t.type == ToolType::Grasper) {
      keys.push_back("jaw_length");
      keys.push_back("shaft_length");
    }
    ObjectReader dr(*v, r.child("dynamics"), c.file, keys);
    ToolDynamics d;
    if (const json* x = dr.optional("mass")) d.mass = c.positive(*x, dr.child("mass"));
    if (const json* x = dr.optional("jaw_length"))
      d.jawLength = c.positive(*x, dr.child("jaw_length"));
    if (const json* x = dr.optional("shaft_length"))
      d.shaftLength = c.positive(*x, dr.child("shaft_length"));
    d.coupling = parseCoupling(c, dr, d.coupling);
    t.dynamics = d;
  }
  return t;
}

ObjectSpec parseObject(const Ctx& c, const json& j, const std::string& path) {
  ObjectReader r(j, path, c.file,
                 {"shape", "radius", "size", "mass", "pos", "trajectory", "stiffness", "damping"});
  ObjectSpec o;
  o.shapeName = c.string(r.required("shape"), r.child("shape"));
  ShapePrimitive p;
  if (o.shapeName == "sphere") {
    p.kind = ShapePrimitive::Kind::Sphere;
    p.radius = c.positive(r.required("radius"), r.child("radius"));
    if (r.has("size")) c.fail(r.child("size"), "applies only to boxes (spheres take \"radius\")");
  } else if (o.shapeName == "box") {
    p.kind = ShapePrimitive::Kind::Box;
    const Vec3 size = c.vec3(r.required("size"), r.child("size"));
    for (int i = 0; i < 3; ++i)
      if (!(size[i] > 0)) c.fail(r.child("size") + "/" + std::to_string(i), "must be > 0");
    p.halfExtents = 0.5 * size;
    if (r.has("radius")) c.fail(r.child("radius"), "applies only to spheres (boxes take \"size\")");
  } else {
    c.fail(r.child("shape"), "expected \"sphere\" or \"box\", got \"" + o.shapeName + "\"");
  }
  o.shape.parts.push_back(p);
  o.mass = c.positive(r.required("mass"), r.child("mass"));
  o.pos = c.vec3(r.required("pos"), r.child("pos"));
  if (const json* v = r.optional("trajectory"))
    o.trajectory = parseKeyFrames(c, *v, r.child("trajectory"), false);
  o.coupling = parseCoupling(c, r, o.coupling);
  return o;
}

ContactParams parseContact(const Ctx& c, const json& j, const std::string& path) {
  ObjectReader r(j, path, c.file,
                 {"thickness", "passes", "method", "stiffness", "damping", "friction"});
  ContactParams p;
  if (const json* v = r.optional("thickness")) p.thickness = c.positive(*v, r.child("thickness"));
  if (const json* v = r.optional("passes")) {
    const long long n = c.integer(*v, r.child("passes"));
    if (n < 1 || n > 100) c.fail(r.child("passes"), "must be in [1, 100], got " + num(double(n)));
    p.passes = static_cast<int>(n);
  }
  if (const json* v = r.optional("method")) {
    const std::string m = c.string(*v, r.child("method"));
    if (m == "projection")
      p.method = ContactMethod::Projection;
    else if (m == "penalty")
      p.method = ContactMethod::Penalty;
    else
      c.fail(r.child("method"), "expected \"projection\" or \"penalty\", got \"" + m + "\"");
  }
  const bool penalty = p.method == ContactMethod::Penalty;
  if (const json* v = r.optional("stiffness")) {
    if (!penalty) c.fail(r.child("stiffness"), "applies only to \"method\": \"penalty\"");
    p.stiffness = c.positive(*v, r.child("stiffness"));
  }
  if (const json* v = r.optional("damping")) {
    if (!penalty) c.fail(r.child("damping"), "applies only to \"method\": \"penalty\"");
    p.damping = c.number(*v, r.child("damping"));
    if (p.damping < 0) c.fail(r.child("damping"), "must be >= 0, got " + num(p.damping));
  }
  if (const json* v = r.optional("friction")) {
    p.friction = c.number(*v, r.child("friction"));
    if (p.friction < 0) c.fail(r.child("friction"), "must be >= 0, got " + num(p.friction));
  }
  return p;
}

LoadSpec parseLoad(const Ctx& c, const json& j, const std::string& path) {
  if (!j.is_object()) c.fail(path, "expected an object, got " + typeName(j));
  if (!j.contains("type")) c.fail(path + "/type", "required key is missing");
  const std::string type = c.string(j.at("type"), path + "/type");
  LoadSpec l;
  std::vector<std::string> keys;
  if (type == "point_force") {
    l.type = LoadType::PointForce;
    keys = {"type", "at", "force", "radius", "start", "end"};
  } else if (type == "pin_head") {
    l.type = LoadType::PinHead;
    keys = {"type", "at", "stiffness", "path", "radius", "start", "end"};
  } else if (type == "traction") {
    l.type = LoadType::Traction;
    keys = {"type", "region", "force", "start", "end"};
  } else {
    c.fail(path + "/type",
           "expected \"point_force\", \"pin_head\" or \"traction\", got \"" + type + "\"");
  }
  ObjectReader r(j, path, c.file, keys);
  if (l.type == LoadType::Traction) {
    ObjectReader region(r.required("region"), r.child("region"), c.file, {"box"});
    l.region = c.box(region.required("box"), region.child("box"));
    l.at = l.region.center();
    l.force = c.vec3(r.required("force"), r.child("force"));
  } else {
    l.at = c.vec3(r.required("at"), r.child("at"));
  }
  if (l.type == LoadType::Traction) {
    // force read above
  } else if (l.type == LoadType::PointForce) {
    l.force = c.vec3(r.required("force"), r.child("force"));
  } else {
    l.stiffness = c.positive(r.required("stiffness"), r.child("stiffness"));
    l.path = parseKeyFrames(c, r.required("path"), r.child("path"), false);
  }
  if (const json* v = r.optional("radius")) l.radius = c.positive(*v, r.child("radius"));
  if (const json* v = r.optional("start")) {
    l.start = c.number(*v, r.child("start"));
    if (l.start < 0) c.fail(r.child("start"), "must be >= 0, got " + num(l.start));
  }
  if (const json* v = r.optional("end")) {
    l.end = c.number(*v, r.child("end"));
    if (!(l.end > l.start))
      c.fail(r.child("end"), "must be > start (" + num(l.start) + "), got " + num(l.end));
  }
  return l;
}

PlateSpec parsePlate(const Ctx& c, const json& j, const std::string& path) {
  ObjectReader r(j, path, c.file, {"region", "contact", "normal", "trajectory"});
  PlateSpec p;
  ObjectReader region(r.required("region"), r.child("region"), c.file, {"box"});
  p.region = c.box(region.required("box"), region.child("box"));
  if (const json* v = r.optional("contact")) {
    const std::string s = c.string(*v, r.child("contact"));
    if (s == "sliding")
      p.contact = PlateContact::Sliding;
    else if (s != "bonded")
      c.fail(r.child("contact"), "expected \"bonded\" or \"sliding\", got \"" + s + "\"");
  }
  const std::string tp = r.child("trajectory");
  const json& frames = c.array(r.required("trajectory"), tp);
  if (frames.empty()) c.fail(tp, "needs at least one keyframe");
  for (size_t i = 0; i < frames.size(); ++i) {
    const std::string fp = tp + "/" + std::to_string(i);
    ObjectReader f(frames[i], fp, c.file, {"t", "offset"});
    KeyFrame k;
    k.t = c.number(f.required("t"), f.child("t"));
    if (k.t < 0) c.fail(f.child("t"), "must be >= 0, got " + num(k.t));
    if (!p.trajectory.empty() && !(k.t > p.trajectory.back().t))
      c.fail(f.child("t"), "keyframe times must be strictly increasing, got " + num(k.t) +
                               " after " + num(p.trajectory.back().t));
    k.pos = c.vec3(f.required("offset"), f.child("offset"));
    p.trajectory.push_back(k);
  }
  // The normal of a sliding plate: given, or the direction of the trajectory's largest offset;
  // a coordinate axis for now (the models hold single coordinates).
  const std::string np = r.child("normal");
  if (const json* v = r.optional("normal")) {
    if (p.contact != PlateContact::Sliding)
      c.fail(np, "only a sliding plate has a normal (\"contact\": \"sliding\")");
    p.normal = c.vec3(*v, np);
    if (!(p.normal.norm() > 0)) c.fail(np, "must be a non-zero vector");
  } else if (p.contact == PlateContact::Sliding) {
    for (const KeyFrame& k : p.trajectory)
      if (k.pos.norm() > p.normal.norm()) p.normal = k.pos;
    if (!(p.normal.norm() > 0))
      c.fail(np, "a sliding plate whose trajectory never moves needs a \"normal\"");
  }
  if (p.contact == PlateContact::Sliding) {
    p.normal.normalize();
    int axis = -1;
    for (int a = 0; a < 3; ++a)
      if (std::abs(p.normal[a]) > 1 - 1e-9) axis = a;
    if (axis < 0)
      c.fail(np, "a sliding plate's normal must lie along x, y or z for now, got [" +
                     num(p.normal.x()) + ", " + num(p.normal.y()) + ", " + num(p.normal.z()) + "]" +
                     (r.has("normal") ? "" : " (the direction of its largest offset)"));
    const Real sign = p.normal[axis] > 0 ? 1.0 : -1.0;
    p.normal = Vec3::Zero();
    p.normal[axis] = sign;
  }
  return p;
}

/// Points as [[x, y, z], ...] (at least one), or read from a text file: one point per line,
/// three numbers separated by commas or white space; blank lines and lines starting with '#'
/// are skipped. The file is resolved relative to the scene file.
MatX3 parsePoints(const Ctx& c, const ObjectReader& r, const std::string& what) {
  const bool hasPoints = r.has("points"), hasFile = r.has("file");
  if (hasPoints == hasFile)
    c.fail(r.path(), "needs exactly one of \"points\" and \"file\" (the " + what + ")");
  std::vector<Vec3> pts;
  if (hasPoints) {
    const std::string pp = r.child("points");
    const json& a = c.array(r.required("points"), pp);
    for (size_t i = 0; i < a.size(); ++i) pts.push_back(c.vec3(a[i], pp + "/" + std::to_string(i)));
    if (pts.empty()) c.fail(pp, "needs at least one point");
  } else {
    const std::string name = c.string(r.required("file"), r.child("file"));
    fs::path path(name);
    if (path.is_relative() && !c.file.empty()) path = fs::path(c.file).parent_path() / path;
    std::ifstream in(path);
    if (!in) c.fail(r.child("file"), "cannot open the points file " + path.string());
    std::string line;
    for (int n = 1; std::getline(in, line); ++n) {
      std::replace(line.begin(), line.end(), ',', ' ');
      std::istringstream ls(line);
      std::string first;
      if (!(ls >> first) || first[0] == '#') continue;
      ls.clear();
      ls.str(line);
      Vec3 v;
      std::string rest;
      if (!(ls >> v.x() >> v.y() >> v.z()) || (ls >> rest) || !v.allFinite())
        throw InputError(path.string(), "line " + std::to_string(n),
                         "expected three numbers x, y, z (m), got \"" + line + "\"");
      pts.push_back(v);
    }
    if (pts.empty()) c.fail(r.child("file"), path.string() + " holds no point");
  }
  MatX3 m(Eigen::Index(pts.size()), 3);
  for (size_t i = 0; i < pts.size(); ++i) m.row(Eigen::Index(i)) = pts[i].transpose();
  return m;
}

MarkerSpec parseMarkers(const Ctx& c, const json& j, const std::string& path) {
  ObjectReader r(j, path, c.file, {"points", "file", "measured"});
  MarkerSpec m;
  m.points = parsePoints(c, r, "markers' rest positions, m");
  if (const json* v = r.optional("measured")) {
    const std::string mp = r.child("measured");
    c.array(*v, mp);
    for (size_t i = 0; i < v->size(); ++i) {
      const std::string fp = mp + "/" + std::to_string(i);
      ObjectReader f((*v)[i], fp, c.file, {"t", "points", "file"});
      MarkerFrame frame;
      const json& t = f.required("t");
      if (t.is_string()) {
        if (t.get<std::string>() != "equilibrium")
          c.fail(f.child("t"),
                 "expected a time in s or \"equilibrium\", got \"" + t.get<std::string>() + "\"");
        frame.atEquilibrium = true;
      } else {
        frame.t = c.number(t, f.child("t"));
      }
      if (!m.measured.empty() && (frame.atEquilibrium || m.measured.back().atEquilibrium))
        c.fail(f.child("t"), "a frame measured at \"equilibrium\" must be the only one");
      if (!m.measured.empty() && !(frame.t > m.measured.back().t))
        c.fail(f.child("t"), "instants must be strictly increasing, got " + num(frame.t) +
                                 " after " + num(m.measured.back().t));
      frame.points = parsePoints(c, f, "measured positions, m");
      if (frame.points.rows() != m.points.rows())
        c.fail(fp, std::to_string(frame.points.rows()) + " measured positions for " +
                       std::to_string(m.points.rows()) + " markers");
      m.measured.push_back(std::move(frame));
    }
  }
  return m;
}

}  // namespace

int Scene::numSteps() const {
  return static_cast<int>(std::llround(duration / dt));
}

bool Scene::needsContact() const {
  return !objects.empty() || std::any_of(tools.begin(), tools.end(), [](const ToolSpec& t) {
    return t.type == ToolType::Probe;
  });
}

bool Scene::needsDynamics() const {
  return !objects.empty() || std::any_of(tools.begin(), tools.end(),
                                         [](const ToolSpec& t) { return t.dynamics.has_value(); });
}

Scene parseScene(const nlohmann::json& j, const std::string& file) {
  const Ctx c{file};
  ObjectReader r(
      j, "", file,
      {"name", "description", "organ", "gravity", "dt", "duration", "tools", "objects", "contact",
       "loads", "plates", "markers", "models", "reference", "samples", "compare_at", "output"});
  Scene s;
  s.file = file;
  if (const json* v = r.optional("name")) {
    s.name = c.string(*v, "/name");
    if (s.name.empty()) c.fail("/name", "must not be empty");
  } else {
    s.name = file.empty() ? "scene" : fs::path(file).stem().string();
  }
  if (const json* v = r.optional("description")) c.string(*v, "/description");
  s.organ = parseOrgan(c, r.required("organ"), "/organ");
  if (const json* v = r.optional("gravity")) s.gravity = c.vec3(*v, "/gravity");
  if (const json* v = r.optional("dt")) s.dt = c.positive(*v, "/dt");
  if (const json* v = r.optional("duration")) s.duration = c.positive(*v, "/duration");
  const double steps = std::round(s.duration / s.dt);
  if (steps < 1) {
    c.fail("/duration", "shorter than one time step (duration " + num(s.duration) + " s, dt " +
                            num(s.dt) + " s)");
  }
  if (steps > 1e9) c.fail("/duration", "more than 1e9 steps (" + num(steps) + ")");

  appendList(c, r.optional("tools"), "/tools", parseTool, s.tools);
  appendList(c, r.optional("objects"), "/objects", parseObject, s.objects);
  if (const json* v = r.optional("contact")) s.contact = parseContact(c, *v, "/contact");
  appendList(c, r.optional("loads"), "/loads", parseLoad, s.loads);
  appendList(c, r.optional("plates"), "/plates", parsePlate, s.plates);
  if (const json* v = r.optional("markers")) s.markers = parseMarkers(c, *v, "/markers");
  checkCouplingStability(s);
  const json& models = c.array(r.required("models"), "/models");
  if (models.empty()) c.fail("/models", "needs at least one model");
  std::set<std::string> labels;
  const auto checkLabel = [&](const ModelSpec& m) {
    if (!m.label.empty() && !labels.insert(m.label).second)
      c.fail(m.jsonPath + "/label", "duplicate label \"" + m.label + "\"");
  };
  for (size_t i = 0; i < models.size(); ++i) {
    s.models.push_back(parseModelSpec(c, models[i], "/models/" + std::to_string(i)));
    checkLabel(s.models.back());
  }
  if (const json* v = r.optional("reference")) {
    s.reference = parseModelSpec(c, *v, "/reference");
    checkLabel(*s.reference);
  }
  if (const json* v = r.optional("samples")) {
    ObjectReader sr(*v, "/samples", file, {"nearest"});
    if (const json* n = sr.optional("nearest")) {
      c.array(*n, "/samples/nearest");
      s.nearest.clear();
      for (size_t i = 0; i < n->size(); ++i) {
        const std::string p = "/samples/nearest/" + std::to_string(i);
        const long long k = c.integer((*n)[i], p);
        if (k < 1 || k > 100000000) c.fail(p, "must be >= 1, got " + num(double(k)));
        s.nearest.push_back(static_cast<int>(k));
      }
    }
  }
  if (const json* v = r.optional("compare_at"); v && v->is_string()) {
    const std::string str = c.string(*v, "/compare_at");
    if (str != "equilibrium")
      c.fail("/compare_at", "expected a list of instants or \"equilibrium\", got \"" + str + "\"");
    s.compareAtEquilibrium = true;
  } else if (v) {
    c.array(*v, "/compare_at");
    for (size_t i = 0; i < v->size(); ++i) {
      const std::string p = "/compare_at/" + std::to_string(i);
      const double t = c.number((*v)[i], p);
      if (!(t > 0) || t > s.duration + 0.5 * s.dt)
        c.fail(p, "must be in (0, duration = " + num(s.duration) + "], got " + num(t));
      if (!s.compareAt.empty() && !(t > s.compareAt.back()))
        c.fail(p, "instants must be strictly increasing, got " + num(t) + " after " +
                      num(s.compareAt.back()));
      s.compareAt.push_back(t);
    }
  }
  for (size_t i = 0; i < s.markers.measured.size(); ++i) {
    const std::string path = "/markers/measured/" + std::to_string(i) + "/t";
    if (s.markers.measured[i].atEquilibrium) {
      if (!s.compareAtEquilibrium)
        c.fail(path, "\"equilibrium\" needs \"compare_at\": \"equilibrium\"");
      continue;
    }
    if (s.compareAtEquilibrium)
      c.fail(path, "a scene compared at equilibrium takes one frame at \"t\": \"equilibrium\"");
    const Real t = s.markers.measured[i].t;
    const std::vector<Real> instants =
        s.compareAt.empty() ? std::vector<Real>{s.duration} : s.compareAt;
    const bool found = std::any_of(instants.begin(), instants.end(),
                                   [&](Real x) { return std::fabs(x - t) <= 0.5 * s.dt; });
    if (!found)
      c.fail(path, "must be one of the compared instants (compare_at, or the duration " +
                       num(s.duration) + " s without it), got " + num(t));
  }
  if (const json* v = r.optional("output")) {
    ObjectReader o(*v, "/output", file, {"surfaces"});
    if (const json* sv = o.optional("surfaces")) {
      const std::string str = c.string(*sv, "/output/surfaces");
      if (str == "final") {
        s.surfaces = SurfaceOutput::Final;
      } else if (str == "none") {
        s.surfaces = SurfaceOutput::None;
      } else if (str.rfind("every:", 0) == 0) {
        const std::string n = str.substr(6);
        int every = 0;
        const auto res = std::from_chars(n.data(), n.data() + n.size(), every);
        if (n.empty() || res.ec != std::errc() || res.ptr != n.data() + n.size() || every < 1)
          c.fail("/output/surfaces", "\"every:N\" needs an integer N >= 1, got \"" + str + "\"");
        s.surfaces = SurfaceOutput::Every;
        s.surfaceEvery = every;
      } else {
        c.fail("/output/surfaces",
               "expected \"final\", \"every:N\" or \"none\", got \"" + str + "\"");
      }
    }
  }
  return s;
}

Scene parseSceneFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "", "cannot open the scene file");
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (in.bad()) throw InputError(path, "", "cannot read the scene file");
  // JSON itself lets a key repeat (the last one wins); a scene must not, so a typo'd copy of
  // "dt" cannot silently override the first. Track the path while parsing to name the place.
  struct Frame {
    bool array = false;
    long index = -1;
    std::string key;
    std::set<std::string> keys;
  };
  std::vector<Frame> stack;
  const auto pathOf = [&stack]() {
    std::string p;
    for (const Frame& f : stack) p += "/" + (f.array ? std::to_string(f.index) : f.key);
    return p;
  };
  const json::parser_callback_t noDuplicates = [&](int, json::parse_event_t event, json& parsed) {
    switch (event) {
      case json::parse_event_t::object_start:
      case json::parse_event_t::array_start:
        if (!stack.empty() && stack.back().array) ++stack.back().index;
        stack.push_back(Frame{event == json::parse_event_t::array_start, -1, {}, {}});
        break;
      case json::parse_event_t::object_end:
      case json::parse_event_t::array_end:
        if (!stack.empty()) stack.pop_back();
        break;
      case json::parse_event_t::key: {
        Frame& f = stack.back();
        f.key = parsed.get<std::string>();
        if (!f.keys.insert(f.key).second)
          throw InputError(path, pathOf(), "duplicate key '" + f.key + "'");
        break;
      }
      case json::parse_event_t::value:
        if (!stack.empty() && stack.back().array) ++stack.back().index;
        break;
    }
    return true;
  };
  json j;
  try {
    j = json::parse(text, noDuplicates);
  } catch (const json::parse_error& e) {
    // nlohmann reports a byte offset (1-based, one past the offending character); turn it into
    // line and column, and keep only the explanation from its message.
    const size_t byte = std::min<size_t>(e.byte > 0 ? e.byte - 1 : 0, text.size());
    size_t line = 1, col = 1;
    for (size_t i = 0; i < byte; ++i) {
      if (text[i] == '\n') {
        ++line;
        col = 1;
      } else {
        ++col;
      }
    }
    std::string what = e.what();
    const size_t colon = what.find(": ", what.find("parse error"));
    if (colon != std::string::npos) what = what.substr(colon + 2);
    throw InputError(path, "line " + std::to_string(line) + ", column " + std::to_string(col),
                     "malformed JSON: " + what);
  } catch (const json::out_of_range& e) {
    // A number too large for a double (e.g. 1e999) is out_of_range.406, not a parse_error.
    std::string what = e.what();
    const size_t bracket = what.find("] ");
    if (bracket != std::string::npos) what = what.substr(bracket + 2);
    throw InputError(path, "", "malformed JSON: " + what);
  }
  Scene s = parseScene(j, path);
  s.sha256 = sha256Hex(text.data(), text.size());
  return s;
}

ParamValues resolveParams(const std::vector<ParamSpec>& specs, const nlohmann::json& given,
                          const std::string& file, const std::string& jsonPath) {
  const Ctx c{file};
  if (!given.is_null() && !given.is_object())
    c.fail(jsonPath, "expected an object, got " + typeName(given));
  ParamValues values = ParamValues::defaults(specs);
  if (given.is_null()) return values;
  // Named copies, not structured bindings: clang before 16 cannot capture those in a lambda.
  for (const auto& item : given.items()) {
    const std::string key = item.key();
    const json& v = item.value();
    const std::string p = jsonPath + "/" + key;
    const auto it =
        std::find_if(specs.begin(), specs.end(), [&](const ParamSpec& s) { return s.key == key; });
    if (it == specs.end()) {
      std::string known;
      std::vector<std::string> keys;
      for (const auto& s : specs) {
        known += (known.empty() ? "" : ", ") + s.key;
        keys.push_back(s.key);
      }
      c.fail(p, "unknown parameter '" + key + "' (" + didYouMean(key, keys) +
                    "declared: " + (known.empty() ? "none" : known) + ")");
    }
    const ParamSpec& spec = *it;
    const auto checkRange = [&](double x) {
      if (x < spec.min) c.fail(p, "must be >= " + num(spec.min) + ", got " + num(x));
      if (x > spec.max) c.fail(p, "must be <= " + num(spec.max) + ", got " + num(x));
    };
    switch (spec.type) {
      case ParamType::Real: {
        const double x = c.number(v, p);
        checkRange(x);
        values.set(key, x);
        break;
      }
      case ParamType::Int: {
        const long long x = c.integer(v, p);
        checkRange(double(x));
        values.set(key, x);
        break;
      }
      case ParamType::Bool:
        values.set(key, c.boolean(v, p));
        break;
      case ParamType::Choice: {
        const std::string x = c.string(v, p);
        if (std::find(spec.choices.begin(), spec.choices.end(), x) == spec.choices.end()) {
          std::string known;
          for (const auto& ch : spec.choices) known += (known.empty() ? "\"" : ", \"") + ch + "\"";
          c.fail(p, "expected one of " + known + ", got \"" + x + "\"");
        }
        values.set(key, x);
        break;
      }
    }
  }
  return values;
}

nlohmann::json paramsToJson(const ParamValues& values) {
  json j = json::object();
  for (const auto& kv : values.all()) {
    const std::string& key = kv.first;
    std::visit([&](const auto& x) { j[key] = x; }, kv.second);
  }
  return j;
}

namespace {

/// The type's name in the JSON of a parameter specification.
const char* paramTypeName(ParamType type) {
  // In ParamType's order.
  static constexpr const char* kNames[] = {"real", "int", "bool", "choice"};
  return kNames[static_cast<int>(type)];
}

}  // namespace

nlohmann::json paramSpecToJson(const ParamSpec& spec) {
  json j;
  j["key"] = spec.key;
  j["type"] = paramTypeName(spec.type);
  j["unit"] = spec.unit;
  std::visit([&](const auto& x) { j["default"] = x; }, spec.defaultValue);
  if (spec.type == ParamType::Real || spec.type == ParamType::Int) {
    // JSON has no infinity: an open end of the range is null.
    j["min"] = std::isfinite(spec.min) ? json(spec.min) : json(nullptr);
    j["max"] = std::isfinite(spec.max) ? json(spec.max) : json(nullptr);
    if (spec.type == ParamType::Int) {
      if (std::fabs(spec.min) < 9e18) j["min"] = static_cast<long long>(spec.min);
      if (std::fabs(spec.max) < 9e18) j["max"] = static_cast<long long>(spec.max);
    }
  }
  if (spec.type == ParamType::Choice) j["choices"] = spec.choices;
  j["description"] = spec.description;
  if (spec.calibratable) {
    j["calibrate"] = {
        {"min", spec.calibMin}, {"max", spec.calibMax}, {"scale", paramScaleName(spec.calibScale)}};
  }
  return j;
}

}  // namespace deform
