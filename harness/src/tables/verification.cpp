// verification: the reference FEM (at its defaults) and CalculiX against answers from outside the
// code: beam theory with shear, the elastica under its own weight (shooting, analytic.h),
// homogeneous Neo-Hookean compression in closed form, and Cook's membrane's published tips.
#include "paper_figures.h"
#include "table_kit.h"

#include <deform/geometry/mesh_io.h>
#include <deform/geometry/phantom.h>
#include <deform_harness/analytic.h>

#include <algorithm>
#include <cmath>

namespace deform::harness::tables {

namespace {

constexpr double kGravity = 9.81;
/// Every row's reference_fem figure must be within this of the row's value.
constexpr double kTolerancePct = 2.0;
constexpr const char* kCalculix = "calculix";
constexpr double kBeamLength = 0.1;  ///< m, the beam phantom's length (x)

/// What a row measures on the final surface: the mean displacement along `axis` (0 x, 1 y, 2 z;
/// sign: +1 along the axis, -1 against it) of the rest surface vertices inside `where`.
struct Probe {
  Box where;
  int axis = 2;
  double sign = 1;
};

struct VerificationRow {
  std::string id, what, quantity, source;
  std::string phantom;
  double resolution = 1;
  double value = 0;  ///< m, the analytic or published figure
  Probe probe;
  ojson scene;
};

ojson box(const Vec3& lo, const Vec3& hi) {
  return ojson::array({vecJson(lo), vecJson(hi)});
}

ojson materialOf(double young, double poisson, double density = 1000) {
  return {{"young", young}, {"poisson", poisson}, {"density", density}};
}

/// A one-step quasi-static scene: reference_fem at its defaults, and CalculiX when it is found
/// (it then solves the same scene at its own defaults).
ojson verificationScene(const std::string& name, const std::string& description, ojson organ,
                        const Vec3& gravity, ojson loads, bool withCalculix) {
  ojson j;
  j["name"] = "verification-" + name;
  j["description"] = description;
  j["organ"] = std::move(organ);
  j["gravity"] = vecJson(gravity);
  j["dt"] = 1.0;
  j["duration"] = 1.0;
  if (!loads.empty()) j["loads"] = std::move(loads);
  ojson models = ojson::array({model("reference_fem", "reference_fem")});
  if (withCalculix) models.push_back(model(kCalculix, kCalculix));
  j["models"] = models;
  j["output"] = {{"surfaces", "final"}};
  return j;
}

/// Cantilever 0.1 m x 10 mm x 10 mm (beam phantom), root face clamped, under gravity.
ojson cantileverOrgan(double young) {
  return {{"mesh", "phantom:beam"},
          {"material", materialOf(young, 0.3)},
          {"fixed", {{"box", box(Vec3(-0.001, -0.01, -0.01), Vec3(1e-4, 0.01, 0.01))}}}};
}

/// A cantilever row (the beam phantom, length kBeamLength): its tip sag under gravity.
VerificationRow cantileverRow(const std::string& name, std::string what, double sag,
                              std::string source, double young, const std::string& description,
                              bool withCalculix) {
  VerificationRow r;
  r.id = "verification/" + name;
  r.what = std::move(what);
  r.quantity = "tip sag";
  r.value = sag;
  r.source = std::move(source);
  r.phantom = "beam";
  r.probe = {Box{Vec3(kBeamLength - 1e-9, -1, -1), Vec3(1, 1, 1)}, 2, -1};
  r.scene = verificationScene(name, description, cantileverOrgan(young), Vec3(0, 0, -kGravity),
                              ojson::array(), withCalculix);
  return r;
}

std::vector<VerificationRow> verificationRows(bool withCalculix) {
  std::vector<VerificationRow> rows;
  const double L = kBeamLength, t = 0.01, rho = 1000, nu = 0.3;
  rows.push_back(cantileverRow(
      "cantilever_small", "gravity cantilever, small deflection (E 10 MPa)",
      cantileverSag(1e7, nu, rho, kGravity, L, t),
      "beam theory: Euler-Bernoulli q L^4 / (8 E I) + Timoshenko shear q L^2 / (2 k G A), "
      "k = 5/6",
      1e7,
      "Gravity cantilever 0.1 m x 10 mm x 10 mm, root face clamped, E 10 MPa, nu 0.3, "
      "rho 1000: small deflection, against beam theory with shear.",
      withCalculix));
  {
    // q L^3 / (E I) = 3: the tip sags about a third of the length.
    const double alpha = 3, q = rho * kGravity * t * t, I = t * t * t * t / 12;
    const double E = q * L * L * L / (alpha * I);
    rows.push_back(cantileverRow(
        "cantilever_large",
        "gravity cantilever, large deflection (q L^3 / EI = 3, E " +
            formatG(std::round(E / 100) / 10) + " kPa)",
        elasticaCantilever(L, E * I, q, 0).sag,
        "elastica under its own weight, computed here by shooting on EI theta'' = -q (L - s) "
        "cos theta (analytic.h; the solver reproduces Mattiasson 1981, IJNME 17:145, tip-load "
        "table to 5 digits)",
        E,
        "Gravity cantilever 0.1 m x 10 mm x 10 mm, root face clamped, nu 0.3, rho 1000, E such "
        "that q L^3 / EI = 3: large deflection, against the elastica under its own weight.",
        withCalculix));
  }
  {
    VerificationRow r;
    r.id = "verification/cube_compression";
    const double E = 5500, a = 0.05, force = 11;  // 1.1 kPa nominal: 20% of E
    const UniaxialState s = neoHookeanUniaxialAtNominalStress(E, nu, -force / (4 * a * a));
    r.what = "uniaxial compression of a 0.1 m cube, frictionless faces (E 5.5 kPa, 11 N)";
    // Measured at mid-height, on the side faces' vertices at z = 0, away from the loaded face.
    r.quantity = "mid-height descent";
    r.value = (1 - s.axialStretch) * a;
    r.source =
        "closed form: psi = mu/2 (J^-2/3 I1 - 3) + kappa/2 (J - 1)^2 under a dead nominal "
        "stress, lateral Cauchy stress zero (axial stretch " +
        formatG(std::round(s.axialStretch * 1e5) / 1e5) + ", lateral " +
        formatG(std::round(s.lateralStretch * 1e5) / 1e5) + ")";
    r.phantom = "cube";
    r.probe = {Box{Vec3(-1, -1, -1e-9), Vec3(1, 1, 1e-9)}, 2, -1};
    const double e = 1e-6, m = 0.06;
    ojson organ = {
        {"mesh", "phantom:cube"},
        {"material", materialOf(E, nu)},
        {"fixed",
         ojson::array({{{"box", box(Vec3(-m, -m, -a - e), Vec3(m, m, -a + e))}, {"axes", "z"}},
                       {{"box", box(Vec3(-a - e, -m, -m), Vec3(-a + e, m, m))}, {"axes", "x"}},
                       {{"box", box(Vec3(-m, -a - e, -m), Vec3(m, -a + e, m))}, {"axes", "y"}}})}};
    ojson loads = ojson::array({{{"type", "traction"},
                                 {"region", {{"box", box(Vec3(-m, -m, a - e), Vec3(m, m, a + e))}}},
                                 {"force", {0, 0, -force}}}});
    r.scene = verificationScene(
        "cube_compression",
        "Cube 0.1 m, E 5.5 kPa, nu 0.3: bottom on z-rollers, the x = -0.05 and y = -0.05 faces "
        "on symmetry rollers, 11 N down spread uniformly over the top face.",
        organ, Vec3::Zero(), loads, withCalculix);
    rows.push_back(r);
  }
  // Cook's membrane: 8 mm thick here (plane strain: z-rollers on both faces, so the thickness
  // does not matter), the force scaled with the thickness.
  const double thick = 0.008;
  const auto cooksOrgan = [&](double young, double poisson) {
    const double e = 1e-6;
    return ojson{
        {"mesh", "phantom:cooks_membrane"},
        {"material", materialOf(young, poisson)},
        {"fixed",
         ojson::array(
             {{{"box", box(Vec3(-0.001, -0.001, -0.001), Vec3(1e-5, 0.061, 0.009))}},
              {{"box", box(Vec3(-0.001, -0.001, -e), Vec3(0.049, 0.061, e))}, {"axes", "z"}},
              {{"box", box(Vec3(-0.001, -0.001, thick - e), Vec3(0.049, 0.061, thick + e))},
               {"axes", "z"}}})}};
  };
  const auto shear = [&](double force) {
    return ojson::array(
        {{{"type", "traction"},
          {"region", {{"box", box(Vec3(0.048 - 1e-6, 0.043, -0.001), Vec3(0.049, 0.061, 0.009))}}},
          {"force", {0, force, 0}}}});
  };
  {
    VerificationRow r;
    r.id = "verification/cooks_membrane";
    const double mu = 0.4225e6, poisson = 0.3;
    r.what = "Cook's membrane, compressible Neo-Hookean (mu 422.5 kPa, nu 0.3, 1 N per mm)";
    r.quantity = "y at (48, 52) mm";
    r.value = kCooksCompressibleTip;
    r.source = kCooksCompressibleSource;
    r.phantom = "cooks_membrane";
    r.probe = {Box{Vec3(0.048 - 1e-9, 0.052 - 1e-9, -1), Vec3(1, 0.052 + 1e-9, 1)}, 1, 1};
    r.scene = verificationScene(
        "cooks_membrane",
        "Cook's membrane (48 x 44/16 mm taper, 8 mm thick, z-rollers on both faces: plane "
        "strain), left edge clamped, 8 N (1 N per mm of thickness) along +y spread uniformly "
        "over the right edge; mu 422.5 kPa, nu 0.3.",
        cooksOrgan(2 * mu * (1 + poisson), poisson), Vec3::Zero(), shear(thick / 0.001),
        withCalculix);
    rows.push_back(r);
  }
  {
    VerificationRow r;
    r.id = "verification/cooks_membrane_nu0499";
    const double E = 240.565e6, poisson = 0.499;
    r.what = "Cook's membrane, nearly incompressible (E 240.565 MPa, nu 0.499, 6.25 MPa shear)";
    r.quantity = "y at (48, 60) mm";
    r.value = kCooksIncompressibleTip;
    r.source = kCooksIncompressibleSource;
    r.phantom = "cooks_membrane";
    r.probe = {Box{Vec3(0.048 - 1e-9, 0.06 - 1e-9, -1), Vec3(1, 1, 1)}, 1, 1};
    r.scene = verificationScene(
        "cooks_membrane_nu0499",
        "Cook's membrane (48 x 44/16 mm taper, 8 mm thick, z-rollers on both faces: plane "
        "strain), left edge clamped, 6.25 MPa along +y on the right edge (800 N); E 240.565 "
        "MPa, nu 0.499.",
        cooksOrgan(E, poisson), Vec3::Zero(), shear(6.25e6 * 0.016 * thick), withCalculix);
    rows.push_back(r);
  }
  return rows;
}

/// The rows --quick runs (the others are listed as skipped).
bool inQuick(const std::string& id) {
  return id == "verification/cantilever_small" || id == "verification/cube_compression";
}

/// The probe's mean displacement (m) on the run's final surface; NaN when it cannot be read.
double measure(const CaseResult& c, const RunRecord* r, const VerificationRow& row) {
  if (!r || r->status != RunStatus::Ok) return std::nan("");
  MatX3 final = r->finalSurface;
  if (final.rows() == 0 && !r->finalSurfaceFile.empty()) {
    try {
      final = readObj((c.outDir / r->finalSurfaceFile).string()).V;
    } catch (const std::exception&) {
      return std::nan("");
    }
  }
  const SurfaceMesh rest = makePhantom(row.phantom, row.resolution);
  if (final.rows() < rest.V.rows()) return std::nan("");
  double sum = 0;
  int n = 0;
  for (Eigen::Index v = 0; v < rest.V.rows(); ++v) {
    if (!row.probe.where.contains(rest.V.row(v).transpose())) continue;
    sum += row.probe.sign * (final(v, row.probe.axis) - rest.V(v, row.probe.axis));
    ++n;
  }
  return n ? sum / n : std::nan("");
}

double runSeconds(const RunRecord* r) {
  if (!r) return std::nan("");
  double s = r->precomputeS;
  for (double ms : r->stepMs) s += 1e-3 * ms;
  return s;
}

}  // namespace

TableDef verification(const TablesOptions& o, PluginLoader& loader) {
  TableDef t = tableDef(
      "verification", "reference_fem and CalculiX against analytic and published solutions",
      "beam theory; the elastica (Mattiasson 1981); Neo-Hookean closed form; Cook's membrane "
      "(deal.II code gallery, OpenGeoSys)",
      {{"case", "case"},
       {"quantity", "quantity"},
       {"reference_fem_mm", "reference_fem mm"},
       {"calculix_mm", "CalculiX mm"},
       {"value_mm", "value mm"},
       {"error_pct", "error %"},
       {"calculix_error_pct", "CalculiX error %"},
       {"reference_fem_s", "reference_fem s"},
       {"calculix_s", "CalculiX s"},
       {"status", "status"},
       {"source", "value from"},
       {"scene", "scene"},
       {"note", "note"}});
  std::string calculixProblem = pluginProblem(loader, kCalculix);
  const bool withCalculix = calculixProblem.empty();
  t.notes = {
      "Each row is one quasi-static scene (scenes/verification/*.json) run by reference_fem at "
      "its defaults (no parameters given) and by CalculiX (the calculix plugin) at its own; "
      "error % = (model - value) / value; a reference_fem error above " +
          formatG(kTolerancePct) + "% is flagged in the status.",
      "Rollers (\"fixed\" boxes with \"axes\") make the cube's faces frictionless and Cook's "
      "membrane plane strain; tractions (\"traction\" loads) spread the force uniformly over "
      "the loaded face, and both solvers integrate it against their quadratic faces' shape "
      "functions (consistent loads). The measured figure is the mean displacement of the "
      "organ's surface vertices at the named place.",
      kCooksNote,
      "CalculiX runs the plain displacement element C3D10 (Debian's build has no hybrid "
      "elements); the 2% goal is reference_fem's, whose P2 tets switch to mean dilatation at "
      "nu >= 0.45."};
  if (!withCalculix) t.notes.push_back("CalculiX: not available: " + calculixProblem + ".");
  const std::vector<VerificationRow> rows = verificationRows(withCalculix);
  for (const VerificationRow& r : rows)
    if (!o.quick || inQuick(r.id)) t.cases.push_back({r.id, r.scene});
  t.rows = [rows, o, withCalculix, calculixProblem](const Results& res, const fs::path& dir) {
    std::vector<ojson> out;
    for (const VerificationRow& v : rows) {
      ojson row;
      row["case"] = v.what;
      row["quantity"] = v.quantity;
      row["value_mm"] = 1e3 * v.value;
      row["source"] = v.source;
      const CaseResult* c = caseOrSkipped(res, v.id, o.quick, row);
      if (!c) {
        for (const char* k : {"reference_fem_mm", "calculix_mm", "error_pct", "calculix_error_pct",
                              "reference_fem_s", "calculix_s"})
          row[k] = nullptr;
        row["note"] = "";
        out.push_back(row);
        continue;
      }
      const RunRecord* ref = c->run("reference_fem");
      const RunRecord* ccx = withCalculix ? c->run(kCalculix) : nullptr;
      const double a = measure(*c, ref, v), b = measure(*c, ccx, v);
      const auto pct = [&](double x) {
        return std::isfinite(x) ? ojson(100 * (x - v.value) / v.value) : ojson(nullptr);
      };
      row["reference_fem_mm"] = numberOrNull(1e3 * a);
      row["calculix_mm"] = numberOrNull(1e3 * b);
      row["error_pct"] = pct(a);
      row["calculix_error_pct"] = pct(b);
      row["reference_fem_s"] = ref ? ojson(runSeconds(ref)) : ojson(nullptr);
      row["calculix_s"] = ccx ? ojson(runSeconds(ccx)) : ojson(nullptr);
      caseCells(row, *c, "reference_fem", ref, dir, false);
      std::string status = row["status"].get<std::string>();
      if (std::isfinite(a) && std::abs(100 * (a - v.value) / v.value) > kTolerancePct)
        appendTo(status, "reference_fem error above " + formatG(kTolerancePct) + "%");
      std::string note = row["note"].get<std::string>();
      if (!withCalculix) {
        appendTo(note, "CalculiX: not available (see the notes)");
      } else {
        const std::string st = statusOf(*c, kCalculix, ccx);
        if (st != "ok") appendTo(note, "CalculiX: " + st + (ccx ? " " + ccx->message : ""));
      }
      row["status"] = status;
      row["note"] = note;
      out.push_back(row);
    }
    return out;
  };
  return t;
}

}  // namespace deform::harness::tables
