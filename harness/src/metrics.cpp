// Error metrics and step-time statistics (see metrics.h for the definitions).
#include <deform/engine/interaction.h>
#include <deform/sdk/mesh.h>
#include <deform_harness/metrics.h>

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <numeric>

namespace deform::harness {

ErrorMetrics computeErrors(const MatX3& model, const MatX3& reference, const MatX3& rest,
                           const Vec3& focus, const std::vector<int>& nearest) {
  return computeErrors(std::vector<MatX3>{model}, std::vector<MatX3>{reference}, rest, focus,
                       nearest);
}

ErrorMetrics computeErrors(const std::vector<MatX3>& model, const std::vector<MatX3>& reference,
                           const MatX3& rest, const Vec3& focus, const std::vector<int>& nearest) {
  return computeErrors(model, reference, rest, focus, nearest, {});
}

std::vector<int> graspedSurfaceVertices(const Scene& scene, const MatX3& rest) {
  std::vector<int> out;
  for (const ToolSpec& tool : scene.tools) {
    if (tool.type != ToolType::Grasper) continue;
    bool closed = false;
    for (const KeyFrame& k : tool.trajectory) {
      if (k.jawClosed && !closed) {
        const std::vector<int> g = deform::graspedSurfaceVertices(rest, k.pos, tool.radius);
        out.insert(out.end(), g.begin(), g.end());
      }
      closed = k.jawClosed;
    }
  }
  std::sort(out.begin(), out.end());
  out.erase(std::unique(out.begin(), out.end()), out.end());
  return out;
}

std::vector<int> rmseExcludedVertices(const Scene& scene, const MatX3& rest) {
  if (!scene.loads.empty()) return {};
  return graspedSurfaceVertices(scene, rest);
}

ErrorMetrics computeErrors(const std::vector<MatX3>& model, const std::vector<MatX3>& reference,
                           const MatX3& rest, const Vec3& focus, const std::vector<int>& nearest,
                           const std::vector<int>& excluded) {
  assert(model.size() == reference.size());
  ErrorMetrics m;
  m.instants = static_cast<int>(model.size());
  const Eigen::Index nv = rest.rows();
  double sumSq = 0, sumDist = 0, sumRef = 0;
  long long count = 0;
  for (size_t s = 0; s < model.size(); ++s) {
    assert(model[s].rows() >= nv && reference[s].rows() >= nv);
    for (Eigen::Index i = 0; i < nv; ++i) {
      const double d = (model[s].row(i) - reference[s].row(i)).norm();
      sumSq += d * d;
      sumDist += d;
      m.max = std::max(m.max, d);
      sumRef += (reference[s].row(i) - rest.row(i)).norm();
      ++count;
    }
  }
  m.rmseAll = count > 0 ? std::sqrt(sumSq / double(count)) : 0.0;
  if (sumRef > 0) {
    m.lossRatio = sumDist / sumRef;
  } else {
    m.lossRatio = sumDist > 0 ? std::numeric_limits<double>::infinity() : 0.0;
  }
  if (!excluded.empty()) {
    m.nearestSamples = "nearest_ungrasped";
    m.excludedGrasped = static_cast<int>(excluded.size());
  }
  for (int k : nearest) {
    std::vector<int> idx;
    if (excluded.empty()) {
      idx = nearestVertices(rest, focus, k);
    } else {
      for (int i : nearestVertices(rest, focus, k + static_cast<int>(excluded.size()))) {
        if (static_cast<int>(idx.size()) == k) break;
        if (!std::binary_search(excluded.begin(), excluded.end(), i)) idx.push_back(i);
      }
    }
    double sq = 0, refSq = 0;
    long long n = 0;
    for (size_t s = 0; s < model.size(); ++s) {
      for (int i : idx) {
        sq += (model[s].row(i) - reference[s].row(i)).squaredNorm();
        refSq += (reference[s].row(i) - rest.row(i)).squaredNorm();
        ++n;
      }
    }
    m.rmseNearest.emplace_back(k, n > 0 ? std::sqrt(sq / double(n)) : 0.0);
    m.referenceNearest.emplace_back(k, n > 0 ? std::sqrt(refSq / double(n)) : 0.0);
  }
  return m;
}

double median(std::vector<double> values) {
  if (values.empty()) return 0.0;
  const size_t n = values.size();
  std::nth_element(values.begin(), values.begin() + n / 2, values.end());
  const double hi = values[n / 2];
  if (n % 2 == 1) return hi;
  const double lo = *std::max_element(values.begin(), values.begin() + n / 2);
  return 0.5 * (lo + hi);
}

StepStats stepStatistics(const std::vector<double>& stepMs, double warmupFraction) {
  StepStats s;
  if (stepMs.empty()) return s;
  size_t skip = static_cast<size_t>(std::floor(warmupFraction * double(stepMs.size())));
  if (skip >= stepMs.size()) skip = 0;
  std::vector<double> v(stepMs.begin() + static_cast<std::ptrdiff_t>(skip), stepMs.end());
  s.samples = static_cast<int>(v.size());
  s.mean = std::accumulate(v.begin(), v.end(), 0.0) / double(v.size());
  s.median = median(v);
  std::sort(v.begin(), v.end());
  s.max = v.back();
  const size_t rank = static_cast<size_t>(std::ceil(0.95 * double(v.size())));
  s.p95 = v[std::max<size_t>(rank, 1) - 1];
  return s;
}

}  // namespace deform::harness
