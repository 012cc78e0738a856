// truth-cube: the Truth Cube experiment (Kerdok et al. 2003) replayed. A silicone cube of 80 mm,
// bonded to a rigid base, compressed by a bonded rigid plate; 343 beads tracked by CT. Every
// model that maps interior markers is measured against the beads, after a rigid registration of
// each scan. Data: data/truth-cube/ (README.md there: source, license, frame).
#include "table_kit.h"

#include <deform/sdk/error.h>
#include <deform/sdk/registry.h>
#include <deform_harness/calibration.h>
#include <deform_harness/scripts.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <set>
#include <sstream>

#ifndef DEFORM_SOURCE_DIR
#define DEFORM_SOURCE_DIR ""
#endif

namespace deform::harness::tables {

namespace {

constexpr double kSide = 0.08;        ///< m, the cube's edge
constexpr double kBeadMargin = 0.01;  ///< m, from the base to the bottom bead layer
constexpr const char* kCalculix = "calculix";
/// reference_fem with the volumetric term per quadrature point, CalculiX's C3D10 formulation.
constexpr const char* kDisplacementLabel = "reference_fem(volumetric=displacement)";
/// The other models of the project: rows for them say why they have no bead figures.
const std::vector<std::string> kOtherModels = {
    "fem_hex", "hybrid_fem_pbd", "particle_bem",    "metaballs",
    "pbd",     "massspring",     "bullet_softbody", "bullet_deformable"};

}  // namespace

TruthCubeData readTruthCubeData(const std::string& file) {
  std::ifstream in(file);
  if (!in) throw InputError(file, "", "cannot open the Truth Cube data file");
  TruthCubeData d;
  d.file = file;
  std::string line, previous;
  bool header = false;
  int lineNo = 0;
  const auto cells = [](const std::string& s) {
    std::vector<std::string> out;
    std::stringstream ss(s);
    std::string c;
    while (std::getline(ss, c, ',')) {
      c.erase(0, c.find_first_not_of(" \t\r"));
      c.erase(c.find_last_not_of(" \t\r") + 1);
      out.push_back(c);
    }
    return out;
  };
  size_t levels = 0;
  while (std::getline(in, line)) {
    ++lineNo;
    const std::vector<std::string> c = cells(line);
    if (!header) {
      if (c.size() >= 6 && c[0] == "i" && c[1] == "j" && c[2] == "k") {
        header = true;
        if ((c.size() - 3) % 3 != 0 || c.size() < 9)
          throw InputError(file, "line " + std::to_string(lineNo),
                           "expected i, j, k and x, y, z column triples (rest and at least one "
                           "compression level), got " +
                               std::to_string(c.size()) + " columns");
        levels = (c.size() - 6) / 3;
        // The strains: the "N% strain" cells of the line above, in order.
        for (const std::string& p : cells(previous)) {
          const size_t pct = p.find('%');
          if (pct == std::string::npos) continue;
          try {
            d.strains.push_back(std::stod(p.substr(0, pct)) / 100);
          } catch (const std::exception&) {
            throw InputError(file, "line " + std::to_string(lineNo - 1),
                             "cannot read a strain from \"" + p + "\"");
          }
        }
        if (d.strains.size() != levels)
          throw InputError(file, "line " + std::to_string(lineNo - 1),
                           "expected one \"N% strain\" label per compression level (" +
                               std::to_string(levels) + "), found " +
                               std::to_string(d.strains.size()));
      }
      previous = line;
      continue;
    }
    if (c.empty() || (c.size() == 1 && c[0].empty())) continue;
    if (c.size() < 6 + 3 * levels)
      throw InputError(file, "line " + std::to_string(lineNo),
                       "expected " + std::to_string(6 + 3 * levels) + " numbers, got " +
                           std::to_string(c.size()));
    TruthCubeData::Bead b;
    try {
      for (int k = 0; k < 3; ++k) b.ijk[size_t(k)] = std::stoi(c[size_t(k)]);
      for (size_t l = 0; l <= levels; ++l) {
        Vec3 p;
        for (int k = 0; k < 3; ++k) p[k] = 1e-3 * std::stod(c[3 + 3 * l + size_t(k)]);
        b.positions.push_back(p);
      }
    } catch (const std::exception&) {
      throw InputError(file, "line " + std::to_string(lineNo),
                       "expected numbers, got \"" + line + "\"");
    }
    d.beads.push_back(b);
  }
  if (!header) throw InputError(file, "", "no \"i,j,k,x0,y0,z0,...\" header line");
  if (d.beads.empty()) throw InputError(file, "", "no bead rows after the header");
  return d;
}

MatX3 truthCubeSceneFrame(const TruthCubeData& d, int level) {
  // Scanner frame: -z up. The scene's: z up, a rotation of 180 degrees about x (y and z flip),
  // centred on the cube: x, y on the beads' mean; the base kBeadMargin below the bottom layer.
  Vec3 mean = Vec3::Zero();
  double bottom = 0;
  int nBottom = 0;
  int kMin = 1 << 30;
  for (const auto& b : d.beads) kMin = std::min(kMin, b.ijk[2]);
  for (const auto& b : d.beads) {
    mean += b.positions[0];
    if (b.ijk[2] == kMin) {
      bottom += b.positions[0].z();
      ++nBottom;
    }
  }
  mean /= double(d.beads.size());
  bottom /= std::max(nBottom, 1);
  // Scanner z of the centre: the base lies at bottom + margin (larger z is lower).
  const Vec3 centre(mean.x(), mean.y(), bottom + kBeadMargin - 0.5 * kSide);
  MatX3 out(Eigen::Index(d.beads.size()), 3);
  for (size_t i = 0; i < d.beads.size(); ++i) {
    const Vec3 p = d.beads[i].positions[size_t(level)] - centre;
    out.row(Eigen::Index(i)) = Vec3(p.x(), -p.y(), -p.z()).transpose();
  }
  return out;
}

TruthCubeFigures truthCubeFigures(const TruthCubeData& d, const MatX3& modelRest,
                                  const MatX3& model, int level, bool bottomLayer) {
  const MatX3 rest = truthCubeSceneFrame(d, 0), scan = truthCubeSceneFrame(d, level);
  const Eigen::Index n = rest.rows();
  const MatX3 um = model - modelRest, ub = scan - rest;
  TruthCubeFigures f;
  int kMin = 1 << 30, kMax = -(1 << 30), iMin = kMin, iMax = kMax, jMin = kMin, jMax = kMax;
  for (const auto& b : d.beads) {
    kMin = std::min(kMin, b.ijk[2]);
    kMax = std::max(kMax, b.ijk[2]);
    iMin = std::min(iMin, b.ijk[0]);
    iMax = std::max(iMax, b.ijk[0]);
    jMin = std::min(jMin, b.ijk[1]);
    jMax = std::max(jMax, b.ijk[1]);
  }
  // Registration: the translation that the least-squares fit (or the bottom layer's mean)
  // takes the measured displacements by.
  Vec3 shift = Vec3::Zero();
  int count = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    if (bottomLayer && d.beads[size_t(i)].ijk[2] != kMin) continue;
    shift += (um.row(i) - ub.row(i)).transpose();
    ++count;
  }
  shift /= std::max(count, 1);
  double sum2 = 0, measured2 = 0;
  std::map<int, std::pair<double, int>> layers;
  const Vec3 centre = rest.colwise().mean().transpose();
  double bulge = 0, measuredBulge = 0;
  int bulgeCount = 0;
  for (Eigen::Index i = 0; i < n; ++i) {
    const Vec3 a = um.row(i).transpose(), b = ub.row(i).transpose() + shift;
    const double e2 = (a - b).squaredNorm();
    sum2 += e2;
    measured2 += ub.row(i).squaredNorm();
    f.maxError = std::max(f.maxError, std::sqrt(e2));
    auto& layer = layers[d.beads[size_t(i)].ijk[2]];
    layer.first += e2;
    ++layer.second;
    // Outer columns (an extreme i or j): their outward lateral displacement, on each side they
    // face, in the middle layers (the top and bottom ones are held by the plate and the base).
    const auto& ijk = d.beads[size_t(i)].ijk;
    if (ijk[2] == kMin || ijk[2] == kMax) continue;
    for (int axis = 0; axis < 2; ++axis) {
      const int v = ijk[size_t(axis)];
      const bool outer = axis == 0 ? (v == iMin || v == iMax) : (v == jMin || v == jMax);
      if (!outer) continue;
      const double out = rest(i, axis) > centre[axis] ? 1.0 : -1.0;
      bulge += out * a[axis];
      measuredBulge += out * b[axis];
      ++bulgeCount;
    }
  }
  f.rms = std::sqrt(sum2 / double(n));
  f.measuredRms = std::sqrt(measured2 / double(n));
  for (const auto& [k, v] : layers) f.layerRms.push_back(std::sqrt(v.first / v.second));
  f.bulge = bulgeCount ? bulge / bulgeCount : std::nan("");
  f.measuredBulge = bulgeCount ? measuredBulge / bulgeCount : std::nan("");
  return f;
}

namespace {

std::string defaultDataFile() {
  return (fs::path(DEFORM_SOURCE_DIR) / "data" / "truth-cube" / "uniaxial_positions.csv").string();
}

ojson pointsJson(const MatX3& p) {
  ojson a = ojson::array();
  for (Eigen::Index i = 0; i < p.rows(); ++i) a.push_back({p(i, 0), p(i, 1), p(i, 2)});
  return a;
}

/// The compression scene: the phantom cube scaled to 80 mm, its bottom face bonded (fixed), its
/// top face bonded to a plate moved down by each level's strain times the height (one compared
/// instant per level, t = level), the beads as markers with their measured positions.
ojson truthCubeScene(const TruthCubeData& d, const std::vector<ojson>& models,
                     const std::string& contact) {
  const double h = 0.5 * kSide, e = 1e-6, m = h + 0.01;
  ojson j;
  j["name"] = "truth-cube";
  j["description"] =
      "Truth Cube (Kerdok et al. 2003): 80 mm silicone cube, E 15.3 kPa, nu 0.499, rho 980; "
      "base bonded, top plate " +
      contact + " and displacement-controlled; 343 beads as markers.";
  j["organ"] = {
      {"mesh", "phantom:cube"},
      {"scale", kSide / 0.1},
      {"material", {{"young", 15300}, {"poisson", 0.499}, {"density", 980}}},
      {"fixed", {{"box", ojson::array({vecJson(Vec3(-m, -m, -m)), vecJson(Vec3(m, m, -h + e))})}}}};
  j["gravity"] = vecJson(Vec3::Zero());
  j["dt"] = 1.0;
  const size_t levels = d.strains.size();
  j["duration"] = double(levels);
  ojson traj = ojson::array({{{"t", 0.0}, {"offset", vecJson(Vec3::Zero())}}});
  ojson compare = ojson::array();
  ojson measured = ojson::array();
  for (size_t l = 0; l < levels; ++l) {
    const double t = double(l + 1);
    traj.push_back({{"t", t}, {"offset", vecJson(Vec3(0, 0, -d.strains[l] * kSide))}});
    compare.push_back(t);
    measured.push_back({{"t", t}, {"points", pointsJson(truthCubeSceneFrame(d, int(l + 1)))}});
  }
  j["plates"] = ojson::array(
      {{{"region", {{"box", ojson::array({vecJson(Vec3(-m, -m, h - e)), vecJson(Vec3(m, m, m))})}}},
        {"contact", contact},
        {"trajectory", traj}}});
  j["markers"] = {{"points", pointsJson(truthCubeSceneFrame(d, 0))}, {"measured", measured}};
  j["models"] = models;
  j["compare_at"] = compare;
  j["output"] = {{"surfaces", "final"}};
  return j;
}

/// The compression scene for dynamic models at one level: the plate moves down over the first
/// second and holds; each model is compared once it settles (the duration is the cap).
ojson truthCubeDynamicScene(const TruthCubeData& d, size_t level, const std::vector<ojson>& models,
                            double duration, const std::string& contact) {
  ojson j = truthCubeScene(d, models, contact);
  j["name"] = "truth-cube-dynamic-" + std::to_string(level + 1);
  j["description"] = "Truth Cube, dynamic models: the plate moves down by " +
                     formatG(1e3 * d.strains[level] * kSide) +
                     " mm over 1 s and holds; compared at equilibrium.";
  j["dt"] = 1e-3;
  j["duration"] = duration;
  j["plates"][0]["trajectory"] =
      ojson::array({{{"t", 0.0}, {"offset", vecJson(Vec3::Zero())}},
                    {{"t", 1.0}, {"offset", vecJson(Vec3(0, 0, -d.strains[level] * kSide))}}});
  // The beads of this level, measured at the one compared instant: equilibrium.
  j["markers"]["measured"] = ojson::array(
      {{{"t", "equilibrium"}, {"points", pointsJson(truthCubeSceneFrame(d, int(level + 1)))}}});
  j["compare_at"] = "equilibrium";
  return j;
}

/// The quasi-static scene of one level alone: the plate moved to the level's strain in one
/// step, compared (and the beads measured) at t = 1.
ojson truthCubeStaticLevelScene(const TruthCubeData& d, size_t level,
                                const std::vector<ojson>& models, const std::string& contact) {
  ojson j = truthCubeScene(d, models, contact);
  j["name"] = "truth-cube-level-" + std::to_string(level + 1);
  j["duration"] = 1.0;
  j["plates"][0]["trajectory"] =
      ojson::array({{{"t", 0.0}, {"offset", vecJson(Vec3::Zero())}},
                    {{"t", 1.0}, {"offset", vecJson(Vec3(0, 0, -d.strains[level] * kSide))}}});
  j["compare_at"] = ojson::array({1.0});
  j["markers"]["measured"] =
      ojson::array({{{"t", 1.0}, {"points", pointsJson(truthCubeSceneFrame(d, int(level + 1)))}}});
  return j;
}

/// The reference's parameters in the table: quadratic Gmsh tets whose surface nodes are the
/// organ's vertices (refine_surface off: the plate and the base hold every surface node of
/// their faces, the midside nodes following).
ojson femParams(bool quick) {
  return {{"element_order", 2}, {"elements", quick ? 1000 : 6000}, {"refine_surface", false}};
}

double dynamicCap(bool quick) {
  return quick ? 3.0 : 5.0;
}

/// What the table reads of one run: at each compared instant with markers, their positions and
/// the force the tissue exerts on the plate along +z (N; NaN when the model reports none).
struct Readout {
  std::vector<MatX3> markers;
  std::vector<double> plateForce;
  std::string why;  ///< why there are no markers
};

/// The plate's force (+z) of a run's results.json entry at each instant it was written.
std::map<double, double> plateForceAt(const nlohmann::json& run) {
  std::map<double, double> out;
  if (!run.contains("plate_force_at")) return out;
  for (const auto& at : run["plate_force_at"]) {
    const auto& f = at.at("plate_force_N");
    if (!f.empty() && f[0].size() == 3 && f[0][2].is_number())
      out[at.at("t").get<double>()] = f[0][2].get<double>();
  }
  return out;
}

/// The markers of run `label` at each compared instant, read from the case's results.json.
Readout readRun(const CaseResult& c, const std::string& label) {
  Readout out;
  std::string& why = out.why;
  try {
    std::ifstream in(c.outDir / "results.json");
    const nlohmann::json doc = nlohmann::json::parse(in);
    for (const auto& r : doc.at("runs")) {
      if (r.value("label", "") != label) continue;
      if (!r.contains("markers")) {
        why = "no markers in results.json";
        return out;
      }
      const auto& m = r["markers"];
      if (m.value("status", "") != "ok") {
        why = "markers unsupported: " + m.value("reason", std::string("?"));
        return out;
      }
      const std::map<double, double> force = plateForceAt(r);
      for (const auto& at : m.at("at")) {
        const auto f = force.find(at.value("t", std::nan("")));
        out.plateForce.push_back(f == force.end() ? NAN : f->second);
        const auto& p = at.at("positions_m");
        MatX3 x(Eigen::Index(p.size()), 3);
        for (size_t i = 0; i < p.size(); ++i)
          for (int k = 0; k < 3; ++k)
            x(Eigen::Index(i), k) =
                p[i][size_t(k)].is_number() ? p[i][size_t(k)].get<double>() : NAN;
        out.markers.push_back(std::move(x));
      }
      return out;
    }
    why = "no run " + label + " in results.json";
  } catch (const std::exception& e) {
    why = std::string("cannot read results.json: ") + e.what();
  }
  return out;
}

/// A model's runs in the table's cases: its label, plugin, and per level the case and the index
/// of the compared instant that holds that level.
struct Source {
  std::string label, plugin;
  std::vector<std::pair<std::string, size_t>> levels;
  /// A calibrated twin: the level it was trained on (0-based; -1: not a Truth Cube calibration)
  /// and its note (the file and the fitted values).
  bool calibrated = false;
  int trainLevel = -1;
  std::string calibrationNote;
};

/// "fitted poisson = 0.4999 at its upper bound, thickness = 0.01 (FILE)", and the plate it was
/// fitted with when it is not the table's.
std::string fittedNote(const CalibrationParams& c, const std::string& contact) {
  std::string values;
  for (const nlohmann::json* set : {&c.material, &c.params})
    for (const auto& [k, v] : set->items()) {
      const std::string bound = boundWords(c, set == &c.material ? "material." + k : k);
      appendTo(values, k + " = " + (v.is_number() ? formatG(v.get<double>()) : v.dump()) +
                           (bound.empty() ? "" : " " + bound));
    }
  const std::string fitted = c.truthCube.value("contact", std::string());
  return "fitted " + values + " (" + c.file + ")" +
         (!fitted.empty() && fitted != contact ? ", with a " + fitted + " plate" : "");
}

std::string layersMm(const std::vector<double>& v) {
  std::string s;
  for (double x : v) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.2f", 1e3 * x);
    s += (s.empty() ? "" : " ") + std::string(buf);
  }
  return s;
}

/// "run_s" (init plus the solves; a run read back from results.json keeps the statistics only)
/// and "ms_per_step" (the mean wall time of a step; a quasi-static model's steps are its solves).
void timeCells(ojson& row, const RunRecord* r) {
  double seconds = NAN, msPerStep = NAN;
  if (r && !r->stepMs.empty()) {
    seconds = r->precomputeS;
    msPerStep = 0;
    for (double ms : r->stepMs) {
      seconds += 1e-3 * ms;
      msPerStep += ms / double(r->stepMs.size());
    }
  } else if (r) {
    seconds = r->precomputeS + 1e-3 * r->stepStats.mean * r->stepStats.samples;
    if (r->stepStats.samples > 0) msPerStep = r->stepStats.mean;
  }
  row["run_s"] = numberOrNull(seconds);
  row["ms_per_step"] = numberOrNull(msPerStep);
}

/// The table's rows: each source per registration and level (its bead figures, or why it has
/// none), the reference against CalculiX, and a row for each absent model.
std::vector<ojson> truthCubeRows(const TruthCubeData& data, const std::vector<Source>& sources,
                                 const std::vector<std::pair<std::string, std::string>>& absent,
                                 const std::string& contact, const Results& res,
                                 const fs::path& dir) {
  std::vector<ojson> out;
  const MatX3 rest = truthCubeSceneFrame(data, 0);
  // CalculiX's figures, for the reference's comparison column.
  std::map<std::pair<std::string, size_t>, double> calculix;
  // Each source's markers per level (empty when absent) and why not; each case read once.
  std::map<std::pair<std::string, std::string>, Readout> read;
  struct Computed {
    Source source;
    std::string label, plugin;
    std::vector<const CaseResult*> cases;
    std::vector<MatX3> markers;      ///< per level; 0 rows when absent
    std::vector<double> plateForce;  ///< per level, N along +z; NaN when absent
    std::vector<std::string> why;
  };
  std::vector<Computed> computed;
  for (const Source& src : sources) {
    Computed k{src, src.label, src.plugin, {}, {}, {}, {}};
    for (const auto& [caseId, index] : src.levels) {
      const CaseResult* c = res.count(caseId) ? &res.at(caseId) : nullptr;
      const auto key = std::make_pair(caseId, src.label);
      if (c && !read.count(key)) read[key] = readRun(*c, src.label);
      const Readout* m = c ? &read[key] : nullptr;
      const bool has = m && index < m->markers.size();
      k.cases.push_back(c);
      k.markers.push_back(has ? m->markers[index] : MatX3());
      k.plateForce.push_back(has ? m->plateForce[index] : NAN);
      k.why.push_back(m ? m->why : std::string());
    }
    computed.push_back(std::move(k));
  }
  for (const char* reg : {"translation", "bottom_layer"}) {
    const bool bottom = std::string(reg) == "bottom_layer";
    for (const Computed& k : computed) {
      for (size_t l = 0; l < data.strains.size(); ++l) {
        ojson row;
        row["model"] = k.label;
        row["level"] = data.strains[l];
        row["plate_mm"] = 1e3 * data.strains[l] * kSide;
        row["plate_force_N"] = numberOrNull(k.plateForce[l]);
        row["registration"] = reg;
        row["contact"] = contact;
        row["calibrated"] = k.source.calibrated;
        row["calibration"] = !k.source.calibrated ? ""
                             : k.source.trainLevel < 0
                                 ? "not fitted to the beads"
                                 : (int(l) == k.source.trainLevel ? "train" : "validation");
        const CaseResult* c = k.cases[l];
        const RunRecord* r = c ? c->run(k.label) : nullptr;
        const bool ok = r && r->status == RunStatus::Ok && r->valid && k.markers[l].rows() > 0;
        if (ok) {
          const TruthCubeFigures f = truthCubeFigures(data, rest, k.markers[l], int(l + 1), bottom);
          row["rms_error_m"] = numberOrNull(f.rms);
          row["max_error_m"] = numberOrNull(f.maxError);
          row["measured_rms_m"] = numberOrNull(f.measuredRms);
          row["rms_error_mm"] = numberOrNull(1e3 * f.rms);
          row["relative_error"] = numberOrNull(f.rms / f.measuredRms);
          row["max_error_mm"] = numberOrNull(1e3 * f.maxError);
          row["measured_rms_mm"] = numberOrNull(1e3 * f.measuredRms);
          row["layer_rms_mm"] = layersMm(f.layerRms);
          ojson layers = ojson::array();
          for (double v : f.layerRms) layers.push_back(v);
          row["layer_rms_error_m"] = layers;
          row["bulge_mm"] = numberOrNull(1e3 * f.bulge);
          row["measured_bulge_mm"] = numberOrNull(1e3 * f.measuredBulge);
          if (k.label == kCalculix) calculix[{reg, l}] = f.rms;
        } else {
          for (const char* key :
               {"rms_error_m", "max_error_m", "measured_rms_m", "rms_error_mm", "relative_error",
                "max_error_mm", "measured_rms_mm", "bulge_mm", "measured_bulge_mm"})
            row[key] = nullptr;
          row["layer_rms_mm"] = "";
        }
        timeCells(row, r);
        if (c) {
          caseCells(row, *c, k.plugin, r, dir, false);
        } else {
          row["status"] = "not run";
          row["scene"] = "";
          row["note"] = "";
        }
        if (!k.why[l].empty()) {
          std::string note = row["note"].get<std::string>();
          appendTo(note, k.why[l]);
          row["note"] = note;
          if (row["status"] == "ok") row["status"] = "no bead figures";
        }
        if (k.source.calibrated) {
          std::string note = row["note"].get<std::string>();
          appendTo(note, k.source.calibrationNote);
          row["note"] = note;
        }
        out.push_back(row);
      }
    }
  }
  // The reference against CalculiX on the same registration (done when within 10%).
  for (ojson& row : out) {
    row["vs_calculix_pct"] = nullptr;
    const std::string label = row["model"].get<std::string>();
    if (label.rfind("reference_fem", 0) != 0 || !row["rms_error_m"].is_number()) continue;
    size_t l = 0;
    while (l < data.strains.size() && data.strains[l] != row["level"].get<double>()) ++l;
    const auto it = calculix.find({row["registration"].get<std::string>(), l});
    if (it == calculix.end() || !(it->second > 0)) continue;
    const double pct = 100 * (row["rms_error_m"].get<double>() - it->second) / it->second;
    row["vs_calculix_pct"] = pct;
    if (std::abs(pct) > 10 && label == "reference_fem") {
      std::string status = row["status"].get<std::string>();
      appendTo(status, "bead error over 10% from CalculiX's");
      row["status"] = status;
    }
  }
  for (const auto& [name, why] : absent) {
    ojson row = {{"model", name},           {"level", nullptr},
                 {"plate_mm", nullptr},     {"plate_force_N", nullptr},
                 {"registration", nullptr}, {"contact", contact},
                 {"calibrated", false},     {"calibration", ""}};
    for (const char* key : {"rms_error_m", "max_error_m", "measured_rms_m", "rms_error_mm",
                            "relative_error", "max_error_mm", "measured_rms_mm", "bulge_mm",
                            "measured_bulge_mm", "vs_calculix_pct", "run_s", "ms_per_step"})
      row[key] = nullptr;
    row["layer_rms_mm"] = "";
    row["status"] = why;
    row["scene"] = "";
    row["note"] = "";
    out.push_back(row);
  }
  return out;
}

}  // namespace

namespace {

/// The given calibrations, then each shipped one of calibrations/truth-cube/ for a model none of
/// them names (a file given by name wins).
std::vector<CalibrationParams> truthCubeCalibrations(const std::vector<CalibrationParams>& given) {
  std::vector<CalibrationParams> out = given;
  const std::string dir = shippedCalibrationsDir();
  std::error_code ec;
  const fs::path folder = fs::path(dir) / "truth-cube";
  if (dir.empty() || !fs::is_directory(folder, ec)) return out;
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(folder, ec))
    if (e.path().extension() == ".json") files.push_back(e.path());
  std::sort(files.begin(), files.end());
  for (const fs::path& f : files) {
    CalibrationParams c = readCalibrationFile(f.string());
    c.shipped = true;
    c.file = "calibrations/truth-cube/" + f.filename().string();
    if (std::none_of(out.begin(), out.end(), [&](const CalibrationParams& x) {
          return x.plugin == c.plugin && x.model == c.model;
        }))
      out.push_back(std::move(c));
  }
  return out;
}

}  // namespace

namespace {

/// A calibrated twin ("+cal") of a model: its scene entry and the fit it holds.
struct Twin {
  ojson entry;
  CalibrationParams calibration;
  bool dynamic = false;
};

/// Who runs where: the quasi-static models (one scene), the dynamic ones (a scene per level),
/// the absent ones with why, and the calibrated twins (those --quick leaves out named).
struct Lineup {
  std::vector<ojson> models, dynamic;
  std::vector<std::pair<std::string, std::string>> absent;
  std::vector<Twin> twins;
  std::string skippedTwins;
};

Lineup truthCubeLineup(const TablesOptions& o, PluginLoader& loader, const TruthCubeData& data,
                       const std::string& contact, bool withCalculix) {
  Lineup u;
  // Reference and CalculiX on one quadratic tet mesh (deform/geometry/organ_tets.h).
  ojson displacementParams = femParams(o.quick);
  displacementParams["volumetric"] = "displacement";
  u.models = {model("reference_fem", "reference_fem", femParams(o.quick)),
              model("reference_fem", kDisplacementLabel, displacementParams)};
  if (withCalculix) u.models.push_back(model(kCalculix, kCalculix, femParams(o.quick)));
  // The other models: the quasi-static ones in the same scene, the dynamic ones in a settling
  // scene per level; the others get a row saying why they have no figure.
  for (const std::string& name : kOtherModels) {
    const TruthCubeModel m = truthCubeModel(loader, name, o.quick);
    if (!m.problem.empty()) {
      u.absent.emplace_back(name, m.problem);
    } else {
      (m.dynamic ? u.dynamic : u.models).push_back(m.entry);
    }
  }
  // Calibrated twins: the shipped calibrations on the Truth Cube (calibrations/truth-cube/,
  // fitted to the beads by calibrate --truth-cube) and any --calibration for it. A twin of the
  // parameters runs beside its model; one of the organ's material runs alone.
  const std::vector<CalibrationParams> calibrations = truthCubeCalibrations(o.calibrations);
  const std::string organ = calibrationOrgan(truthCubeScene(data, {}, contact)["organ"]);
  for (bool isDynamic : {false, true}) {
    for (const ojson& m : isDynamic ? u.dynamic : u.models) {
      const std::string plugin = m["plugin"].get<std::string>();
      if (m["label"] != plugin) continue;  // the default configuration only
      const auto c = std::find_if(calibrations.begin(), calibrations.end(), [&](const auto& x) {
        return x.plugin == plugin && x.model == plugin && calibrationApplies(x, organ);
      });
      if (c == calibrations.end()) continue;
      ojson twin = m;
      twin["label"] = plugin + "+cal";
      ojson params = ojson::parse(c->params.dump());
      for (const auto& [k, v] : m["params"].items()) params[k] = v;
      twin["params"] = params;
      // --quick: a fit of the organ's material needs cases of its own; only the full table
      // runs them.
      if (o.quick && !c->material.empty()) {
        appendTo(u.skippedTwins, twin["label"].get<std::string>());
        continue;
      }
      u.twins.push_back({twin, *c, isDynamic});
    }
  }
  for (const Twin& tw : u.twins)
    if (tw.calibration.material.empty()) (tw.dynamic ? u.dynamic : u.models).push_back(tw.entry);
  return u;
}

/// The table's notes on its twins: which files, which models have none, what --quick left out.
void twinNotes(const Lineup& u, std::vector<std::string>& notes) {
  std::string untwinned;
  for (const std::string& name : kOtherModels)
    if (std::none_of(u.twins.begin(), u.twins.end(),
                     [&](const Twin& tw) { return tw.entry["plugin"] == name; }) &&
        std::none_of(u.absent.begin(), u.absent.end(),
                     [&](const auto& a) { return a.first == name; }) &&
        u.skippedTwins.find(name + "+cal") == std::string::npos)
      appendTo(untwinned, name);
  if (!u.twins.empty() && !untwinned.empty())
    notes.push_back("No calibrated twin (no fit in calibrations/truth-cube/): " + untwinned + ".");
  if (u.twins.empty()) {
    notes.push_back(
        "Not calibrated: every row is at the published material (calibrated = false); "
        "calibrations/truth-cube/ holds none for these models.");
  } else {
    std::string files;
    for (const Twin& tw : u.twins) appendTo(files, tw.calibration.file);
    notes.push_back(
        "Calibrated twins (+cal, calibrated = true): fitted to the beads of one level "
        "(`deformbench calibrate --truth-cube LEVEL`, metric marker_rms: the bead RMS after the "
        "translation registration), the level it was trained on marked \"train\", the others "
        "\"validation\"; each row's note gives the fitted values. A fit of the organ's nu (E "
        "does not move the beads when the plate's displacement is prescribed) runs in cases of "
        "its own. Files: " +
        files + ".");
  }
  if (!u.skippedTwins.empty())
    notes.push_back(
        "--quick leaves out the twins whose fit holds the organ's nu (they need cases of their "
        "own; the full table runs them): " +
        u.skippedTwins + ".");
}

/// The table's cases (the quasi-static scene, a settling scene per level, the material twins'
/// own) and where each model's markers at each level are, each twin after its model.
std::vector<Source> truthCubeCases(TableDef& t, const Lineup& u, const TruthCubeData& data,
                                   const std::string& contact, bool quick) {
  // Sliding runs are other cases (a --resume never mixes them with the bonded ones).
  const std::string suffix = contact == "sliding" ? "_sliding" : "";
  const std::string id = "truth-cube/cube" + suffix;
  t.cases.push_back({id, truthCubeScene(data, u.models, contact)});
  const auto dynamicId = [&](size_t l, const std::string& tail) {
    return "truth-cube/dynamic_" + std::to_string(l + 1) + tail + suffix;
  };
  // (case, index of the compared instant) per level.
  std::vector<Source> sources;
  const auto addSource = [&](const ojson& m, const std::function<std::string(size_t)>& caseOf,
                             bool perLevelScene) {
    Source src;
    src.label = m["label"].get<std::string>();
    src.plugin = m["plugin"].get<std::string>();
    for (const Twin& tw : u.twins) {
      if (tw.entry["label"] != src.label) continue;
      src.calibrated = true;
      src.trainLevel = tw.calibration.truthCube.value("level", 0) - 1;
      src.calibrationNote = fittedNote(tw.calibration, contact);
    }
    for (size_t l = 0; l < data.strains.size(); ++l)
      src.levels.emplace_back(caseOf(l), perLevelScene ? 0 : l);
    sources.push_back(src);
  };
  for (const ojson& m : u.models)
    addSource(
        m, [&](size_t) { return id; }, false);
  if (!u.dynamic.empty()) {
    for (size_t l = 0; l < data.strains.size(); ++l)
      t.cases.push_back({dynamicId(l, ""),
                         truthCubeDynamicScene(data, l, u.dynamic, dynamicCap(quick), contact)});
    for (const ojson& m : u.dynamic)
      addSource(
          m, [&](size_t l) { return dynamicId(l, ""); }, true);
  }
  // Twins of the organ's material: their own cases, the organ's material replaced.
  for (const Twin& tw : u.twins) {
    if (tw.calibration.material.empty()) continue;
    const auto withMaterial = [&](ojson scene) {
      for (const auto& [k, v] : tw.calibration.material.items())
        scene["organ"]["material"][k] = v.get<double>();
      return scene;
    };
    const std::string plugin = tw.entry["plugin"].get<std::string>();
    if (!tw.dynamic) {
      const std::string cid = "truth-cube/cube_cal_" + plugin + suffix;
      t.cases.push_back({cid, withMaterial(truthCubeScene(data, {tw.entry}, contact))});
      addSource(
          tw.entry, [cid](size_t) { return cid; }, false);
    } else {
      for (size_t l = 0; l < data.strains.size(); ++l)
        t.cases.push_back(
            {dynamicId(l, "_cal_" + plugin),
             withMaterial(truthCubeDynamicScene(data, l, {tw.entry}, dynamicCap(quick), contact))});
      addSource(
          tw.entry, [&](size_t l) { return dynamicId(l, "_cal_" + plugin); }, true);
    }
  }
  std::vector<std::string> order;
  for (const Source& src : sources)
    if (!src.calibrated) order.push_back(src.label);
  const auto rank = [&order](const Source& src) {
    const std::string base = src.calibrated ? src.label.substr(0, src.label.size() - 4) : src.label;
    return std::find(order.begin(), order.end(), base) - order.begin();
  };
  std::stable_sort(sources.begin(), sources.end(),
                   [&rank](const Source& a, const Source& b) { return rank(a) < rank(b); });
  return sources;
}

}  // namespace

TableDef truthCube(const TablesOptions& o, PluginLoader& loader) {
  TableDef t = tableDef(
      "truth-cube", "Every model against the Truth Cube's 343 beads (a physical experiment)",
      "Kerdok, Cotin, Ottensmeyer, Galea, Howe, Dawson 2003, Medical Image Analysis 7:283-291 "
      "(data: simquest/opensurgsim, Apache-2.0; data/truth-cube/README.md)",
      {{"model", "model"},
       {"level", "strain"},
       {"plate_mm", "plate mm"},
       {"plate_force_N", "plate force N"},
       {"registration", "registration"},
       {"contact", "plate"},
       {"rms_error_mm", "bead RMS error mm"},
       {"relative_error", "RMS error / measured RMS"},
       {"max_error_mm", "max error mm"},
       {"measured_rms_mm", "measured RMS mm"},
       {"layer_rms_mm", "RMS per layer mm (bottom to top)"},
       {"bulge_mm", "outer columns bulge mm"},
       {"measured_bulge_mm", "measured bulge mm"},
       {"vs_calculix_pct", "vs CalculiX %"},
       {"calibrated", "calibrated"},
       {"calibration", "calibration level"},
       {"run_s", "run s"},
       {"ms_per_step", "ms/step"},
       {"status", "status"},
       {"scene", "scene"},
       {"note", "note"}});
  const std::string file = o.truthCubeData.empty() ? defaultDataFile() : o.truthCubeData;
  const TruthCubeData data = readTruthCubeData(file);
  const std::string contact = o.truthCubeContact.empty() ? "bonded" : o.truthCubeContact;
  if (contact != "bonded" && contact != "sliding")
    throw InputError("--contact", "", "expected bonded or sliding, got " + contact);
  const std::string calculixProblem = pluginProblem(loader, kCalculix);
  const Lineup u = truthCubeLineup(o, loader, data, contact, calculixProblem.empty());
  t.notes = {
      "Data: " + file + " (" + std::to_string(data.beads.size()) + " beads, " +
          std::to_string(data.strains.size()) +
          " compression levels). Scanner frame (-z up) turned 180 degrees about x into the "
          "scene's (z up), centred on the beads in x and y, the base 10 mm under the bottom "
          "layer.",
      "Scene (scenes/truth-cube/cube.json): the phantom cube scaled to 80 mm; E 15.3 kPa, nu "
      "0.499, rho 980, no gravity (the rest scan is the reference state); the bottom face "
      "fixed (bonded base); the top face held by a " +
          contact +
          " plate (sliding: its vertical displacement prescribed, the lateral free, --contact) "
          "moved down by strain x 80 mm; one compared instant per level. reference_fem and "
          "CalculiX solve the same " +
          std::to_string(femParams(o.quick)["elements"].get<long long>()) +
          "-target quadratic tet mesh: reference_fem with its default volumetric term at nu "
          "0.499 (mean dilatation, constant per element), and again with the volumetric term "
          "per quadrature point (volumetric = displacement, CalculiX's C3D10 formulation).",
      "Registration: \"translation\" removes the least-squares rigid translation between the "
      "model's and the measured bead displacements of each scan (the scans were not registered "
      "to one another); \"bottom_layer\" the mean difference of the bottom bead layer. RMS and "
      "max over all beads; the measured RMS is the beads' own RMS displacement. The bulge is "
      "the mean outward lateral displacement of the outer columns' middle layers.",
      "For orientation, the issue's CalculiX figures from 8 x 8 x 8 20-node hexes: 0.60 / 0.80 "
      "mm (translation), 0.90 / 1.18 mm (bottom layer) at 5% / 12.5%."};
  twinNotes(u, t.notes);
  if (!calculixProblem.empty())
    t.notes.push_back("CalculiX: not available: " + calculixProblem + ".");
  if (!u.dynamic.empty())
    t.notes.push_back(
        "Dynamic models (their volume network where they have one, default parameters): one "
        "scene per level (scenes/truth-cube/dynamic_N.json, dt 1 ms), the plate moved over 1 s "
        "and held, compared once settled (\"compare_at\": \"equilibrium\", capped at " +
        formatG(dynamicCap(o.quick)) + " s).");
  const std::vector<Source> sources = truthCubeCases(t, u, data, contact, o.quick);
  const auto absent = u.absent;
  t.rows = [data, sources, absent, contact](const Results& res, const fs::path& dir) {
    return truthCubeRows(data, sources, absent, contact, res, dir);
  };
  return t;
}

}  // namespace deform::harness::tables

namespace deform::harness {

TruthCubeModel truthCubeModel(PluginLoader& loader, const std::string& plugin, bool quick) {
  TruthCubeModel m;
  const std::string problem = pluginProblem(loader, plugin);
  if (!problem.empty()) {
    m.problem = "missing plugin " + plugin + ": " + problem;
    return m;
  }
  const ModelInfo& info = loader.load(plugin, plugin);
  if (plugin == "reference_fem" || plugin == tables::kCalculix) {
    m.entry = tables::model(plugin, plugin, tables::femParams(quick));
  } else if (!info.has(Capability::Markers)) {
    m.problem = "unsupported: " + plugin +
                " has no markers capability: it maps no interior point (a surface model has none)";
  } else if (quick && info.param("tets")) {
    // A model that meshes its own tets gets at least ~3,400 on the cube (its 866-vertex surface
    // bounds them): bullet_deformable, at ~18 us per tet and step, takes 1-2 min per settling
    // scene, more than --quick has.
    m.problem = "left out by --quick: " + plugin +
                " meshes its own tets, at least ~3,400 on the cube; the full table runs it";
  } else {
    nlohmann::ordered_json params = nlohmann::ordered_json::object();
    // Dynamic models with a volume network use it: the beads are inside.
    if (!info.has(Capability::QuasiStatic) && info.param("network")) params["network"] = "volume";
    m.entry = tables::model(plugin, plugin, params);
    m.dynamic = !info.has(Capability::QuasiStatic);
  }
  return m;
}

std::vector<double> truthCubeStrains(const std::string& dataFile) {
  return tables::readTruthCubeData(dataFile.empty() ? tables::defaultDataFile() : dataFile).strains;
}

nlohmann::ordered_json truthCubeLevelScene(const std::string& dataFile, size_t level,
                                           const TruthCubeModel& m, const std::string& contact,
                                           bool quick) {
  const tables::TruthCubeData d =
      tables::readTruthCubeData(dataFile.empty() ? tables::defaultDataFile() : dataFile);
  if (level >= d.strains.size())
    throw InputError("--truth-cube", std::to_string(level + 1),
                     "the data hold levels 1 to " + std::to_string(d.strains.size()));
  if (contact != "bonded" && contact != "sliding")
    throw InputError("--contact", "", "expected bonded or sliding, got " + contact);
  return m.dynamic ? tables::truthCubeDynamicScene(d, level, {m.entry}, tables::dynamicCap(quick),
                                                   contact)
                   : tables::truthCubeStaticLevelScene(d, level, {m.entry}, contact);
}

}  // namespace deform::harness
