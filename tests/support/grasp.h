// Grasps and loads built the way the harness builds them, for tests that drive a model directly
// (without the runner). Include as "../support/grasp.h".
#pragma once

#include <deform/engine/interaction.h>
#include <deform/sdk/model.h>

#include <algorithm>
#include <cmath>
#include <vector>

namespace deform::testing {

/// A grasp holding the given organ surface vertices; their targets are the rows of `positions`
/// (indexed by vertex) moved by `shift`.
inline GraspInput graspOf(const std::vector<int>& vertices, const MatX3& positions,
                          const Vec3& shift = Vec3::Zero()) {
  GraspInput g;
  g.vertices = vertices;
  g.targets.resize(Eigen::Index(vertices.size()), 3);
  for (size_t k = 0; k < vertices.size(); ++k)
    g.targets.row(Eigen::Index(k)) = positions.row(vertices[k]) + shift.transpose();
  return g;
}

/// The grasp of the surface vertices within r of p, picked on the rest surface as the harness
/// picks them (graspedSurfaceVertices: at least the nearest one); targets as in graspOf.
inline GraspInput surfaceGrasp(const SurfaceMesh& rest, const Vec3& p, Real r,
                               const MatX3& positions, const Vec3& shift = Vec3::Zero()) {
  return graspOf(graspedSurfaceVertices(rest, p, r), positions, shift);
}

/// RMS distance of the grasped vertices of `surface` to their targets (results.json's
/// grasp_residual_m for one step).
inline Real graspResidual(const MatX3& surface, const GraspInput& g) {
  Real sum = 0;
  for (size_t k = 0; k < g.vertices.size(); ++k)
    sum += (surface.row(g.vertices[k]) - g.targets.row(Eigen::Index(k))).squaredNorm();
  return std::sqrt(sum / Real(std::max<size_t>(1, g.vertices.size())));
}

/// The harness's spread of a force at surface vertex v over a pressure patch of radius R (m).
inline PointLoad patchLoad(const SurfaceMesh& rest, int v, const Vec3& force, Real R = 0.01) {
  PointLoad load;
  load.surfaceVertex = v;
  load.force = force;
  const SurfacePatch patch = pressurePatch(rest, v, R);
  load.vertices = patch.vertices;
  load.weights = patch.weights;
  return load;
}

/// A force on one surface vertex with no spread (vertices and weights left empty).
inline PointLoad vertexLoad(int v, const Vec3& force) {
  PointLoad load;
  load.surfaceVertex = v;
  load.force = force;
  return load;
}

}  // namespace deform::testing
