#include "vacant_space_filling.h"

#include <deform/geometry/kdtree.h>

#include <vector>

namespace deform::metaballs {

Vec3 gapMidpoint(const Vec3& c1, Real r1, const Vec3& c2, Real r2) {
  const Real d = (c1 - c2).norm();
  if (!(d > 0)) return c1;
  return (d + r2 - r1) / (2 * d) * c1 + (d + r1 - r2) / (2 * d) * c2;
}

FillResult fillVacantSpace(SphereSet& spheres, const MeshDistance& dist, const FillParams& p) {
  FillResult res;
  int frontBegin = 0;  // spheres of the current generation: [frontBegin, size)
  std::vector<int> nb, hits;
  for (int gen = 0; gen < p.maxGenerations; ++gen) {
    const int frontEnd = spheres.size();
    if (frontBegin >= frontEnd) break;
    ++res.generations;
    const KdTree3 tree(spheres.centers);
    const Real rmax = spheres.radii.maxCoeff();
    for (int s = frontBegin; s < frontEnd; ++s) {
      const Vec3 c1 = spheres.center(s);
      tree.knn(c1, p.neighbours + 1, nb);
      for (int j : nb) {
        if (j == s) continue;
        const Vec3 cn = gapMidpoint(c1, spheres.radii(s), spheres.center(j), spheres.radii(j));
        // Inside any sphere of the set at the start of this round?
        tree.radius(cn, rmax, hits);
        bool covered = false;
        for (int h : hits) {
          if ((cn - spheres.center(h)).norm() < spheres.radii(h)) {
            covered = true;
            break;
          }
        }
        // ... or of a sphere added during this round (not yet in the tree).
        for (int h = frontEnd; h < spheres.size() && !covered; ++h)
          covered = (cn - spheres.center(h)).norm() < spheres.radii(h);
        if (covered) continue;
        const Real sd = dist.signedDistance(cn);
        if (sd >= 0 || -sd < p.minRadius) continue;
        spheres.append(cn, -sd);
        ++res.added;
      }
    }
    frontBegin = frontEnd;
  }
  return res;
}

}  // namespace deform::metaballs
