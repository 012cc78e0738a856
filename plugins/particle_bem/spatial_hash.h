// particle_bem: spatial hashing for neighbour search and particle collisions (Teschner et al.
// 2003, "Optimized spatial hashing for collision detection of deformable objects", the paper's
// ref. [15]). Space is cut into cubic cells of size `cellSize`; cell (i, j, k) goes to bucket
// (i*73856093 xor j*19349663 xor k*83492791) mod tableSize (a power of two here). build() sorts the
// points into buckets by counting sort (O(N), no allocation after the first build of a given size).
#pragma once

#include <deform/sdk/types.h>

#include <cmath>
#include <vector>

namespace deform::particle_bem {

class SpatialHash {
 public:
  /// Table sizes are rounded up to a power of two (the bucket is the hash masked, no division);
  /// tableSize <= 0: chosen at build() as >= twice the point count.
  explicit SpatialHash(Real cellSize = 1, int tableSize = 0)
      : m_cell(cellSize), m_table(tableSize) {}

  void setCellSize(Real cellSize) { m_cell = cellSize; }
  Real cellSize() const { return m_cell; }

  /// Buckets the rows of P (#N by 3). P must stay alive and unchanged while querying.
  void build(const MatX3& P);

  /// Calls f(j, distance) for every built point j with |P_j - p| < radius (radius <= cellSize
  /// searches the 27 cells around p; larger radii search more). Hash collisions are filtered
  /// by the distance test.
  template <class F>
  void forEachWithin(const Vec3& p, Real radius, F&& f) const {
    const int r = int(std::ceil(radius / m_cell));
    const long long ci = cellCoord(p[0]), cj = cellCoord(p[1]), ck = cellCoord(p[2]);
    const Real r2 = radius * radius;
    ++m_query;
    for (long long i = ci - r; i <= ci + r; ++i)
      for (long long j = cj - r; j <= cj + r; ++j)
        for (long long k = ck - r; k <= ck + r; ++k) {
          const int b = bucket(i, j, k);
          // Two cells of the search box may share a bucket: visit each bucket once.
          if (m_bucketStamp[b] == m_query) continue;
          m_bucketStamp[b] = m_query;
          for (int t = m_start[b]; t < m_start[b + 1]; ++t) {
            const int q = m_sorted[t];
            const Real d2 = (m_points->row(q).transpose() - p).squaredNorm();
            if (d2 < r2) f(q, std::sqrt(d2));
          }
        }
  }

  /// All pairs (i < j) closer than radius (radius <= cellSize), appended to out.
  void pairsWithin(Real radius, std::vector<std::pair<int, int>>& out) const;

  int tableSize() const { return m_table; }

 private:
  long long cellCoord(Real x) const { return (long long)std::floor(x / m_cell); }
  int bucket(long long i, long long j, long long k) const {
    const unsigned long long h = (unsigned long long)(i * 73856093LL) ^
                                 (unsigned long long)(j * 19349663LL) ^
                                 (unsigned long long)(k * 83492791LL);
    return int(h & (unsigned long long)(m_tableUsed - 1));
  }
  Real m_cell;
  int m_table;
  int m_tableUsed = 1;
  const MatX3* m_points = nullptr;
  std::vector<int> m_start, m_sorted, m_bucketOf;
  mutable std::vector<unsigned> m_bucketStamp;
  mutable unsigned m_query = 0;
};

}  // namespace deform::particle_bem
