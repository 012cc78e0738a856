#include "skinning.h"

#include <deform/kdtree.h>

#include <algorithm>
#include <utility>

namespace deform::metaballs {

Skinning buildSkinning(const MatX3& V, const SphereSet& spheres, Real threshold, int maxSpheres) {
  Skinning sk;
  const int nv = int(V.rows());
  const int K = std::max(1, maxSpheres);
  sk.numVertices = nv;
  sk.slots = K;
  sk.sphere.assign(size_t(nv) * K, 0);
  sk.weight.assign(size_t(nv) * K, 0.0);
  sk.restRadiusSum.assign(size_t(nv), 0.0);
  sk.dispX.assign(size_t(nv), 0.0);
  sk.dispY.assign(size_t(nv), 0.0);
  sk.dispZ.assign(size_t(nv), 0.0);
  if (spheres.size() == 0) return sk;
  const KdTree3 tree(spheres.centers);
  // f >= T  <=>  |d - r| <= r sqrt(-ln T)  =>  d <= r (1 + sqrt(-ln T)).
  const Real reach = 1 + std::sqrt(std::max(Real(0), -std::log(threshold)));
  const Real rmax = spheres.radii.maxCoeff();
  std::vector<int> hits;
  std::vector<std::pair<Real, int>> att;  // (-f, sphere): strongest first, ties by index
  for (int v = 0; v < nv; ++v) {
    const Vec3 x = V.row(v);
    tree.radius(x, rmax * reach, hits);
    att.clear();
    for (int i : hits) {
      const Real f = fieldStrength((x - spheres.center(i)).norm(), spheres.radii(i));
      if (f >= threshold) att.emplace_back(-f, i);
    }
    if (att.empty()) {
      ++sk.fallbacks;
      Real best = -1;
      int bi = 0;
      for (int i = 0; i < spheres.size(); ++i) {
        const Real f = fieldStrength((x - spheres.center(i)).norm(), spheres.radii(i));
        if (f > best) {
          best = f;
          bi = i;
        }
      }
      att.emplace_back(-best, bi);
    }
    std::sort(att.begin(), att.end());
    if (int(att.size()) > K) att.resize(size_t(K));
    Real fsum = 0, rsum = 0;
    for (const auto& [nf, i] : att) {
      fsum += -nf;
      rsum += spheres.radii(i);
    }
    Vec3 cc = Vec3::Zero();
    for (size_t s = 0; s < att.size(); ++s) {
      const size_t slot = size_t(v) * K + s;
      sk.sphere[slot] = att[s].second;
      sk.weight[slot] = fsum > 0 ? -att[s].first / fsum : 1.0 / Real(att.size());
    }
    // c_center exactly as applySkinning evaluates it, so that the rest pose is reproduced.
    for (int s = 0; s < K; ++s) {
      const size_t slot = size_t(v) * K + s;
      cc += sk.weight[slot] * spheres.center(sk.sphere[slot]);
    }
    sk.attachments += int(att.size());
    sk.restRadiusSum[size_t(v)] = rsum;
    sk.dispX[size_t(v)] = x.x() - cc.x();
    sk.dispY[size_t(v)] = x.y() - cc.y();
    sk.dispZ[size_t(v)] = x.z() - cc.z();
  }
  return sk;
}

void applySkinning(const Skinning& sk, const MatX3& centers, const VecX& radii,
                   const Real* rotations, MatX3& out) {
  const int K = sk.slots;
  const Real* c = centers.data();  // row-major: x, y, z of sphere i at 3i
  const Real* r = radii.data();
  Real* o = out.data();
  for (int v = 0; v < sk.numVertices; ++v) {
    const int* sp = sk.sphere.data() + size_t(v) * K;
    const Real* w = sk.weight.data() + size_t(v) * K;
    Real cx = 0, cy = 0, cz = 0, rs = 0;
    for (int s = 0; s < K; ++s) {
      const Real* ci = c + 3 * sp[s];
      cx += w[s] * ci[0];
      cy += w[s] * ci[1];
      cz += w[s] * ci[2];
      rs += w[s] > 0 ? r[sp[s]] : 0;
    }
    const Real scale = rs / sk.restRadiusSum[size_t(v)];
    Real dx = sk.dispX[size_t(v)], dy = sk.dispY[size_t(v)], dz = sk.dispZ[size_t(v)];
    if (rotations) {
      Real m[9] = {0, 0, 0, 0, 0, 0, 0, 0, 0};
      for (int s = 0; s < K; ++s) {
        const Real* R = rotations + 9 * sp[s];
        for (int q = 0; q < 9; ++q) m[q] += w[s] * R[q];
      }
      const Real rx = m[0] * dx + m[1] * dy + m[2] * dz;
      const Real ry = m[3] * dx + m[4] * dy + m[5] * dz;
      const Real rz = m[6] * dx + m[7] * dy + m[8] * dz;
      dx = rx;
      dy = ry;
      dz = rz;
    }
    o[3 * v + 0] = cx + scale * dx;
    o[3 * v + 1] = cy + scale * dy;
    o[3 * v + 2] = cz + scale * dz;
  }
}

}  // namespace deform::metaballs
