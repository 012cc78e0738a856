#include "sphere_merging.h"

#include <deform/geometry/kdtree.h>

#include <algorithm>
#include <tuple>
#include <vector>

namespace deform::metaballs {

MergeResult mergeOverlappingSpheres(SphereSet& spheres, const MeshDistance& dist, int maxPasses) {
  MergeResult res;
  std::vector<int> hits;
  for (int pass = 0; pass < maxPasses && spheres.size() > 1; ++pass) {
    const KdTree3 tree(spheres.centers);
    std::vector<std::tuple<Real, int, int>> pairs;  // (d / r_small, i, j), i < j
    for (int i = 0; i < spheres.size(); ++i) {
      tree.radius(spheres.center(i), spheres.radii(i), hits);
      for (int j : hits) {
        if (j <= i) continue;
        const Real d = (spheres.center(i) - spheres.center(j)).norm();
        const Real rs = std::min(spheres.radii(i), spheres.radii(j));
        if (d < rs) pairs.emplace_back(d / rs, i, j);
      }
    }
    if (pairs.empty()) break;
    ++res.passes;
    std::sort(pairs.begin(), pairs.end());
    std::vector<uint8_t> used(size_t(spheres.size()), 0), keep(size_t(spheres.size()), 1);
    SphereSet merged;
    for (const auto& [ratio, i, j] : pairs) {
      if (used[size_t(i)] || used[size_t(j)]) continue;
      const Vec3 c = 0.5 * (spheres.center(i) + spheres.center(j));
      // In a concave region the midpoint can leave the organ: keep that pair unmerged.
      const Real sd = dist.signedDistance(c);
      if (sd >= 0) continue;
      used[size_t(i)] = used[size_t(j)] = 1;
      keep[size_t(i)] = keep[size_t(j)] = 0;
      const Real r = std::max(spheres.radii(i), spheres.radii(j));
      merged.append(c, std::min(r, -sd));
      ++res.merged;
    }
    spheres.keep(keep);
    for (int k = 0; k < merged.size(); ++k) spheres.append(merged.center(k), merged.radii(k));
  }
  return res;
}

}  // namespace deform::metaballs
