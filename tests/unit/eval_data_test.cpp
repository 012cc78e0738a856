// Real organ meshes from ../shared/eval-data (see its SOURCES.md for where each comes from and
// the counts checked here). Skipped when the folder is absent, as on a fresh clone.
#include <deform/geometry/mesh_check.h>
#include <deform/geometry/mesh_io.h>
#include <deform/sdk/error.h>
#include <gtest/gtest.h>

#include <filesystem>

namespace deform {
namespace {

std::string evalFile(const std::string& name) {
  return std::string(DEFORM_EVAL_DATA_DIR) + "/" + name;
}

#define SKIP_WITHOUT(name)                                         \
  if (!std::filesystem::exists(evalFile(name))) {                  \
    GTEST_SKIP() << "eval data not available: " << evalFile(name); \
  }

std::string firstMessage(const MeshReport& r) {
  return r.issues.empty() ? "" : r.issues[0].message;
}

struct CleanCase {
  const char* file;
  int vertices;
  int faces;
  int unreferenced;
};

class EvalDataClean : public ::testing::TestWithParam<CleanCase> {};

TEST_P(EvalDataClean, LoadsWithSourceCountsAndValidates) {
  const CleanCase c = GetParam();
  SKIP_WITHOUT(c.file);
  const LoadedMesh m = readMesh(evalFile(c.file));
  EXPECT_FALSE(m.volume.has_value());
  EXPECT_EQ(m.surface.numVertices(), c.vertices);
  EXPECT_EQ(m.surface.numFaces(), c.faces);
  const MeshReport r = validateSurface(m.surface);
  EXPECT_TRUE(r.usable()) << firstMessage(r);
  EXPECT_NO_THROW(requireValidSurface(m.surface, c.file));
  if (c.unreferenced > 0) {
    ASSERT_TRUE(r.has(MeshDefect::UnreferencedVertices));
    EXPECT_EQ(r.issues.back().count, c.unreferenced);
  } else {
    EXPECT_TRUE(r.ok()) << firstMessage(r);
  }
  EXPECT_GT(signedVolume(m.surface.V, m.surface.F), 0);
}

INSTANTIATE_TEST_SUITE_P(SourcesMd, EvalDataClean,
                         ::testing::Values(CleanCase{"Liver.stl", 15365, 30726, 0},
                                           CleanCase{"gallbladder_visual.stl", 7352, 14700, 0},
                                           CleanCase{"Stomach.stl", 4864, 9724, 0},
                                           CleanCase{"Rectum_Lumen.stl", 6887, 13770, 0},
                                           CleanCase{"Kidney_left.stl", 3287, 6570, 0},
                                           CleanCase{"liver-smooth.obj", 2194, 4384, 0},
                                           CleanCase{"liver.obj", 181, 274, 42},
                                           CleanCase{"tissue_surface.obj", 448, 892, 0}),
                         [](const auto& instance) {
                           std::string n = instance.param.file;
                           for (char& ch : n) {
                             if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
                           }
                           return n;
                         });

TEST(EvalData, TetMeshesLoadAndTheirBoundariesValidate) {
  struct Case {
    const char* file;
    int nodes, tets, boundary;
  };
  for (const Case c :
       {Case{"tissue_volume.msh", 493, 1432, -1}, Case{"liver.msh", 181, 596, 276}}) {
    SKIP_WITHOUT(c.file);
    const LoadedMesh m = readMesh(evalFile(c.file));
    ASSERT_TRUE(m.volume.has_value()) << c.file;
    EXPECT_EQ(m.volume->numVertices(), c.nodes) << c.file;
    EXPECT_EQ(m.volume->numTets(), c.tets) << c.file;
    if (c.boundary > 0) {
      EXPECT_EQ(m.surface.numFaces(), c.boundary) << c.file;
    }
    EXPECT_EQ(m.surface.V, m.volume->V) << c.file;
    const MeshReport r = validateSurface(m.surface);
    EXPECT_TRUE(r.usable()) << c.file << ": " << firstMessage(r);
    EXPECT_EQ(m.degenerateTets, 0) << c.file;
  }
}

TEST(EvalData, DirtyLiverIsRefusedThenRepairedToOneComponent) {
  SKIP_WITHOUT("dirty_liver_visual.stl");
  LoadedMesh m = readMesh(evalFile("dirty_liver_visual.stl"));
  EXPECT_EQ(m.surface.numFaces(), 28716);
  const MeshReport before = validateSurface(m.surface);
  EXPECT_TRUE(before.has(MeshDefect::BoundaryEdges));
  EXPECT_TRUE(before.has(MeshDefect::MultipleComponents));
  EXPECT_TRUE(before.has(MeshDefect::DegenerateTriangles));
  try {
    requireValidSurface(m.surface, "dirty_liver_visual.stl");
    FAIL() << "dirty mesh accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "dirty_liver_visual.stl");
    EXPECT_EQ(e.problem(), before.issues.front().message);
  }
  const RepairReport rep = repairSurface(m.surface);
  EXPECT_GT(rep.droppedComponents, 0);
  EXPECT_GT(rep.droppedDegenerate, 0);
  const MeshReport after = validateSurface(m.surface);
  EXPECT_FALSE(after.has(MeshDefect::MultipleComponents)) << firstMessage(after);
  EXPECT_FALSE(after.has(MeshDefect::DegenerateTriangles)) << firstMessage(after);
  EXPECT_FALSE(after.has(MeshDefect::UnreferencedVertices));
}

TEST(EvalData, InvertedLiverIsInwardWithStraysAndRepairsToValid) {
  SKIP_WITHOUT("liver_inverted.vtk");
  LoadedMesh m = readMesh(evalFile("liver_inverted.vtk"));
  EXPECT_FALSE(m.volume.has_value());
  EXPECT_EQ(m.surface.numVertices(), 5008);
  EXPECT_EQ(m.surface.numFaces(), 10000);
  const MeshReport before = validateSurface(m.surface);
  EXPECT_TRUE(before.has(MeshDefect::InwardOrientation)) << firstMessage(before);
  ASSERT_TRUE(before.has(MeshDefect::MultipleComponents));
  const RepairReport rep = repairSurface(m.surface);
  EXPECT_TRUE(rep.reversedWhole);
  EXPECT_EQ(rep.droppedComponents, 3);
  const MeshReport after = validateSurface(m.surface);
  EXPECT_TRUE(after.ok()) << firstMessage(after);
  EXPECT_GT(signedVolume(m.surface.V, m.surface.F), 0);
}

}  // namespace
}  // namespace deform
