// The paper's static accuracy measure as the harness table bem-accuracy computes it
// (static_accuracy.h, bemStaticAccuracy): R = sum|u^o - u^imp| / sum|u^o| over the fine vertices
// (Zhu, Gu & Zhou 2010, Table 2). Small icospheres so the whole file runs in seconds.
#include "static_accuracy.h"
#include "../support/meshes.h"

#include <gtest/gtest.h>

#include <filesystem>

namespace deform::particle_bem {
namespace {

namespace fs = std::filesystem;
using testing::icosphere;

TEST(StaticAccuracy, ZeroWhenCoarseIsFineAndFallsAsCoarseGrows) {
  const SurfaceMesh organ = icosphere(3, 0.05);  // 642 vertices
  const auto rows = bemStaticAccuracy(organ, {{250, 250}, {80, 250}, {160, 250}}, fs::path());
  ASSERT_EQ(rows.size(), 3u);
  for (const auto& r : rows) {
    EXPECT_FALSE(r["cached"].get<bool>()) << "no cache folder: nothing is cached";
    EXPECT_EQ(r["fine_vertices"].get<int>(), 250);
    // The solved surfaces are cut along the fixed box and decimated to the requested counts.
    EXPECT_LE(r["fine_surface_vertices"].get<int>(), 250);
    EXPECT_GE(r["fine_surface_vertices"].get<int>(), 200);
  }
  EXPECT_EQ(rows[1]["coarse_surface_vertices"].get<int>(), 80);
  EXPECT_NEAR(rows[1]["vertex_ratio"].get<double>(),
              rows[1]["fine_surface_vertices"].get<double>() / 80.0, 1e-12);
  const double same = rows[0]["loss_ratio"], coarse80 = rows[1]["loss_ratio"],
               coarse160 = rows[2]["loss_ratio"];
  // Coarse surface = fine surface: u^imp = u^o at every fine vertex.
  EXPECT_LT(same, 1e-9);
  EXPECT_GT(coarse80, 1e-3);
  EXPECT_GT(coarse160, 1e-4);
  EXPECT_LT(coarse160, coarse80) << "a finer coarse surface is closer to the fine one";
  EXPECT_LT(coarse80, 0.5);
  // The load presses the top down: the fine solution is not zero.
  EXPECT_GT(rows[0]["mean_fine_displacement_m"].get<double>(), 0);
}

TEST(StaticAccuracy, SecondRunComesFromTheCache) {
  const fs::path dir = fs::temp_directory_path() / "deform_particle_bem_static_accuracy_cache";
  fs::remove_all(dir);
  const SurfaceMesh organ = icosphere(2, 0.05);  // 162 vertices
  const auto cold = bemStaticAccuracy(organ, {{60, 120}}, dir);
  const auto warm = bemStaticAccuracy(organ, {{60, 120}}, dir);
  ASSERT_EQ(cold.size(), 1u);
  ASSERT_EQ(warm.size(), 1u);
  EXPECT_FALSE(cold[0]["cached"].get<bool>());
  EXPECT_TRUE(warm[0]["cached"].get<bool>());
  EXPECT_EQ(cold[0]["loss_ratio"].get<double>(), warm[0]["loss_ratio"].get<double>());
  // Another organ is another key.
  const auto other = bemStaticAccuracy(icosphere(2, 0.06), {{60, 120}}, dir);
  EXPECT_FALSE(other[0]["cached"].get<bool>());
  fs::remove_all(dir);
}

}  // namespace
}  // namespace deform::particle_bem
