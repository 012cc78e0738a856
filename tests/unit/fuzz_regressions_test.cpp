// Replays every input the fuzzers ever crashed on (tests/fuzz/regressions/<target>/) and every
// seed (tests/fuzz/corpus/<target>/) through the fuzzers' own entry points (tests/fuzz/
// fuzz_entry.h): each must be read or refused with deform::InputError, never crash or throw
// anything else. Under scripts/sanitize.sh this also checks them for memory errors and leaks.
#include <gtest/gtest.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

#include "../fuzz/fuzz_entry.h"

namespace {

namespace fs = std::filesystem;
using deform::fuzz::Outcome;

const fs::path kFuzzDir = fs::path(DEFORM_SOURCE_DIR) / "tests" / "fuzz";

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

/// Regular files in tests/fuzz/<kind>/<target>/, sorted (README and dot files excluded).
std::vector<fs::path> inputs(const std::string& kind, const std::string& target) {
  std::vector<fs::path> out;
  const fs::path dir = kFuzzDir / kind / target;
  if (!fs::is_directory(dir)) return out;
  for (const auto& e : fs::directory_iterator(dir)) {
    const std::string name = e.path().filename().string();
    if (e.is_regular_file() && name != "README.md" && name.front() != '.') out.push_back(e.path());
  }
  std::sort(out.begin(), out.end());
  return out;
}

Outcome feed(const std::string& target, const std::string& data) {
  if (target == "scene") return deform::fuzz::feedScene(data);
  // The target names the reader, whatever the saved file is called.
  return deform::fuzz::feedMesh(data, "input." + target);
}

class FuzzInputs : public ::testing::TestWithParam<std::string> {};

TEST_P(FuzzInputs, RegressionsAreReadOrRefusedWithInputError) {
  for (const fs::path& p : inputs("regressions", GetParam())) {
    SCOPED_TRACE(p.string());
    EXPECT_NO_THROW(feed(GetParam(), slurp(p)));
  }
}

TEST_P(FuzzInputs, SeedsAreReadOrRefusedWithInputError) {
  const std::vector<fs::path> seeds = inputs("corpus", GetParam());
  ASSERT_FALSE(seeds.empty()) << "no seed corpus in " << (kFuzzDir / "corpus" / GetParam());
  int accepted = 0, refused = 0;
  for (const fs::path& p : seeds) {
    SCOPED_TRACE(p.string());
    Outcome o = Outcome::Refused;
    EXPECT_NO_THROW(o = feed(GetParam(), slurp(p)));
    (o == Outcome::Accepted ? accepted : refused)++;
  }
  // Every format's seeds hold both valid and broken files, so the entry point must say both.
  EXPECT_GT(accepted, 0);
  EXPECT_GT(refused, 0);
}

INSTANTIATE_TEST_SUITE_P(Targets, FuzzInputs,
                         ::testing::Values("obj", "stl", "off", "ply", "vtk", "msh", "scene"),
                         [](const auto& instance) { return instance.param; });

TEST(FuzzEntry, MeshEntryAcceptsAValidTetrahedronAndRefusesATruncatedOne) {
  const std::string tet =
      "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n";
  EXPECT_EQ(deform::fuzz::feedMesh(tet, "t.obj"), Outcome::Accepted);
  EXPECT_EQ(deform::fuzz::feedMesh(tet.substr(0, tet.size() - 5), "t.obj"), Outcome::Refused);
}

TEST(FuzzEntry, SceneEntryRefusesNonJsonAndUnknownKeys) {
  EXPECT_EQ(deform::fuzz::feedScene("{\"name\": "), Outcome::Refused);
  EXPECT_EQ(deform::fuzz::feedScene(R"({"name": "x", "organ": {"mesh": "phantom:cube"},
                                        "models": [{"plugin": "pbd"}], "colour": 1})"),
            Outcome::Refused);
  EXPECT_EQ(deform::fuzz::feedScene(R"({"name": "x", "organ": {"mesh": "phantom:cube"},
                                        "models": [{"plugin": "pbd"}]})"),
            Outcome::Accepted);
}

}  // namespace
