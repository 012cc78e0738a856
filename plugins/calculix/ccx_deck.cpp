#include "ccx_deck.h"

#include <cmath>
#include <cstdio>
#include <map>
#include <set>
#include <sstream>
#include <stdexcept>

namespace deform::calculix {

namespace {

/// 14 significant digits: ccx reads at most 20 characters per field ("-1.2345678901234e-05"),
/// and the deck describes the reference's mesh to 1e-14 of each coordinate.
std::string num(double v) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.14g", v);
  return buf;
}

}  // namespace

std::string ccxModelDeck(const CcxModel& model) {
  std::ostringstream s;
  s << "** deformbench calculix plugin: one organ, quasi-static\n";
  s << "*NODE, NSET=NALL\n";
  for (Eigen::Index i = 0; i < model.nodes.rows(); ++i)
    s << i + 1 << ", " << num(model.nodes(i, 0)) << ", " << num(model.nodes(i, 1)) << ", "
      << num(model.nodes(i, 2)) << "\n";
  const bool quadratic = model.elements.cols() == 10;
  s << "*ELEMENT, TYPE=" << (quadratic ? "C3D10" : "C3D4") << ", ELSET=EALL\n";
  for (Eigen::Index t = 0; t < model.elements.rows(); ++t) {
    s << t + 1;
    for (int a = 0; a < model.elements.cols(); ++a) {
      const int local = quadratic ? kCcxC3D10Order[a] : a;
      // ccx takes at most 16 entries per data line; a C3D10 row (11) fits on one.
      s << ", " << model.elements(t, local) + 1;
    }
    s << "\n";
  }
  s << "*MATERIAL, NAME=TISSUE\n";
  const Real mu = model.young / (2 * (1 + model.poisson));
  const Real kappa = model.young / (3 * (1 - 2 * model.poisson));
  if (model.material == CcxMaterial::NeoHookean) {
    s << "*HYPERELASTIC, NEO HOOKE\n" << num(mu / 2) << ", " << num(2 / kappa) << "\n";
  } else {
    s << "*ELASTIC\n" << num(model.young) << ", " << num(model.poisson) << "\n";
  }
  s << "*DENSITY\n" << num(model.density) << "\n";
  s << "*SOLID SECTION, ELSET=EALL, MATERIAL=TISSUE\n";
  bool any = false;
  for (size_t n = 0; n < model.fixedDofs.size(); ++n)
    for (int k = 0; k < 3; ++k)
      if (model.fixedDofs[n][size_t(k)]) {
        if (!any) s << "*BOUNDARY\n";
        any = true;
        s << n + 1 << ", " << k + 1 << ", " << k + 1 << ", 0\n";
      }
  return s.str();
}

std::string ccxStepDeck(const CcxModel& model, const CcxLoads& loads, const CcxIncrements& inc) {
  std::ostringstream s;
  const bool nlgeom = model.material == CcxMaterial::NeoHookean;
  s << "*STEP" << (nlgeom ? ", NLGEOM" : "") << ", INC=" << inc.maxIncrements << "\n";
  s << "*CONTROLS, PARAMETERS=FIELD\n"
    << num(inc.residualTolerance) << ", " << num(10 * inc.residualTolerance) << "\n";
  s << "*STATIC\n"
    << num(nlgeom ? inc.initial : 1.0) << ", 1.0, " << num(inc.minimum) << ", "
    << num(nlgeom ? inc.maximum : 1.0) << "\n";
  if (!loads.displacements.empty() || !loads.dofDisplacements.empty()) {
    s << "*BOUNDARY\n";
    std::set<int> whole;
    for (const auto& [node, u] : loads.displacements) {
      whole.insert(node);
      for (int k = 0; k < 3; ++k)
        s << node + 1 << ", " << k + 1 << ", " << k + 1 << ", " << num(u(k)) << "\n";
    }
    for (const auto& [dof, u] : loads.dofDisplacements)
      if (!whole.count(dof.first))
        s << dof.first + 1 << ", " << dof.second + 1 << ", " << dof.second + 1 << ", " << num(u)
          << "\n";
  }
  std::map<int, Vec3> forces;
  for (const auto& [node, f] : loads.forces) {
    auto it = forces.emplace(node, Vec3::Zero()).first;
    it->second += f;
  }
  bool anyForce = false;
  for (const auto& [node, f] : forces)
    for (int k = 0; k < 3; ++k)
      if (f(k) != 0) {
        if (!anyForce) s << "*CLOAD\n";
        anyForce = true;
        s << node + 1 << ", " << k + 1 << ", " << num(f(k)) << "\n";
      }
  const Real g = loads.gravity.norm();
  if (g > 0) {
    const Vec3 d = loads.gravity / g;
    s << "*DLOAD\nEALL, GRAV, " << num(g) << ", " << num(d(0)) << ", " << num(d(1)) << ", "
      << num(d(2)) << "\n";
  }
  // FREQUENCY larger than any increment count: the tables of the step's last increment only.
  // RF: the reaction force at every node (the force its constraints exert on the tissue; zero,
  // to the solver's tolerance, at a free dof), from which the plates' forces are summed.
  s << "*NODE PRINT, NSET=NALL, FREQUENCY=1000000\nU, RF\n";
  s << "*END STEP\n";
  return s.str();
}

namespace {

/// The last table headed `head` (see ccxLastDisplacements).
MatX3 lastNodeTable(const std::string& dat, const std::string& head, const char* what, int numNodes,
                    double& time) {
  const size_t at = dat.rfind(head);
  if (at == std::string::npos)
    throw std::runtime_error(std::string("ccx's .dat file has no ") + what + " table");
  std::istringstream in(dat.substr(at));
  std::string line;
  std::getline(in, line);
  const size_t t = line.find("time");
  if (t == std::string::npos) throw std::runtime_error("ccx's .dat table has no time: " + line);
  time = std::stod(line.substr(t + 4));
  MatX3 u = MatX3::Constant(numNodes, 3, std::nan(""));
  int read = 0;
  while (std::getline(in, line)) {
    std::istringstream l(line);
    long long node;
    double x, y, z;
    if (!(l >> node)) {
      if (read > 0) break;  // blank line after the table
      continue;
    }
    if (!(l >> x >> y >> z) || node < 1 || node > numNodes)
      throw std::runtime_error("ccx's .dat table has an unreadable line: " + line);
    u.row(Eigen::Index(node - 1)) << x, y, z;
    ++read;
  }
  if (read != numNodes)
    throw std::runtime_error("ccx's .dat table lists " + std::to_string(read) + " of " +
                             std::to_string(numNodes) + " nodes");
  return u;
}

}  // namespace

MatX3 ccxLastDisplacements(const std::string& dat, int numNodes, double& time) {
  return lastNodeTable(dat, "displacements (vx,vy,vz)", "displacement", numNodes, time);
}

MatX3 ccxLastReactionForces(const std::string& dat, int numNodes, double& time) {
  return lastNodeTable(dat, "forces (fx,fy,fz)", "reaction force", numNodes, time);
}

}  // namespace deform::calculix
