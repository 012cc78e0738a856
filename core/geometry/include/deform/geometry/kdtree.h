// deformbench SDK: a k-d tree over 3-D points (a thin wrapper over nanoflann 1.4) for
// k-nearest-neighbour and fixed-radius queries. Results are deterministic: sorted by distance,
// ties broken by point index.
#pragma once

#include <deform/sdk/types.h>

#include <memory>
#include <vector>

namespace deform {

class KdTree3 {
 public:
  KdTree3();
  /// points: #P by 3 (copied; the tree does not refer to the caller's matrix).
  explicit KdTree3(const MatX3& points);
  ~KdTree3();
  KdTree3(KdTree3&&) noexcept;
  KdTree3& operator=(KdTree3&&) noexcept;
  KdTree3(const KdTree3&) = delete;
  KdTree3& operator=(const KdTree3&) = delete;

  /// Rebuilds the tree over new points.
  void build(const MatX3& points);
  int size() const;
  const MatX3& points() const;

  /// The k points nearest to p (k clamped to size()), nearest first. dist2 (optional) receives
  /// the squared distances.
  void knn(const Vec3& p, int k, std::vector<int>& indices,
           std::vector<Real>* dist2 = nullptr) const;
  /// Every point with |x - p| <= radius, nearest first.
  void radius(const Vec3& p, Real radius, std::vector<int>& indices,
              std::vector<Real>* dist2 = nullptr) const;
  /// Index of the nearest point (-1 when empty).
  int nearest(const Vec3& p) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> m_impl;
};

}  // namespace deform
