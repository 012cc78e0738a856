// Issue F9 item 1, mesh readers: every supported format, truncated, garbled, with a NaN or
// infinite coordinate, with an index out of range, and empty, must be refused with an InputError
// naming the input and the place (the line, byte or element of the bad record). The same valid
// octahedron is written in each format by hand here (independently of the project's writers),
// then broken in one known place.
#include <deform/geometry/mesh_check.h>
#include <deform/geometry/mesh_io.h>
#include <deform/sdk/error.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cstring>
#include <limits>
#include <regex>
#include <sstream>

#include "mesh_test_util.h"

namespace deform {
namespace {

using testing::octahedron;

using testing::Bytes;

std::string num(Real x) {
  std::ostringstream o;
  o << x;
  return o.str();
}

/// A text format: the file as lines, where vertex i and face f sit (0-based line index), and how
/// a face line is written with given indices.
struct TextFormat {
  const char* name;  ///< file name (the extension picks the reader)
  std::vector<std::string> lines;
  std::vector<int> vertexLine;  ///< per vertex
  std::vector<int> faceLine;    ///< per face (-1: the format has no indices, STL)
  std::string (*face)(int f, int a, int b, int c) = nullptr;
  int coordinateToken = 1;  ///< token index of the y coordinate on a vertex line
};

std::string joined(const std::vector<std::string>& lines) {
  std::string s;
  for (const auto& l : lines) s += l + "\n";
  return s;
}

/// An indexed format of mesh m: `head`, one line per vertex (x y z after `vertexPrefix`, or after
/// the vertex's 1-based number when `numbered`), `middle`, one line per face written by `face`,
/// `tail`.
TextFormat indexedFormat(const SurfaceMesh& m, const char* name, std::vector<std::string> head,
                         const std::string& vertexPrefix, bool numbered,
                         const std::vector<std::string>& middle,
                         std::string (*face)(int f, int a, int b, int c),
                         const std::vector<std::string>& tail, int coordinateToken) {
  TextFormat t{name, std::move(head), {}, {}};
  for (int i = 0; i < int(m.V.rows()); ++i) {
    const std::string prefix = numbered ? std::to_string(i + 1) + " " : vertexPrefix;
    t.vertexLine.push_back(int(t.lines.size()));
    t.lines.push_back(prefix + num(m.V(i, 0)) + " " + num(m.V(i, 1)) + " " + num(m.V(i, 2)));
  }
  t.lines.insert(t.lines.end(), middle.begin(), middle.end());
  t.face = face;
  for (int f = 0; f < int(m.F.rows()); ++f)
    t.faceLine.push_back(int(t.lines.size())),
        t.lines.push_back(t.face(f, m.F(f, 0), m.F(f, 1), m.F(f, 2)));
  t.lines.insert(t.lines.end(), tail.begin(), tail.end());
  t.coordinateToken = coordinateToken;
  return t;
}

std::vector<TextFormat> textFormats() {
  const SurfaceMesh m = octahedron();
  auto xyz = [&](int i) { return num(m.V(i, 0)) + " " + num(m.V(i, 1)) + " " + num(m.V(i, 2)); };
  auto objFace = [](int, int a, int b, int c) {
    return "f " + std::to_string(a + 1) + " " + std::to_string(b + 1) + " " + std::to_string(c + 1);
  };
  auto counted = [](int, int a, int b, int c) {
    return "3 " + std::to_string(a) + " " + std::to_string(b) + " " + std::to_string(c);
  };
  auto msh22Face = [](int f, int a, int b, int c) {
    return std::to_string(f + 1) + " 2 2 0 1 " + std::to_string(a + 1) + " " +
           std::to_string(b + 1) + " " + std::to_string(c + 1);
  };
  auto legacyFace = [](int f, int a, int b, int c) {
    return std::to_string(f + 1) + " 2 0 1 3 " + std::to_string(a + 1) + " " +
           std::to_string(b + 1) + " " + std::to_string(c + 1);
  };
  std::vector<TextFormat> out;
  out.push_back(indexedFormat(m, "octa.obj", {"# octahedron"}, "v ", false, {}, objFace, {}, 2));
  out.push_back(indexedFormat(m, "octa.off", {"OFF", "6 8 0"}, "", false, {}, counted, {}, 1));
  out.push_back(indexedFormat(m, "octa.ply",
                              {"ply", "format ascii 1.0", "element vertex 6", "property float x",
                               "property float y", "property float z", "element face 8",
                               "property list uchar int vertex_indices", "end_header"},
                              "", false, {}, counted, {}, 1));
  out.push_back(indexedFormat(
      m, "octa.vtk",
      {"# vtk DataFile Version 3.0", "octahedron", "ASCII", "DATASET POLYDATA", "POINTS 6 float"},
      "", false, {"POLYGONS 8 32"}, counted, {}, 1));
  out.push_back(indexedFormat(m, "octa.msh",
                              {"$MeshFormat", "2.2 0 8", "$EndMeshFormat", "$Nodes", "6"}, "", true,
                              {"$EndNodes", "$Elements", "8"}, msh22Face, {"$EndElements"}, 2));
  out.push_back(indexedFormat(m, "legacy.msh", {"$NOD", "6"}, "", true, {"$ENDNOD", "$ELM", "8"},
                              legacyFace, {"$ENDELM"}, 2));
  {
    TextFormat t{"octa.stl", {"solid octa"}, std::vector<int>(6, -1), {}};
    for (int f = 0; f < 8; ++f) {
      t.lines.push_back("facet normal 0 0 0");
      t.lines.push_back("outer loop");
      for (int k = 0; k < 3; ++k) {
        if (t.vertexLine[size_t(m.F(f, k))] < 0)
          t.vertexLine[size_t(m.F(f, k))] = int(t.lines.size());
        t.lines.push_back("vertex " + xyz(m.F(f, k)));
      }
      t.lines.push_back("endloop");
      t.lines.push_back("endfacet");
    }
    t.lines.push_back("endsolid octa");
    t.coordinateToken = 2;
    out.push_back(t);
  }
  return out;
}

/// Replaces token `k` (whitespace-separated) of a line.
std::string replaceToken(const std::string& line, int k, const std::string& with) {
  std::istringstream in(line);
  std::vector<std::string> tok;
  for (std::string s; in >> s;) tok.push_back(s);
  tok.at(size_t(k)) = with;
  std::string out;
  for (size_t i = 0; i < tok.size(); ++i) out += (i ? " " : "") + tok[i];
  return out;
}

/// Reads `data` as `name`; expects an InputError naming `name` at `place` (exact, or any place
/// matching the regex when place starts with '^'). Returns the problem text.
std::string refused(const std::string& data, const std::string& name, const std::string& place) {
  try {
    const LoadedMesh m = readMeshFromMemory(data, name);
    ADD_FAILURE() << name << ": expected an InputError at " << place << ", read "
                  << m.surface.numVertices() << " vertices and " << m.surface.numFaces()
                  << " triangles";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), name) << e.what();
    if (!place.empty() && place[0] == '^')
      EXPECT_TRUE(std::regex_search(e.place(), std::regex(place))) << e.what();
    else
      EXPECT_EQ(e.place(), place) << e.what();
    EXPECT_EQ(std::string(e.what()).find('\n'), std::string::npos) << e.what();
    return e.problem();
  } catch (const std::exception& e) {
    ADD_FAILURE() << name << ": expected InputError, got " << e.what();
  }
  return "";
}

std::string lineOf(int index) {
  return "line " + std::to_string(index + 1);
}

class TextMesh : public ::testing::TestWithParam<TextFormat> {};

TEST_P(TextMesh, ValidFileReadsAndValidates) {
  const TextFormat& t = GetParam();
  const LoadedMesh m = readMeshFromMemory(joined(t.lines), t.name);
  EXPECT_EQ(m.surface.numVertices(), 6);
  EXPECT_EQ(m.surface.numFaces(), 8);
  EXPECT_TRUE(validateSurface(m.surface).ok());
}

TEST_P(TextMesh, GarbledCoordinateNamesItsLine) {
  const TextFormat& t = GetParam();
  std::vector<std::string> lines = t.lines;
  const int at = t.vertexLine[3];
  lines[size_t(at)] = replaceToken(lines[size_t(at)], t.coordinateToken, "0.5x");
  refused(joined(lines), t.name, lineOf(at));
}

TEST_P(TextMesh, NanAndInfCoordinatesNameTheirLine) {
  const TextFormat& t = GetParam();
  for (const char* bad : {"nan", "inf", "-inf", "1e999"}) {
    SCOPED_TRACE(bad);
    std::vector<std::string> lines = t.lines;
    const int at = t.vertexLine[4];
    lines[size_t(at)] = replaceToken(lines[size_t(at)], t.coordinateToken, bad);
    refused(joined(lines), t.name, lineOf(at));
  }
}

TEST_P(TextMesh, IndexOutOfRangeNamesItsLineOrElement) {
  const TextFormat& t = GetParam();
  if (t.faceLine.empty()) GTEST_SKIP() << "STL has no indices";
  std::vector<std::string> lines = t.lines;
  const int f = 5;
  lines[size_t(t.faceLine[size_t(f)])] = t.face(f, 0, 6, 2);  // vertex 6 does not exist
  refused(joined(lines), t.name, "^(" + lineOf(t.faceLine[size_t(f)]) + "|element 5)$");
  lines[size_t(t.faceLine[size_t(f)])] = t.face(f, 0, -100, 2);  // (OBJ: -99, also out of range)
  refused(joined(lines), t.name, "^(" + lineOf(t.faceLine[size_t(f)]) + "|element 5)$");
}

TEST_P(TextMesh, TruncatedInsideTheLastFaceNamesAPlace) {
  const TextFormat& t = GetParam();
  std::string data = joined(t.lines);
  // Cut in the middle of the last face record (for STL: inside the last facet's second corner),
  // after its second number, so no format can read it as a complete record.
  const int last = t.faceLine.empty() ? int(t.lines.size()) - 5 : t.faceLine.back();
  size_t start = 0;
  for (int i = 0; i < last; ++i) start = data.find('\n', start) + 1;
  const std::string& line = t.lines[size_t(last)];
  const size_t cut = line.find(' ', line.find(' ') + 1);
  data.resize(start + cut);
  refused(data, t.name, "^(line|byte) [0-9]+$");
}

TEST_P(TextMesh, EmptyInputIsRefused) {
  const TextFormat& t = GetParam();
  const std::string problem = refused("", t.name, "^(|line 1|byte 0)$");
  EXPECT_FALSE(problem.empty());
  // Only the header: no vertices, no faces (or the count lines say 0).
  refused(t.lines.front() + "\n", t.name, "^.*$");
}

INSTANTIATE_TEST_SUITE_P(EveryTextFormat, TextMesh, ::testing::ValuesIn(textFormats()),
                         [](const auto& instance) {
                           std::string n = instance.param.name;
                           std::replace(n.begin(), n.end(), '.', '_');
                           return n;
                         });

// ---------------------------------------------------------------- binary formats

std::string binaryStl(const SurfaceMesh& m) {
  Bytes b;
  b.text(std::string(80, ' ')).put<uint32_t>(uint32_t(m.numFaces()));
  for (int f = 0; f < m.numFaces(); ++f) {
    b.put<float>(0).put<float>(0).put<float>(0);
    for (int k = 0; k < 3; ++k)
      for (int d = 0; d < 3; ++d) b.put<float>(float(m.V(m.F(f, k), d)));
    b.put<uint16_t>(0);
  }
  return b.s;
}

std::string binaryPly(const SurfaceMesh& m, bool big, size_t* vertexStart, size_t* faceStart) {
  Bytes b;
  b.big = big;
  b.text(std::string("ply\nformat ") + (big ? "binary_big_endian" : "binary_little_endian") +
         " 1.0\nelement vertex 6\nproperty float x\nproperty float y\nproperty float z\n"
         "element face 8\nproperty list uchar int vertex_indices\nend_header\n");
  *vertexStart = b.s.size();
  for (int i = 0; i < m.numVertices(); ++i)
    for (int d = 0; d < 3; ++d) b.put<float>(float(m.V(i, d)));
  *faceStart = b.s.size();
  for (int f = 0; f < m.numFaces(); ++f)
    b.put<uint8_t>(3).put<int32_t>(m.F(f, 0)).put<int32_t>(m.F(f, 1)).put<int32_t>(m.F(f, 2));
  return b.s;
}

std::string binaryVtk(const SurfaceMesh& m, size_t* vertexStart, size_t* faceStart) {
  Bytes b;
  b.big = true;
  b.text("# vtk DataFile Version 3.0\noctahedron\nBINARY\nDATASET POLYDATA\nPOINTS 6 float\n");
  *vertexStart = b.s.size();
  for (int i = 0; i < m.numVertices(); ++i)
    for (int d = 0; d < 3; ++d) b.put<float>(float(m.V(i, d)));
  b.text("\nPOLYGONS 8 32\n");
  *faceStart = b.s.size();
  for (int f = 0; f < m.numFaces(); ++f)
    b.put<int32_t>(3).put<int32_t>(m.F(f, 0)).put<int32_t>(m.F(f, 1)).put<int32_t>(m.F(f, 2));
  b.text("\n");
  return b.s;
}

void putFloat(std::string& s, size_t at, float v, bool big) {
  Bytes b;
  b.big = big;
  b.put<float>(v);
  s.replace(at, 4, b.s);
}

/// "byte N" with lo <= N < hi.
void expectByteIn(const std::string& problemOf, const std::string& data, const std::string& name,
                  size_t lo, size_t hi) {
  try {
    readMeshFromMemory(data, name);
    ADD_FAILURE() << problemOf << ": " << name << " read without error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), name);
    std::smatch m;
    const std::string place = e.place();
    ASSERT_TRUE(std::regex_match(place, m, std::regex("byte ([0-9]+)"))) << e.what();
    const size_t at = std::stoul(m[1]);
    EXPECT_GE(at, lo) << problemOf << ": " << e.what();
    EXPECT_LT(at, hi) << problemOf << ": " << e.what();
  }
}

TEST(BinaryMesh, StlTruncatedNanAndEmpty) {
  const std::string ok = binaryStl(octahedron());
  EXPECT_EQ(readMeshFromMemory(ok, "o.stl").surface.numFaces(), 8);
  // Triangle 6's record starts at 84 + 6 * 50; cut inside it.
  expectByteIn("truncated", ok.substr(0, 84 + 6 * 50 + 20), "o.stl", 0, 84 + 7 * 50);
  for (float bad :
       {std::numeric_limits<float>::quiet_NaN(), std::numeric_limits<float>::infinity()}) {
    std::string s = ok;
    putFloat(s, 84 + 3 * 50 + 12 + 4, bad, false);  // triangle 3, first corner, y
    expectByteIn("non-finite", s, "o.stl", 84 + 3 * 50, 84 + 4 * 50);
  }
  // Count says 8, no records: truncated; a zero count: no triangles.
  expectByteIn("no records", ok.substr(0, 84), "o.stl", 0, 85);
  std::string none = ok.substr(0, 84);
  none.replace(80, 4, std::string(4, '\0'));
  EXPECT_THROW(readMeshFromMemory(none, "o.stl"), InputError);
}

TEST(BinaryMesh, PlyBothEndiannessesTruncatedNanIndexOutOfRange) {
  for (bool big : {false, true}) {
    SCOPED_TRACE(big ? "big endian" : "little endian");
    size_t v0 = 0, f0 = 0;
    const std::string ok = binaryPly(octahedron(), big, &v0, &f0);
    EXPECT_EQ(readMeshFromMemory(ok, "o.ply").surface.numFaces(), 8);
    expectByteIn("truncated", ok.substr(0, f0 + 13 * 7 + 5), "o.ply", f0 + 13 * 7, ok.size());
    std::string s = ok;
    putFloat(s, v0 + 4 * 12 + 4, std::numeric_limits<float>::quiet_NaN(), big);  // vertex 4
    expectByteIn("NaN", s, "o.ply", v0 + 4 * 12, v0 + 5 * 12);
    s = ok;
    Bytes idx;
    idx.big = big;
    idx.put<int32_t>(9);
    s.replace(f0 + 13 * 5 + 1 + 4, 4, idx.s);  // face 5, second index -> 9
    expectByteIn("index", s, "o.ply", f0 + 13 * 5, f0 + 13 * 6);
  }
}

TEST(BinaryMesh, VtkTruncatedNanIndexOutOfRange) {
  size_t v0 = 0, f0 = 0;
  const std::string ok = binaryVtk(octahedron(), &v0, &f0);
  EXPECT_EQ(readMeshFromMemory(ok, "o.vtk").surface.numFaces(), 8);
  expectByteIn("truncated", ok.substr(0, f0 + 16 * 6 + 6), "o.vtk", v0, ok.size());
  std::string s = ok;
  putFloat(s, v0 + 2 * 12 + 8, std::numeric_limits<float>::infinity(), true);  // vertex 2
  expectByteIn("Inf", s, "o.vtk", v0 + 2 * 12, v0 + 3 * 12);
  s = ok;
  Bytes idx;
  idx.big = true;
  idx.put<int32_t>(6);
  s.replace(f0 + 16 * 7 + 8, 4, idx.s);  // cell 7, second index -> 6
  try {
    readMeshFromMemory(s, "o.vtk");
    ADD_FAILURE() << "read without error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "o.vtk");
    EXPECT_TRUE(std::regex_match(e.place(), std::regex("element 7|byte [0-9]+"))) << e.what();
  }
}

}  // namespace
}  // namespace deform
