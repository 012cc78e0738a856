// A plate pressing the top of a cube whose bottom face is fixed (press.h's cubePress organ),
// bonded or sliding (GraspInput::slideNormal), driven without the harness: shared by the models
// with the "sliding" capability. With nu > 0 a sliding plate lets the top face spread out (the
// cube nearer uniaxial stress), so against a bonded one its top vertices move outward and the
// plate needs less force; both push the top face down by the plate's travel.
#pragma once

#include <deform/sdk/model.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <utility>
#include <vector>

namespace deform::testing {

struct PlateRun {
  Real drop = 0;     ///< m, mean downward displacement of the top vertices
  Real outward = 0;  ///< m, mean outward lateral displacement of the top vertices
  Real force = 0;    ///< N, the plate's force along +z (NaN when the model reports none)
  bool ok = true;    ///< every step returned Ok
  /// N, the plate's whole force vector (NaN when the model reports none)
  Vec3 forceVector = Vec3::Constant(std::nan(""));
};

/// Moves a plate holding the top vertices of `organ` (model initialised on it, at rest) down by
/// `press` over `ramp` steps of dt and holds it `hold` steps; the model is reset first.
inline PlateRun pressByPlate(Model& model, const Organ& organ, bool sliding, Real press, int ramp,
                             int hold, Real dt = 1e-3) {
  model.reset();
  const MatX3& rest = organ.surface.V;
  const Real top = rest.col(2).maxCoeff(), eps = 1e-6;
  GraspInput g;
  g.tool = 0;
  for (Eigen::Index v = 0; v < rest.rows(); ++v)
    if (rest(v, 2) > top - eps) g.vertices.push_back(int(v));
  if (sliding) g.slideNormal = Vec3(0, 0, -1);
  PlateRun r;
  StepInput in;
  in.dt = dt;
  for (int s = 0; s < ramp + hold; ++s) {
    const Real offset = -press * std::min<Real>(1, Real(s + 1) / ramp);
    g.targets.resize(Eigen::Index(g.vertices.size()), 3);
    for (size_t k = 0; k < g.vertices.size(); ++k)
      g.targets.row(Eigen::Index(k)) = rest.row(g.vertices[k]) + Vec3(0, 0, offset).transpose();
    in.time = s * dt;
    in.grasps = {g};
    if (model.step(in) != StepStatus::Ok) r.ok = false;
  }
  const MatX3& x = model.surface();
  int n = 0;
  for (int v : g.vertices) {
    r.drop += (rest(v, 2) - x(v, 2)) / Real(g.vertices.size());
    const Vec3 radial(rest(v, 0), rest(v, 1), 0);
    if (radial.norm() < 1e-9) continue;
    r.outward += radial.normalized().dot((x.row(v) - rest.row(v)).transpose());
    ++n;
  }
  r.outward /= std::max(n, 1);
  const std::vector<Vec3> f = model.graspForces();
  r.force = f.empty() ? std::nan("") : f[0].z();
  if (!f.empty()) r.forceVector = f[0];
  return r;
}

/// The sliding plate against the bonded one (see the file comment): both drop the top by the
/// travel (within dropTolerance of it), the sliding top spreads outward (by at least a tenth of
/// nu press / 2, the uniaxial figure at the edge's middle of a cube as high as wide, and 10 times
/// more than the bonded one), and the sliding plate's force is lower where the model reports one.
inline void expectSlidingSpreadsTheTopAndEasesThePlate(Model& model, const Organ& organ, Real press,
                                                       int ramp, int hold, const char* label,
                                                       Real dropTolerance = 0.05) {
  const PlateRun sliding = pressByPlate(model, organ, true, press, ramp, hold);
  const PlateRun bonded = pressByPlate(model, organ, false, press, ramp, hold);
  std::printf(
      "%s: drop %.4f / %.4f mm, outward %.4f / %.4f mm, force %.4g / %.4g N "
      "(sliding / bonded)\n",
      label, 1e3 * sliding.drop, 1e3 * bonded.drop, 1e3 * sliding.outward, 1e3 * bonded.outward,
      sliding.force, bonded.force);
  ASSERT_TRUE(sliding.ok && bonded.ok) << label;
  EXPECT_NEAR(sliding.drop, press, dropTolerance * press) << label;
  EXPECT_NEAR(bonded.drop, press, dropTolerance * press) << label;
  const Real nu = organ.material.poisson;
  EXPECT_GT(sliding.outward, 0.1 * nu * press / 2) << label;
  EXPECT_GT(sliding.outward, 10 * std::abs(bonded.outward)) << label;
  if (!std::isnan(sliding.force)) {
    EXPECT_GT(sliding.force, 0) << label;
    EXPECT_LT(sliding.force, bonded.force) << label;
  }
}

/// A bonded plate's force (pressByPlate) is reported, positive along the press (the tissue pushes
/// the plate back up, +z) and within a factor `factor` of `expected` (N; e.g. reference_fem's on
/// the same cube and travel: 1.1 N for cubePress's 10 cm cube, E 5500 Pa, nu 0.3, at 2 mm).
inline PlateRun expectBondedPlateForceNear(Model& model, const Organ& organ, Real press, int ramp,
                                           int hold, Real expected, Real factor,
                                           const char* label) {
  const PlateRun bonded = pressByPlate(model, organ, false, press, ramp, hold);
  std::printf("%s: bonded plate force %.4g N (expected %.4g N within a factor %.3g)\n", label,
              bonded.force, expected, factor);
  EXPECT_TRUE(bonded.ok) << label;
  EXPECT_FALSE(std::isnan(bonded.force)) << label << ": no plate force reported";
  EXPECT_GT(bonded.force, expected / factor) << label;
  EXPECT_LT(bonded.force, expected * factor) << label;
  return bonded;
}

/// Both plates' forces (pressByPlate, sliding then bonded): each reported; the bonded one
/// positive along the press and within a factor `factor` of `expected` (N, as
/// expectBondedPlateForceNear); the sliding one positive, not above the bonded one, and with no
/// component along the plate (a frictionless platen: below 1e-9 of its normal force). Returns
/// {sliding, bonded}.
inline std::pair<PlateRun, PlateRun> expectPlateForcesNear(Model& model, const Organ& organ,
                                                           Real press, int ramp, int hold,
                                                           Real expected, Real factor,
                                                           const char* label) {
  const PlateRun sliding = pressByPlate(model, organ, true, press, ramp, hold);
  const PlateRun bonded = pressByPlate(model, organ, false, press, ramp, hold);
  std::printf(
      "%s: plate force %.4g / %.4g N (sliding / bonded; expected %.4g N within a factor %.3g), "
      "sliding tangential %.3g N\n",
      label, sliding.force, bonded.force, expected, factor, sliding.forceVector.head<2>().norm());
  EXPECT_TRUE(sliding.ok && bonded.ok) << label;
  EXPECT_FALSE(std::isnan(bonded.force)) << label << ": no bonded plate force reported";
  EXPECT_FALSE(std::isnan(sliding.force)) << label << ": no sliding plate force reported";
  EXPECT_GT(bonded.force, expected / factor) << label;
  EXPECT_LT(bonded.force, expected * factor) << label;
  EXPECT_GT(sliding.force, 0) << label;
  EXPECT_LE(sliding.force, bonded.force) << label;
  EXPECT_LE(sliding.forceVector.head<2>().norm(), 1e-9 * std::abs(sliding.force)) << label;
  return {sliding, bonded};
}

/// Holds the top vertices of `organ` (as pressByPlate) with a plate at rest, bonded or sliding,
/// and pushes each along +x with `force` (N) for `steps` steps of dt; the model is reset first.
/// Returns the mean x displacement of the top vertices (m); heightMiss: the largest |z - z0|
/// among them.
inline Real shearUnderPlate(Model& model, const Organ& organ, bool sliding, Real force, int steps,
                            Real& heightMiss, Real dt = 1e-3) {
  model.reset();
  const MatX3& rest = organ.surface.V;
  const Real top = rest.col(2).maxCoeff(), eps = 1e-6;
  GraspInput g;
  for (Eigen::Index v = 0; v < rest.rows(); ++v)
    if (rest(v, 2) > top - eps) g.vertices.push_back(int(v));
  g.targets = rest(g.vertices, Eigen::all);
  if (sliding) g.slideNormal = Vec3(0, 0, -1);
  StepInput in;
  in.dt = dt;
  in.grasps = {g};
  for (int v : g.vertices) in.loads.push_back(PointLoad::onVertex(v, Vec3(force, 0, 0)));
  for (int s = 0; s < steps; ++s) {
    in.time = s * dt;
    EXPECT_EQ(model.step(in), StepStatus::Ok);
  }
  Real dx = 0;
  heightMiss = 0;
  for (int v : g.vertices) {
    dx += (model.surface()(v, 0) - rest(v, 0)) / Real(g.vertices.size());
    heightMiss = std::max(heightMiss, std::abs(model.surface()(v, 2) - rest(v, 2)));
  }
  return dx;
}

/// The sliding plate leaves the top free along it: a load along the plate moves the top along it
/// by more than minSlide (m) under a sliding plate and by less than a tenth of that under a
/// bonded one; the top stays on the plate (within heightTolerance, m) either way.
inline void expectSlidingLetsTheTopSlide(Model& model, const Organ& organ, Real force, int steps,
                                         Real minSlide, Real heightTolerance, const char* label) {
  Real missSliding = 0, missBonded = 0;
  const Real sliding = shearUnderPlate(model, organ, true, force, steps, missSliding);
  const Real bonded = shearUnderPlate(model, organ, false, force, steps, missBonded);
  std::printf(
      "%s, %.3g N along x on each top vertex: top moves %.4f / %.4f mm, off the plate "
      "%.2g / %.2g mm (sliding / bonded)\n",
      label, force, 1e3 * sliding, 1e3 * bonded, 1e3 * missSliding, 1e3 * missBonded);
  EXPECT_GT(sliding, minSlide) << label;
  EXPECT_LT(std::abs(bonded), 0.1 * sliding) << label;
  EXPECT_LT(missSliding, heightTolerance) << label;
  EXPECT_LT(missBonded, heightTolerance) << label;
}

}  // namespace deform::testing
