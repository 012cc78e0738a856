// The tables' shared kit (table_kit.h).
#include "table_kit.h"

#include <deform/geometry/phantom.h>

#include <algorithm>
#include <cmath>
#include <cstdio>

namespace deform::harness::tables {

std::string forceTag(double f) {
  std::string s = formatG(f) + "N";
  std::replace(s.begin(), s.end(), '.', 'p');
  return s;
}

void appendTo(std::string& list, const std::string& part) {
  if (!part.empty()) list += (list.empty() ? "" : "; ") + part;
}

ojson model(const std::string& plugin, const std::string& label, ojson params) {
  return {{"plugin", plugin}, {"label", label}, {"params", std::move(params)}};
}

ojson material() {
  return {{"young", 5500}, {"poisson", 0.3}, {"density", 1000}};
}

ojson phantomOrgan(const std::string& name, double resolution, double fixedFraction,
                   SurfaceMesh& meshOut) {
  meshOut = makePhantom(name, resolution);
  const Box b = boundingBox(meshOut.V);
  const Vec3 m = Vec3::Constant(0.05 * b.diagonal());
  const Vec3 lo = b.lo - m;
  const Vec3 hi(b.hi.x() + m.x(), b.hi.y() + m.y(), b.lo.z() + fixedFraction * b.size().z());
  return {{"mesh", "phantom:" + name},
          {"resolution", resolution},
          {"material", material()},
          {"fixed", {{"box", ojson::array({vecJson(lo), vecJson(hi)})}}}};
}

ojson baseScene(const std::string& name, const std::string& description, ojson organ,
                double duration) {
  ojson j;
  j["name"] = name;
  j["description"] = description;
  j["organ"] = std::move(organ);
  j["gravity"] = {0, 0, 0};
  j["dt"] = 0.001;
  j["duration"] = duration;
  return j;
}

void addReference(ojson& scene, ojson reference) {
  scene["reference"] = std::move(reference);
  scene["samples"] = {{"nearest", {10, 50}}};
}

ojson referenceFem(long long elements, int order) {
  return model("reference_fem", "reference_fem",
               {{"elements", elements}, {"element_order", order}});
}

std::string referenceTets(long long elements, int order) {
  return std::to_string(elements) + " target P" + std::to_string(order) + " (" +
         (order == 2 ? "10" : "4") + "-node) tets";
}

Vec3 topVertex(const SurfaceMesh& s) {
  const Box b = boundingBox(s.V);
  return s.V.row(nearestVertex(s.V, Vec3(b.center().x(), b.center().y(), b.hi.z()))).transpose();
}

ojson verticalForce(const Vec3& at, double fz, double end) {
  return ojson::array({{{"type", "point_force"},
                        {"at", vecJson(at)},
                        {"force", {0, 0, fz}},
                        {"start", 0.0},
                        {"end", end}}});
}

ojson graspFromTop(const SurfaceMesh& s, double depthFraction, double radiusFraction, double lift,
                   double duration) {
  const double height = boundingBox(s.V).size().z();
  const Vec3 p = topVertex(s) - Vec3(0, 0, depthFraction * height);
  return ojson::array({{{"type", "grasper"},
                        {"radius", radiusFraction * height},
                        {"trajectory",
                         {{{"t", 0.0}, {"pos", vecJson(p)}, {"jaw", "closed"}},
                          {{"t", duration}, {"pos", vecJson(p + Vec3(0, 0, lift))}}}}}});
}

std::vector<TableColumn> withPaper(const std::string& key, const std::string& header,
                                   const std::string& paperHeader) {
  return {{key, header}, {"paper_" + key, paperHeader.empty() ? "paper " + header : paperHeader}};
}

std::vector<TableColumn> columns(std::initializer_list<std::vector<TableColumn>> groups) {
  std::vector<TableColumn> out;
  for (const auto& g : groups) out.insert(out.end(), g.begin(), g.end());
  return out;
}

ojson countOf(const RunRecord* r, const std::string& key) {
  if (!r || !r->counts.count(key)) return nullptr;
  return r->counts.at(key);
}

ojson stepMedian(const RunRecord* r) {
  if (!r || r->stepStats.samples == 0) return nullptr;
  return r->stepStats.median;
}

ojson errorFigure(const RunRecord* r, const std::function<double(const ErrorMetrics&)>& get) {
  if (!r || !r->error) return nullptr;
  return numberOrNull(get(*r->error));
}

ojson rmseMm(const RunRecord* r, int k) {
  return errorFigure(r, [k](const ErrorMetrics& e) {
    for (const auto& [kk, v] : e.rmseNearest)
      if (kk == k) return 1e3 * v;
    return std::nan("");
  });
}

ojson referenceDisplacementMm(const RunRecord* r, int k) {
  return errorFigure(r, [k](const ErrorMetrics& e) {
    for (const auto& [kk, v] : e.referenceNearest)
      if (kk == k) return 1e3 * v;
    return std::nan("");
  });
}

ojson lossRatio(const RunRecord* r) {
  return errorFigure(r, [](const ErrorMetrics& e) { return e.lossRatio; });
}

ojson precomputeS(const RunRecord* r) {
  return r && r->steps > 0 ? ojson(r->precomputeS) : ojson(nullptr);
}

std::string statusOf(const CaseResult& c, const std::string& plugin, const RunRecord* r) {
  if (c.missing.count(plugin)) return "missing plugin " + plugin + ": " + c.missing.at(plugin);
  if (!c.error.empty()) return "not run: " + c.error;
  if (!r) return "not run";
  if (r->status == RunStatus::Ok && !r->valid) return "invalid (" + r->invalidReason + ")";
  return statusName(r->status);
}

std::string referenceStatus(const CaseResult& c) {
  if (!c.result) return "";
  for (const RunRecord& r : c.result->runs) {
    if (!r.isReference || (r.status == RunStatus::Ok && r.valid)) continue;
    // A reference that ran but is invalid still gave errors: they are marked. One that failed
    // gave none: its reason is what the reader needs.
    if (r.status == RunStatus::Ok)
      return "against an invalid reference (reference: invalid (" + r.invalidReason + "))";
    return "reference: " + notRunReason(r);
  }
  return "";
}

std::string noteOf(const CaseResult& c, const RunRecord* r, bool wantsError) {
  std::string s;
  if (r) {
    appendTo(s, r->message);
    for (const auto& n : r->notes) appendTo(s, n);
  }
  if (wantsError && c.missing.count("reference_fem"))
    appendTo(s, "no error: reference_fem missing (" + c.missing.at("reference_fem") + ")");
  return s;
}

std::string relativeTo(const fs::path& p, const fs::path& base) {
  return fs::relative(p, base).generic_string();
}

void caseCells(ojson& row, const CaseResult& c, const std::string& plugin, const RunRecord* r,
               const fs::path& dir, bool wantsError) {
  std::string status = statusOf(c, plugin, r);
  if (r && !r->isReference) appendTo(status, referenceStatus(c));
  row["status"] = status;
  if (r && r->referenceValid && !*r->referenceValid) row["reference_valid"] = false;
  row["scene"] = relativeTo(c.sceneFile, dir);
  row["note"] = noteOf(c, r, wantsError);
}

const CaseResult* caseOrSkipped(const Results& res, const std::string& id, bool quick, ojson& row) {
  if (res.count(id)) return &res.at(id);
  row["status"] = quick ? "skipped (--quick)" : "not run";
  return nullptr;
}

std::vector<std::string> checkedCases(const TableDef& d, const Results& results) {
  return d.pickChecks ? d.pickChecks(results) : d.checks;
}

TableDef tableDef(const std::string& name, const std::string& title, const std::string& source,
                  std::vector<TableColumn> cols) {
  TableDef t;
  t.name = name;
  t.title = title;
  t.source = source;
  t.columns = std::move(cols);
  return t;
}

ojson inColumnOrder(const ojson& row, const std::vector<TableColumn>& cols) {
  ojson out = ojson::object();
  for (const TableColumn& c : cols)
    if (row.contains(c.key)) out[c.key] = row[c.key];
  for (const auto& [k, v] : row.items())
    if (!out.contains(k)) out[k] = v;
  return out;
}

}  // namespace deform::harness::tables
