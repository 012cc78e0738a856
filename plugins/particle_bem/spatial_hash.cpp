#include "spatial_hash.h"

#include <algorithm>

namespace deform::particle_bem {

void SpatialHash::build(const MatX3& P) {
  m_points = &P;
  const int n = int(P.rows());
  const int wanted = m_table > 0 ? m_table : std::max(1, 2 * n);
  m_tableUsed = 1;
  while (m_tableUsed < wanted) m_tableUsed *= 2;
  m_start.assign(m_tableUsed + 1, 0);
  if (int(m_bucketStamp.size()) != m_tableUsed) {
    m_bucketStamp.assign(m_tableUsed, 0);
    m_query = 0;
  }
  m_bucketOf.resize(n);
  for (int q = 0; q < n; ++q) {
    m_bucketOf[q] = bucket(cellCoord(P(q, 0)), cellCoord(P(q, 1)), cellCoord(P(q, 2)));
    ++m_start[m_bucketOf[q] + 1];
  }
  for (int b = 0; b < m_tableUsed; ++b) m_start[b + 1] += m_start[b];
  m_sorted.resize(n);
  std::vector<int> fill(m_start.begin(), m_start.end() - 1);
  for (int q = 0; q < n; ++q) m_sorted[fill[m_bucketOf[q]]++] = q;
}

void SpatialHash::pairsWithin(Real radius, std::vector<std::pair<int, int>>& out) const {
  if (!m_points) return;
  for (int i = 0; i < m_points->rows(); ++i) {
    forEachWithin(m_points->row(i).transpose(), radius, [&](int j, Real) {
      if (j > i) out.emplace_back(i, j);
    });
  }
}

}  // namespace deform::particle_bem
