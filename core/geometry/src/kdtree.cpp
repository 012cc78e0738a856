#include <deform/geometry/kdtree.h>

#include <algorithm>
#include <nanoflann.hpp>
#include <numeric>

namespace deform {

namespace {
struct PointCloud {
  MatX3 pts;
  size_t kdtree_get_point_count() const { return size_t(pts.rows()); }
  Real kdtree_get_pt(size_t i, size_t d) const { return pts(Eigen::Index(i), Eigen::Index(d)); }
  template <class B>
  bool kdtree_get_bbox(B&) const {
    return false;
  }
};
using Index = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<Real, PointCloud>,
                                                  PointCloud, 3, uint32_t>;

// nanoflann orders equal distances by traversal; sort by (distance, index) for determinism.
void sortByDistanceThenIndex(std::vector<int>& idx, std::vector<Real>& d2) {
  std::vector<size_t> order(idx.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::sort(order.begin(), order.end(), [&](size_t a, size_t b) {
    return d2[a] < d2[b] || (d2[a] == d2[b] && idx[a] < idx[b]);
  });
  std::vector<int> i2(idx.size());
  std::vector<Real> dd(idx.size());
  for (size_t k = 0; k < order.size(); ++k) {
    i2[k] = idx[order[k]];
    dd[k] = d2[order[k]];
  }
  idx.swap(i2);
  d2.swap(dd);
}
}  // namespace

struct KdTree3::Impl {
  PointCloud cloud;
  std::unique_ptr<Index> index;
  void build() {
    index = std::make_unique<Index>(3, cloud, nanoflann::KDTreeSingleIndexAdaptorParams(10));
    if (cloud.pts.rows() > 0) index->buildIndex();
  }
};

KdTree3::KdTree3() : m_impl(std::make_unique<Impl>()) {
  m_impl->build();
}
KdTree3::KdTree3(const MatX3& points) : m_impl(std::make_unique<Impl>()) {
  build(points);
}
KdTree3::~KdTree3() = default;
KdTree3::KdTree3(KdTree3&&) noexcept = default;
KdTree3& KdTree3::operator=(KdTree3&&) noexcept = default;

void KdTree3::build(const MatX3& points) {
  m_impl->cloud.pts = points;
  m_impl->build();
}

int KdTree3::size() const {
  return int(m_impl->cloud.pts.rows());
}
const MatX3& KdTree3::points() const {
  return m_impl->cloud.pts;
}

void KdTree3::knn(const Vec3& p, int k, std::vector<int>& indices, std::vector<Real>* dist2) const {
  indices.clear();
  if (dist2) dist2->clear();
  k = std::min(k, size());
  if (k <= 0) return;
  std::vector<uint32_t> idx(static_cast<size_t>(k));
  std::vector<Real> d2(static_cast<size_t>(k));
  const size_t found = m_impl->index->knnSearch(p.data(), size_t(k), idx.data(), d2.data());
  indices.assign(idx.begin(), idx.begin() + long(found));
  d2.resize(found);
  sortByDistanceThenIndex(indices, d2);
  if (dist2) *dist2 = std::move(d2);
}

void KdTree3::radius(const Vec3& p, Real radius, std::vector<int>& indices,
                     std::vector<Real>* dist2) const {
  indices.clear();
  if (dist2) dist2->clear();
  if (size() == 0 || !(radius >= 0)) return;
  std::vector<std::pair<uint32_t, Real>> hits;
  nanoflann::SearchParams sp;
  sp.sorted = false;
  // nanoflann's L2 metric works on squared distances; include the boundary.
  m_impl->index->radiusSearch(p.data(), radius * radius * (1 + 1e-12), hits, sp);
  std::vector<Real> d2;
  indices.reserve(hits.size());
  d2.reserve(hits.size());
  for (const auto& [i, d] : hits) {
    if (d <= radius * radius) {
      indices.push_back(int(i));
      d2.push_back(d);
    }
  }
  sortByDistanceThenIndex(indices, d2);
  if (dist2) *dist2 = std::move(d2);
}

int KdTree3::nearest(const Vec3& p) const {
  std::vector<int> idx;
  knn(p, 1, idx);
  return idx.empty() ? -1 : idx[0];
}

}  // namespace deform
