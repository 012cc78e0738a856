#include "bem_accuracy.h"

#include "guided_particles.h"

#include <cmath>
#include <functional>

namespace deform::particle_bem {

VecX gaussianTraction(const MatX3& V, const LossRatioCase& c) {
  VecX p = VecX::Zero(3 * V.rows());
  for (Eigen::Index j = 0; j < V.rows(); ++j) {
    const Real d2 = (V.row(j).transpose() - c.center).squaredNorm();
    p.segment<3>(3 * j) = c.traction * std::exp(-d2 / (c.radius * c.radius));
  }
  return p;
}

LossRatioResult bemLossRatio(const SurfaceMesh& coarse, const SurfaceMesh& fine,
                             const Material& material, const LossRatioCase& c,
                             const BemQuadrature& q) {
  LossRatioResult r;
  r.coarseVertices = coarse.numVertices();
  r.fineVertices = fine.numVertices();
  const TractionField field = [&c](const Vec3& x) -> Vec3 {
    return c.traction * std::exp(-(x - c.center).squaredNorm() / (c.radius * c.radius));
  };
  const Real resolution = c.fieldResolution > 0 ? c.fieldResolution : c.radius / 4;
  struct Side {
    const SurfaceMesh* s;
    BemMatrices bem;
    VecX fieldRhs;
    std::function<VecX(const Box&)> maskedRhs;  // the field zero in the (closed) box
  };
  const auto prepare = [&](const SurfaceMesh& s) {
    Side side{&s, assembleBem(s, material.young, material.poisson, q), {}, {}};
    // The support-face solves use the masked field only; without the variants nothing else
    // needs the whole field's right-hand side (an integral over every element per node).
    const bool supportOnly = !c.variants && (c.support == FixedSupport::SupportFaces ||
                                             c.support == FixedSupport::SupportFacesSingular);
    if (!supportOnly)
      side.fieldRhs =
          integrateTractionField(s, material.young, material.poisson, field, resolution, q);
    side.maskedRhs = [&, ps = &s](const Box& box) {
      const TractionField masked = [&](const Vec3& x) -> Vec3 {
        return box.contains(x) ? Vec3::Zero() : field(x);
      };
      return integrateTractionField(*ps, material.young, material.poisson, masked, resolution, q);
    };
    return side;
  };
  const Side fs = prepare(fine), cs = prepare(coarse);
  const TriangleGrid grid(coarse.V, coarse.F), fineGrid(fine.V, fine.F);
  const SurfaceMap map = mapToSurface(grid, fine.V);
  GradientTransfer gradient = makeGradientTransfer(coarse.V, coarse.F, map);
  const MatX3 zeroFine = MatX3::Zero(fine.numVertices(), 3);
  const auto toFine = [&](const MatX3& coarseDisp, SurfaceTransfer t) {
    MatX3 out;
    if (t == SurfaceTransfer::Gradient)
      interpolateDisplacement(map, coarse.F, zeroFine, coarseDisp, gradient, out);
    else
      interpolateDisplacement(map, coarse.F, zeroFine, coarseDisp, out);
    return out;
  };
  const auto lossRatio = [](const MatX3& uo, const MatX3& uimp, Real* displacementRatio) {
    Real num = 0, den = 0, imp = 0;
    for (Eigen::Index v = 0; v < uo.rows(); ++v) {
      num += (uo.row(v) - uimp.row(v)).norm();
      den += uo.row(v).norm();
      imp += uimp.row(v).norm();
    }
    if (displacementRatio) *displacementRatio = den > 0 ? imp / den : 0;
    return den > 0 ? num / den : 0;
  };
  // R for one fixed box and one load representation; nodal loads at fixed nodes are dropped
  // (their tractions are unknowns), which G p did implicitly by zeroing them.
  const auto ratio = [&](const Box& box, bool nodal, FixedSupport support, bool keepStats) {
    const auto solve = [&](const Side& side, int& nFixed) {
      const std::vector<int> fixed = rowsInBox(side.s->V, box);
      nFixed = int(fixed.size());
      if (support == FixedSupport::Partial && !nodal)
        return solveBemPartial(side.bem, *side.s, fixedFractions(*side.s, box), material.young,
                               side.fieldRhs);
      if ((support == FixedSupport::SupportFaces ||
           support == FixedSupport::SupportFacesSingular) &&
          !nodal) {
        SupportColumns sc = supportColumns(*side.s, material.young, material.poisson, fixed, q);
        if (support == FixedSupport::SupportFacesSingular)
          sc = withSingularSupport(
              sc, side.bem.G, singularSupport(*side.s, material.young, material.poisson, fixed));
        return solveBemRhs(side.bem, *side.s, fixed, side.maskedRhs(box), &sc);
      }
      VecX rhs = side.fieldRhs;
      if (nodal) {
        VecX p = gaussianTraction(side.s->V, c);
        for (int j : fixed) p.segment<3>(3 * j).setZero();
        rhs = side.bem.G * p;
      }
      return solveBemRhs(side.bem, *side.s, fixed, rhs);
    };
    int nf = 0, nc = 0;
    const VecX uf = solve(fs, nf), uc = solve(cs, nc);
    MatX3 coarseDisp(coarse.numVertices(), 3), fineDisp(fine.numVertices(), 3);
    for (int j = 0; j < coarse.numVertices(); ++j) coarseDisp.row(j) = uc.segment<3>(3 * j);
    for (int v = 0; v < fine.numVertices(); ++v) fineDisp.row(v) = uf.segment<3>(3 * v);
    if (!keepStats) return lossRatio(fineDisp, toFine(coarseDisp, c.transfer), nullptr);
    r.coarseFixed = nc;
    r.fineFixed = nf;
    Real sum = 0, maxU = 0;
    for (int v = 0; v < fine.numVertices(); ++v) {
      sum += fineDisp.row(v).norm();
      maxU = std::max(maxU, fineDisp.row(v).norm());
    }
    r.maxFineDisplacement = maxU;
    r.meanFineDisplacement = sum / std::max(1, fine.numVertices());
    r.ratioLinearTransfer =
        lossRatio(fineDisp, toFine(coarseDisp, SurfaceTransfer::Linear),
                  c.transfer == SurfaceTransfer::Linear ? &r.displacementRatio : nullptr);
    r.ratioGradientTransfer =
        lossRatio(fineDisp, toFine(coarseDisp, SurfaceTransfer::Gradient),
                  c.transfer == SurfaceTransfer::Gradient ? &r.displacementRatio : nullptr);
    // The transfer alone: the fine solution at the coarse vertices (closest point on the fine
    // surface, linear) and back.
    MatX3 fineAtCoarse;
    interpolateDisplacement(mapToSurface(fineGrid, coarse.V), fine.F,
                            MatX3::Zero(coarse.numVertices(), 3), fineDisp, fineAtCoarse);
    r.roundTripLinear = lossRatio(fineDisp, toFine(fineAtCoarse, SurfaceTransfer::Linear), nullptr);
    r.roundTripGradient =
        lossRatio(fineDisp, toFine(fineAtCoarse, SurfaceTransfer::Gradient), nullptr);
    return c.transfer == SurfaceTransfer::Gradient ? r.ratioGradientTransfer
                                                   : r.ratioLinearTransfer;
  };
  r.ratio = ratio(c.fixedBox, false, c.support, true);
  if (!c.variants) return r;
  r.ratioNodalClamp = c.support != FixedSupport::Clamp
                          ? ratio(c.fixedBox, false, FixedSupport::Clamp, false)
                          : r.ratio;
  r.ratioNodalLoad = ratio(c.fixedBox, true, FixedSupport::Clamp, false);
  r.ratioPartial = c.support != FixedSupport::Partial
                       ? ratio(c.fixedBox, false, FixedSupport::Partial, false)
                       : r.ratio;
  if (c.support == FixedSupport::SupportFacesSingular)
    r.ratioSupportFaces = ratio(c.fixedBox, false, FixedSupport::SupportFaces, false);
  for (Real shift : c.edgeShifts) {
    Box b = c.fixedBox;
    b.hi[2] += shift;
    r.shiftedRatios.push_back(ratio(b, false, c.support, false));
    r.shiftedClampRatios.push_back(c.support != FixedSupport::Clamp
                                       ? ratio(b, false, FixedSupport::Clamp, false)
                                       : r.shiftedRatios.back());
  }
  return r;
}

}  // namespace deform::particle_bem
