// facesOnBoxFaces (box_clip.h), kept out of box_clip.cpp so that it does not need CGAL.
#include <deform/geometry/box_clip.h>

namespace deform {

std::vector<char> facesOnBoxFaces(const MatX3& V, const MatX3i& F, const std::vector<Box>& boxes) {
  std::vector<char> out(size_t(F.rows()), 0);
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    const Vec3 p[3] = {V.row(F(f, 0)).transpose(), V.row(F(f, 1)).transpose(),
                       V.row(F(f, 2)).transpose()};
    for (const Box& b : boxes) {
      if (!b.contains(p[0]) || !b.contains(p[1]) || !b.contains(p[2])) continue;
      for (int k = 0; k < 3 && !out[size_t(f)]; ++k)
        for (const Real v : {b.lo[k], b.hi[k]})
          if (p[0][k] == v && p[1][k] == v && p[2][k] == v) out[size_t(f)] = 1;
      if (out[size_t(f)]) break;
    }
  }
  return out;
}

}  // namespace deform
