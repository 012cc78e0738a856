#include "skinning.h"

#include <deform/geometry/kdtree.h>

#include <algorithm>
#include <cstdint>

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
#include <immintrin.h>
#endif
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
  sk.count.assign(size_t(nv), 0);
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
    sk.count[size_t(v)] = int(att.size());
    sk.restRadiusSum[size_t(v)] = rsum;
    sk.dispX[size_t(v)] = x.x() - cc.x();
    sk.dispY[size_t(v)] = x.y() - cc.y();
    sk.dispZ[size_t(v)] = x.z() - cc.z();
  }
  return sk;
}

void packSphereFrames(const MatX3& centers, const VecX& radii, const Real* rotations,
                      std::vector<Real>& frames) {
  const int n = int(radii.size());
  const Real* c = centers.data();
  for (int i = 0; i < n; ++i) {
    Real* f = frames.data() + size_t(kFrameStride) * size_t(i);
    f[0] = c[3 * i];
    f[1] = c[3 * i + 1];
    f[2] = c[3 * i + 2];
    f[3] = radii(i);
    for (int q = 0; q < 9; ++q) f[4 + q] = rotations ? rotations[9 * i + q] : (q % 4 == 0);
    f[13] = f[14] = f[15] = 0;
  }
}

namespace {

// v' from the blended record acc (weighted sums, acc[3] unused) and the plain radius sum.
inline void finishVertex(const Skinning& sk, int v, const Real* acc, Real rs, bool rotate,
                         Real* o) {
  const Real scale = rs / sk.restRadiusSum[size_t(v)];
  Real dx = sk.dispX[size_t(v)], dy = sk.dispY[size_t(v)], dz = sk.dispZ[size_t(v)];
  if (rotate) {
    const Real* m = acc + 4;
    const Real rx = m[0] * dx + m[1] * dy + m[2] * dz;
    const Real ry = m[3] * dx + m[4] * dy + m[5] * dz;
    const Real rz = m[6] * dx + m[7] * dy + m[8] * dz;
    dx = rx;
    dy = ry;
    dz = rz;
  }
  o[0] = acc[0] + scale * dx;
  o[1] = acc[1] + scale * dy;
  o[2] = acc[2] + scale * dz;
}

#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
__attribute__((target("avx512f"))) void skinAvx512(const Skinning& sk, const Real* frames,
                                                   bool rotate, Real* out) {
  const int K = sk.slots;
  alignas(64) Real acc[kFrameStride];
  for (int v = 0; v < sk.numVertices; ++v) {
    const int* sp = sk.sphere.data() + size_t(v) * K;
    const Real* w = sk.weight.data() + size_t(v) * K;
    __m512d a0 = _mm512_setzero_pd(), a1 = _mm512_setzero_pd();
    Real rs = 0;
    for (int s = 0; s < sk.count[size_t(v)]; ++s) {
      const Real* f = frames + size_t(kFrameStride) * size_t(sp[s]);
      const __m512d ws = _mm512_set1_pd(w[s]);
      a0 = _mm512_add_pd(a0, _mm512_mul_pd(ws, _mm512_loadu_pd(f)));
      a1 = _mm512_add_pd(a1, _mm512_mul_pd(ws, _mm512_loadu_pd(f + 8)));
      rs += f[3];
    }
    _mm512_store_pd(acc, a0);
    _mm512_store_pd(acc + 8, a1);
    finishVertex(sk, v, acc, rs, rotate, out + 3 * size_t(v));
  }
}
bool skinSimd() {
  return __builtin_cpu_supports("avx512f");
}
#else
bool skinSimd() {
  return false;
}
#endif

}  // namespace

void applySkinningFrames(const Skinning& sk, const Real* frames, bool rotate, MatX3& out,
                         bool simd) {
#if defined(__x86_64__) && (defined(__GNUC__) || defined(__clang__))
  static const bool kSimd = skinSimd();
  if (simd && kSimd) {
    skinAvx512(sk, frames, rotate, out.data());
    return;
  }
#endif
  const int K = sk.slots;
  Real acc[kFrameStride];
  for (int v = 0; v < sk.numVertices; ++v) {
    const int* sp = sk.sphere.data() + size_t(v) * K;
    const Real* w = sk.weight.data() + size_t(v) * K;
    for (int q = 0; q < kFrameStride; ++q) acc[q] = 0;
    Real rs = 0;
    for (int s = 0; s < sk.count[size_t(v)]; ++s) {
      const Real* f = frames + size_t(kFrameStride) * size_t(sp[s]);
      for (int q = 0; q < kFrameStride; ++q) acc[q] = acc[q] + w[s] * f[q];
      rs += f[3];
    }
    finishVertex(sk, v, acc, rs, rotate, out.data() + 3 * size_t(v));
  }
}

void applySkinning(const Skinning& sk, const MatX3& centers, const VecX& radii,
                   const Real* rotations, MatX3& out) {
  std::vector<Real> frames(size_t(kFrameStride) * size_t(radii.size()));
  packSphereFrames(centers, radii, rotations, frames);
  applySkinningFrames(sk, frames.data(), rotations != nullptr, out);
}

}  // namespace deform::metaballs
