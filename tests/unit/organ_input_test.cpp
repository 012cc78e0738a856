// Issue F9 item 1 through the organ loader (what `deformbench run` does with a scene): every
// surface defect is refused naming the mesh file, and a grasp that closes away from the organ is
// refused naming the scene file and the keyframe's JSON path.
#include <deform/engine/scene.h>
#include <deform/sdk/error.h>
#include <gtest/gtest.h>

#include <fstream>
#include <sstream>

#include "mesh_test_util.h"

namespace deform {
namespace {

using nlohmann::json;
using testing::ScratchDir;

/// The octahedron as OBJ text with face lines replaced/added by the caller.
const char* kVertices = "v 1 0 0\nv -1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0 0 -1\n";
const char* kFaces = "f 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n";

struct DefectCase {
  const char* name;
  std::string obj;
  const char* expected;  ///< substring of the problem
};

/// Each "f a b c" line of `faces` rewritten as face(a, b, c) gives it (a whole "f ..." line).
template <class Face>
std::string mapFaces(const std::string& faces, Face&& face) {
  std::string out;
  std::istringstream in(faces);
  for (std::string line; std::getline(in, line);) {
    std::istringstream l(line.substr(2));
    int a, b, c;
    l >> a >> b >> c;
    out += face(a, b, c);
  }
  return out;
}

std::string faceLine(int a, int b, int c) {
  return "f " + std::to_string(a) + " " + std::to_string(b) + " " + std::to_string(c) + "\n";
}

std::string shifted(const std::string& faces, int by) {
  return mapFaces(faces, [by](int a, int b, int c) { return faceLine(a + by, b + by, c + by); });
}

std::vector<DefectCase> defectCases() {
  const std::string v = kVertices, f = kFaces;
  const std::string inverted =
      mapFaces(f, [](int a, int b, int c) { return faceLine(a, c, b); });  // every face flipped
  std::string farVertices;
  for (const char* p :
       {"v 4 0 0\n", "v 2 0 0\n", "v 3 1 0\n", "v 3 -1 0\n", "v 3 0 1\n", "v 3 0 -1\n"})
    farVertices += p;
  return {
      {"holes", v + f.substr(0, f.rfind("f ")), "3 boundary edges (holes)"},  // a face missing
      // Two closed tetrahedra in opposite octants sharing the x axis edge (4 triangles on it).
      {"non_manifold_edge",
       "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nv 0 -1 0\nv 0 0 -1\n"
       "f 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\nf 1 5 2\nf 1 2 6\nf 1 6 5\nf 2 5 6\n",
       "1 non-manifold edge"},
      {"two_components", v + farVertices + f + shifted(f, 6), "2 components"},
      {"inverted", v + inverted, "inward-facing normals"},
      {"nan_coordinate", "v 1 0 0\nv nan 0 0\n" + v.substr(v.find("v 0 1 0")) + f, "line 2"},
      {"index_out_of_range", v + f + "f 1 2 9\n", "line 15"},
      {"empty", "", ""},
  };
}

class OrganDefect : public ::testing::TestWithParam<DefectCase> {};

TEST_P(OrganDefect, LoadOrganRefusesNamingTheMeshFile) {
  const DefectCase& c = GetParam();
  ScratchDir dir(std::string("organ_defect_") + c.name);
  const std::string mesh = dir.write(std::string(c.name) + ".obj", c.obj);
  const json j = {{"organ", {{"mesh", mesh}}}, {"models", {{{"plugin", "pbd"}}}}};
  const Scene scene = parseScene(j, dir.file("scene.json"));
  try {
    loadOrgan(scene);
    FAIL() << "no error";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_EQ(e.file(), mesh) << what;
    EXPECT_EQ(what.rfind(mesh + ": ", 0), 0u) << what;
    EXPECT_NE(what.find(c.expected), std::string::npos) << what;
    EXPECT_EQ(what.find('\n'), std::string::npos) << what;
  }
}

INSTANTIATE_TEST_SUITE_P(EveryDefect, OrganDefect, ::testing::ValuesIn(defectCases()),
                         [](const auto& instance) { return std::string(instance.param.name); });

// ---------------------------------------------------------------- grasps against the organ

/// The 0.1 m cube phantom (centred at the origin) with one grasper of radius 5 mm whose jaws
/// close at `at` (second keyframe) or, with closedFirst, from the first keyframe on.
json graspScene(const Vec3& at, bool closedFirst = false) {
  json frames = json::array();
  if (!closedFirst)
    frames.push_back({{"t", 0.0}, {"pos", {at.x(), at.y(), at.z()}}, {"jaw", "open"}});
  frames.push_back({{"t", 0.1}, {"pos", {at.x(), at.y(), at.z()}}, {"jaw", "closed"}});
  frames.push_back({{"t", 0.5}, {"pos", {at.x(), at.y(), at.z() + 0.02}}});
  return {{"organ", {{"mesh", "phantom:cube"}, {"resolution", 0.3}}},
          {"tools", {{{"type", "grasper"}, {"radius", 0.005}, {"trajectory", frames}}}},
          {"models", {{{"plugin", "pbd"}}}}};
}

TEST(GraspOutsideOrgan, ClosingAwayFromTheSurfaceNamesTheSceneAndTheKeyframe) {
  for (bool closedFirst : {false, true}) {
    SCOPED_TRACE(closedFirst ? "closed from the first keyframe" : "closes at the second");
    const Scene scene = parseScene(graspScene(Vec3(0, 0, 0.2), closedFirst), "scenes/x.json");
    try {
      loadOrgan(scene);
      FAIL() << "no error";
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), "scenes/x.json");
      EXPECT_EQ(e.place(), closedFirst ? "/tools/0/trajectory/0/pos" : "/tools/0/trajectory/1/pos");
      EXPECT_NE(std::string(e.what()).find("0.15 m outside"), std::string::npos) << e.what();
    }
  }
}

TEST(GraspOutsideOrgan, OnTheSurfaceWithinTheRadiusOrInsideIsAccepted) {
  EXPECT_NO_THROW(loadOrgan(parseScene(graspScene(Vec3(0.01, 0, 0.05)), "x.json")));
  EXPECT_NO_THROW(loadOrgan(parseScene(graspScene(Vec3(0, 0, 0.0549)), "x.json")));
  EXPECT_NO_THROW(loadOrgan(parseScene(graspScene(Vec3(0, 0, 0)), "x.json")));  // inside
  EXPECT_THROW(loadOrgan(parseScene(graspScene(Vec3(0, 0, 0.0551)), "x.json")), InputError);
  // A probe may start anywhere: it presses, it does not grasp.
  json probe = graspScene(Vec3(0, 0, 0.2));
  probe["tools"][0]["type"] = "probe";
  for (auto& k : probe["tools"][0]["trajectory"]) k.erase("jaw");
  EXPECT_NO_THROW(loadOrgan(parseScene(probe, "x.json")));
}

// ---------------------------------------------------------------- loads against the organ

/// The 0.1 m cube phantom with one load at `at` (patch radius 1 cm).
json loadScene(const Vec3& at, const char* type = "point_force") {
  json load = {{"type", type}, {"at", {at.x(), at.y(), at.z()}}};
  if (std::string(type) == "point_force") {
    load["force"] = {0, 0, 1};
  } else {
    load["stiffness"] = 100;
    load["path"] = {{{"t", 0.0}, {"pos", {at.x(), at.y(), at.z()}}},
                    {{"t", 0.5}, {"pos", {at.x(), at.y(), at.z() + 0.01}}}};
  }
  return {{"organ", {{"mesh", "phantom:cube"}, {"resolution", 0.3}}},
          {"loads", {load}},
          {"models", {{{"plugin", "pbd"}}}}};
}

// Issue 35 item 6: a point force 17 m from the organ was applied at the nearest vertex in silence.
TEST(LoadAwayFromOrgan, FartherThanItsRadiusIsOneClearError) {
  for (const char* type : {"point_force", "pin_head"}) {
    SCOPED_TRACE(type);
    try {
      loadOrgan(parseScene(loadScene(Vec3(10, 10, 10), type), "scenes/far.json"));
      FAIL() << "no error";
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), "scenes/far.json");
      EXPECT_EQ(e.place(), "/loads/0/at");
      EXPECT_NE(
          std::string(e.what()).find("m outside the organ's surface, beyond its radius 0.01 m"),
          std::string::npos)
          << e.what();
      EXPECT_NE(std::string(e.what()).find("17.2"), std::string::npos) << e.what();
    }
  }
  EXPECT_THROW(loadOrgan(parseScene(loadScene(Vec3(0, 0, 0)), "x.json")), InputError)
      << "5 cm deep inside: the nearest vertex is far from the point";
  EXPECT_NO_THROW(loadOrgan(parseScene(loadScene(Vec3(0, 0, 0.05)), "x.json")));
  EXPECT_NO_THROW(loadOrgan(parseScene(loadScene(Vec3(0, 0, 0.059)), "x.json")));
  EXPECT_THROW(loadOrgan(parseScene(loadScene(Vec3(0, 0, 0.061)), "x.json")), InputError);
}

}  // namespace
}  // namespace deform
