// deformbench harness: error metrics against a reference (docs/results-format.md) and step-time
// statistics.
//
// With x the model's surface, y the reference's and X the rest surface (each #V by 3, m, the
// organ's input vertex order), d_i = |x_i - y_i| and u = displacement from rest:
//   rmse_k     = sqrt( (1/k) sum_{i in N_k} d_i^2 ), N_k = the k rest-surface vertices nearest
//                the focus point (the first load's vertex, else the first grasp point). In a
//                grasp scene (no loads; the focus is a grasp's closing point) N_k leaves out the
//                grasped vertices (graspedSurfaceVertices()): every model holds those at the
//                tool, so they would make rmse_k trivially small.
//   reference_displacement_k = sqrt( (1/k) sum_{i in N_k} |y_i - X_i|^2 ), the displacement
//                rmse_k measures (an error at least this large says nothing of the motion)
//   rmse_all   = the same over every vertex, max = max_i d_i
//   loss_ratio = sum_i |u_ref,i - u_model,i| / sum_i |u_ref,i|   (the particle/BEM paper's
//                "accuracy loss ratio"; u_ref - u_model = y - x, so the numerator is sum_i d_i)
// Over several compared instants the sums run over every (instant, vertex) pair.
#pragma once

#include <deform/engine/scene.h>
#include <deform/sdk/types.h>

#include <string>

#include <utility>
#include <vector>

namespace deform::harness {

struct ErrorMetrics {
  std::vector<std::pair<int, double>> rmseNearest;  ///< (k, rmse_k in m) in samples.nearest order
  /// (k, reference_displacement_k in m): the reference's rms displacement from rest over rmse_k's
  /// vertices and instants, in the same order.
  std::vector<std::pair<int, double>> referenceNearest;
  double rmseAll = 0;  ///< m
  double max = 0;      ///< m
  double lossRatio =
      0;             ///< dimensionless; +inf when the reference does not move but the model does
  int instants = 0;  ///< how many instants were compared
  /// Which vertices rmse_k covers: "nearest" (the k nearest the focus) or "nearest_ungrasped"
  /// (the k nearest the focus among those no grasp holds). results.json: error.rmse_k_samples.
  std::string nearestSamples = "nearest";
  int excludedGrasped = 0;  ///< vertices left out of rmse_k's candidates (grasped)
};

/// The surface vertices a grasp holds: deform::graspedSurfaceVertices (deform/sdk/model.h), the one
/// definition. The union of those over every closing of every grasper of the scene (a keyframe
/// whose jaws are closed after open ones, or closed at the first keyframe). Sorted, no repeats.
std::vector<int> graspedSurfaceVertices(const Scene& scene, const MatX3& rest);
/// The vertices rmse_k leaves out in this scene: the grasped ones when the scene has no loads
/// (its focus is a grasp), else none.
std::vector<int> rmseExcludedVertices(const Scene& scene, const MatX3& rest);

/// Errors at one instant. model, reference, rest: #V by 3 (same V). nearest: the k values.
ErrorMetrics computeErrors(const MatX3& model, const MatX3& reference, const MatX3& rest,
                           const Vec3& focus, const std::vector<int>& nearest);

/// Errors pooled over several instants (model[i] and reference[i] at the same instant).
ErrorMetrics computeErrors(const std::vector<MatX3>& model, const std::vector<MatX3>& reference,
                           const MatX3& rest, const Vec3& focus, const std::vector<int>& nearest);

/// The same, with rmse_k taken over the k vertices nearest the focus that are not in `excluded`
/// (sorted); nearestSamples says "nearest_ungrasped" when excluded is not empty.
ErrorMetrics computeErrors(const std::vector<MatX3>& model, const std::vector<MatX3>& reference,
                           const MatX3& rest, const Vec3& focus, const std::vector<int>& nearest,
                           const std::vector<int>& excluded);

/// Step-time statistics in ms over the steps after the warm-up (the first warmupFraction of the
/// steps, rounded down; all steps when that would leave none). p95 is the nearest-rank 95th
/// percentile.
struct StepStats {
  double median = 0, p95 = 0, max = 0, mean = 0;
  int samples = 0;  ///< steps the statistics cover
};
StepStats stepStatistics(const std::vector<double>& stepMs, double warmupFraction = 0.05);

/// Median of a list (mean of the two middle values for an even count; 0 for an empty list).
double median(std::vector<double> values);

}  // namespace deform::harness
