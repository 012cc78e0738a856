#include <deform/geometry/mesh_check.h>
#include <deform/geometry/mesh_io.h>
#include <deform/sdk/error.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <regex>
#include <sstream>

#include "mesh_test_util.h"

namespace deform {
namespace {

using testing::octahedron;
using testing::ScratchDir;

using testing::Bytes;

/// Expects fn() to throw InputError naming `file` and `place`; returns the problem text.
template <class Fn>
std::string expectInputError(Fn&& fn, const std::string& file, const std::string& place) {
  try {
    fn();
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), file) << e.what();
    EXPECT_EQ(e.place(), place) << e.what();
    return e.problem();
  } catch (const std::exception& e) {
    ADD_FAILURE() << "expected InputError, got: " << e.what();
    return "";
  }
  ADD_FAILURE() << "expected InputError at " << place << ", nothing thrown";
  return "";
}

/// The corners of each triangle as positions, for comparing meshes whose vertex numbering
/// differs (e.g. after STL corner merging).
std::vector<std::array<double, 9>> trianglePositions(const SurfaceMesh& m) {
  std::vector<std::array<double, 9>> out;
  for (int f = 0; f < m.numFaces(); ++f) {
    std::array<double, 9> t;
    for (int k = 0; k < 3; ++k) {
      for (int d = 0; d < 3; ++d) t[size_t(3 * k + d)] = m.V(m.F(f, k), d);
    }
    out.push_back(t);
  }
  return out;
}

SurfaceMesh awkwardOctahedron() {
  SurfaceMesh m = octahedron();
  m.V *= 1.0 / 3.0;
  m.V.rowwise() += Eigen::RowVector3d(0.1, -2.7e-5, 1234.5678901234567);
  return m;
}

// ---------------------------------------------------------------- round trips

/// The two-tet meshes of the VTK and Gmsh readers' tests: six nodes, the second tet given with
/// negative orientation and reversed on read.
::testing::AssertionResult twoTetsOneReoriented(const LoadedMesh& r) {
  if (!r.volume) return ::testing::AssertionFailure() << "no volume";
  if (r.volume->numTets() != 2 || r.volume->numVertices() != 6 || r.reorientedTets != 1)
    return ::testing::AssertionFailure()
           << r.volume->numTets() << " tets, " << r.volume->numVertices() << " nodes, "
           << r.reorientedTets << " reoriented";
  return ::testing::AssertionSuccess();
}

TEST(MeshIoRoundTrip, ObjIsExact) {
  ScratchDir dir("io_obj_rt");
  const SurfaceMesh m = awkwardOctahedron();
  writeObj(dir.file("a.obj"), m);
  const SurfaceMesh r = readObj(dir.file("a.obj"));
  EXPECT_EQ(r.V, m.V);  // shortest round-trip decimal text: bit-exact
  EXPECT_EQ(r.F, m.F);
}

TEST(MeshIoRoundTrip, OffIsExact) {
  ScratchDir dir("io_off_rt");
  const SurfaceMesh m = awkwardOctahedron();
  writeOff(dir.file("a.off"), m);
  const SurfaceMesh r = readOff(dir.file("a.off"));
  EXPECT_EQ(r.V, m.V);
  EXPECT_EQ(r.F, m.F);
}

TEST(MeshIoRoundTrip, BinaryStlKeepsTrianglesAndMergesCorners) {
  ScratchDir dir("io_stl_rt");
  SurfaceMesh m = octahedron();
  m.V *= 0.25;  // exactly representable as float
  writeStl(dir.file("a.stl"), m);
  EXPECT_EQ(std::filesystem::file_size(dir.file("a.stl")), 84u + 50u * 8u);
  const SurfaceMesh r = readStl(dir.file("a.stl"));
  EXPECT_EQ(r.numVertices(), 6);  // 24 corners merged back into 6 vertices
  EXPECT_EQ(trianglePositions(r), trianglePositions(m));
  // First-seen order: faces (0,2,4), (2,1,4), (1,3,4), ... give 0, 2, 4, 1, 3, 5.
  const int order[6] = {0, 2, 4, 1, 3, 5};
  for (int i = 0; i < 6; ++i) EXPECT_EQ(r.V.row(i), m.V.row(order[i])) << i;
  EXPECT_TRUE(validateSurface(r).ok());
}

TEST(MeshIoRoundTrip, MshTetsAndBoundary) {
  ScratchDir dir("io_msh_rt");
  TetMesh t;
  t.V.resize(5, 3);
  t.V << 0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1, 1.0 / 3, 1.0 / 3, 1.0 / 3;
  t.T.resize(3, 4);
  // Three positive tets fanned around the point 4 inside the corner tet's face, plus node 0.
  t.T << 0, 1, 2, 4, 0, 1, 4, 3, 0, 4, 2, 3;
  for (int i = 0; i < t.numTets(); ++i) {
    ASSERT_GT(
        tetVolume(t.V.row(t.T(i, 0)), t.V.row(t.T(i, 1)), t.V.row(t.T(i, 2)), t.V.row(t.T(i, 3))),
        0);
  }
  writeMsh(dir.file("a.msh"), t);
  const LoadedMesh r = readMsh(dir.file("a.msh"));
  ASSERT_TRUE(r.volume.has_value());
  EXPECT_EQ(r.volume->V, t.V);
  EXPECT_EQ(r.volume->T, t.T);
  EXPECT_EQ(r.reorientedTets, 0);
  const SurfaceMesh b = tetBoundary(t);
  EXPECT_EQ(r.surface.V, b.V);
  EXPECT_EQ(r.surface.F, b.F);
  EXPECT_NEAR(signedVolume(r.surface.V, r.surface.F), 1.0 / 6.0 * (1.0 / 3 + 1.0 / 3 + 1.0 / 3),
              1e-12);
}

/// Numbers inside <DataArray ... Name="name" ...> ... </DataArray> (first match; empty name =
/// first array without a Name attribute).
std::vector<double> dataArray(const std::string& xml, const std::string& name) {
  const std::string open =
      name.empty() ? "NumberOfComponents=\"3\" format=\"ascii\">" : "Name=\"" + name + "\"";
  size_t at = xml.find(open);
  if (at == std::string::npos) return {};
  at = xml.find('>', at) + 1;
  const size_t end = xml.find("</DataArray>", at);
  std::istringstream in(xml.substr(at, end - at));
  std::vector<double> v;
  double x;
  while (in >> x) v.push_back(x);
  return v;
}

std::string slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), {});
}

TEST(MeshIoRoundTrip, VtpHoldsPointsPolysAndScalars) {
  ScratchDir dir("io_vtp");
  const SurfaceMesh m = awkwardOctahedron();
  VecX s(6);
  s << 1.5, -2, 3e-7, 4, 5, 6;
  writeVtp(dir.file("a.vtp"), m, {{"stress<&>", s}, {"zero", VecX::Zero(6)}});
  const std::string xml = slurp(dir.file("a.vtp"));
  EXPECT_NE(xml.find("NumberOfPoints=\"6\""), std::string::npos);
  EXPECT_NE(xml.find("NumberOfPolys=\"8\""), std::string::npos);
  EXPECT_NE(xml.find("Name=\"stress&lt;&amp;&gt;\""), std::string::npos);
  const auto pts = dataArray(xml, "");
  ASSERT_EQ(pts.size(), 18u);
  for (int i = 0; i < 18; ++i) EXPECT_EQ(pts[size_t(i)], m.V(i / 3, i % 3));
  const auto conn = dataArray(xml, "connectivity");
  ASSERT_EQ(conn.size(), 24u);
  for (int i = 0; i < 24; ++i) EXPECT_EQ(conn[size_t(i)], m.F(i / 3, i % 3));
  const auto off = dataArray(xml, "offsets");
  ASSERT_EQ(off.size(), 8u);
  EXPECT_EQ(off.back(), 24);
  const auto sc = dataArray(xml, "stress&lt;&amp;&gt;");
  ASSERT_EQ(sc.size(), 6u);
  for (int i = 0; i < 6; ++i) EXPECT_EQ(sc[size_t(i)], s[i]);
  EXPECT_THROW(writeVtp(dir.file("b.vtp"), m, {{"short", VecX::Zero(5)}}), std::invalid_argument);
}

TEST(MeshIoRoundTrip, VtuHoldsTetraCells) {
  ScratchDir dir("io_vtu");
  TetMesh t;
  t.V = octahedron().V;
  t.T.resize(2, 4);
  t.T << 0, 2, 4, 5, 1, 3, 4, 5;
  writeVtu(dir.file("a.vtu"), t, {{"u", VecX::LinSpaced(6, 0, 1)}});
  const std::string xml = slurp(dir.file("a.vtu"));
  EXPECT_NE(xml.find("NumberOfCells=\"2\""), std::string::npos);
  const auto conn = dataArray(xml, "connectivity");
  ASSERT_EQ(conn.size(), 8u);
  for (int i = 0; i < 8; ++i) EXPECT_EQ(conn[size_t(i)], t.T(i / 4, i % 4));
  EXPECT_EQ(dataArray(xml, "offsets"), (std::vector<double>{4, 8}));
  EXPECT_EQ(dataArray(xml, "types"), (std::vector<double>{10, 10}));
  EXPECT_EQ(dataArray(xml, "u").size(), 6u);
}

TEST(MeshIoRoundTrip, PvdListsEveryStep) {
  ScratchDir dir("io_pvd");
  writePvd(dir.file("s.pvd"), {{0.0, "a/f0.vtp"}, {0.125, "a/f1.vtp"}});
  const std::string xml = slurp(dir.file("s.pvd"));
  EXPECT_NE(xml.find("type=\"Collection\""), std::string::npos);
  EXPECT_NE(xml.find("timestep=\"0\" group=\"\" part=\"0\" file=\"a/f0.vtp\""), std::string::npos);
  EXPECT_NE(xml.find("timestep=\"0.125\" group=\"\" part=\"0\" file=\"a/f1.vtp\""),
            std::string::npos);
}

TEST(MeshIoWrite, AtomicLeavesNoTemporaryAndReportsUnwritablePath) {
  ScratchDir dir("io_atomic");
  writeObj(dir.file("a.obj"), octahedron());
  writeObj(dir.file("a.obj"), octahedron());  // overwrite in place
  int files = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir.path())) {
    ++files;
    EXPECT_EQ(e.path().filename(), "a.obj");
  }
  EXPECT_EQ(files, 1);
  const std::string bad = dir.file("no/such/folder/a.obj");
  try {
    writeStl(bad, octahedron());
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), bad);
  }
}

// ---------------------------------------------------------------- readers on hand-made content

TEST(MeshIoRead, ObjCornerFormsNegativeIndicesAndPolygons) {
  ScratchDir dir("io_obj_read");
  const std::string path = dir.write("q.obj",
                                     "# comment\n"
                                     "mtllib x.mtl\n"
                                     "o thing\ng group\ns 1\nusemtl red\n"
                                     "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                     "vt 0 0\nvn 0 0 1\n"
                                     "v 0.5 0.5 -1 1.0\n"           // optional w ignored
                                     "f 1/1/1 4/1/1 3/1/1 2/1/1\n"  // quad: fan-triangulated
                                     "f 1//1 2//1 -1//1\r\n"        // -1 is vertex 5
                                     "f 2/1 3/1 5/1\n"
                                     "f -4 -3 -1\n"
                                     "l 1 2\n");
  const SurfaceMesh m = readObj(path);
  ASSERT_EQ(m.numVertices(), 5);
  ASSERT_EQ(m.numFaces(), 5);
  MatX3i expected(5, 3);
  expected << 0, 3, 2, 0, 2, 1, 0, 1, 4, 1, 2, 4, 1, 2, 4;
  EXPECT_EQ(m.F, expected);
  EXPECT_EQ(m.V(4, 2), -1);
}

TEST(MeshIoRead, AsciiStlMergesCornersInFirstSeenOrder) {
  ScratchDir dir("io_stl_ascii");
  const std::string path = dir.write("a.stl",
                                     "solid two\n"
                                     " facet normal 0 0 1\n  outer loop\n"
                                     "   vertex 0 0 0\n   vertex 1 0 0\n   vertex 0 1 0\n"
                                     "  endloop\n endfacet\n"
                                     " facet normal 0 0 1\n  outer loop\n"
                                     "   vertex 1 0 0\n   vertex 1 1 0\n   vertex -0 1 0\n"
                                     "  endloop\n endfacet\n"
                                     "endsolid two\n");
  const SurfaceMesh m = readStl(path);
  ASSERT_EQ(m.numVertices(), 4);  // -0 and 0 are the same coordinate
  MatX3i expected(2, 3);
  expected << 0, 1, 2, 1, 3, 2;
  EXPECT_EQ(m.F, expected);
  EXPECT_EQ(m.V.row(3), Eigen::RowVector3d(1, 1, 0));
}

std::string binaryStl(const std::string& header, const SurfaceMesh& m) {
  Bytes b;
  std::string h = header;
  h.resize(80, ' ');
  b.text(h).put<uint32_t>(uint32_t(m.numFaces()));
  for (int f = 0; f < m.numFaces(); ++f) {
    b.put<float>(0).put<float>(0).put<float>(0);
    for (int k = 0; k < 3; ++k) {
      for (int d = 0; d < 3; ++d) b.put<float>(float(m.V(m.F(f, k), d)));
    }
    b.put<uint16_t>(0);
  }
  return b.s;
}

TEST(MeshIoRead, BinaryStlWithColorHeaderAndWithSolidHeader) {
  ScratchDir dir("io_stl_bin");
  const SurfaceMesh m = octahedron();
  for (const std::string header : {"COLOR= MATERIAL=", "solid but binary"}) {
    const std::string path = dir.write("a.stl", binaryStl(header, m));
    const SurfaceMesh r = readStl(path);
    EXPECT_EQ(r.numVertices(), 6) << header;
    EXPECT_EQ(trianglePositions(r), trianglePositions(m)) << header;
  }
}

TEST(MeshIoRead, OffWithCommentsColoursAndQuads) {
  ScratchDir dir("io_off_read");
  const std::string path = dir.write("a.off",
                                     "COFF # coloured\n"
                                     "# counts follow\n"
                                     "5 2 0\n"
                                     "0 0 0 255 0 0 255\n1 0 0 255 0 0 255\n"
                                     "1 1 0 0 0 0 0\n0 1 0 0 0 0 0\n\n"
                                     "9 9 9 1 1 1 1\n"  // unreferenced: kept
                                     "4 0 1 2 3 10 20 30\n"
                                     "3 0 2 1\n");
  const SurfaceMesh m = readOff(path);
  EXPECT_EQ(m.numVertices(), 5);
  MatX3i expected(3, 3);
  expected << 0, 1, 2, 0, 2, 3, 0, 2, 1;
  EXPECT_EQ(m.F, expected);
  EXPECT_EQ(m.V(4, 0), 9);
}

TEST(MeshIoRead, PlyAsciiSkipsOtherPropertiesAndElements) {
  ScratchDir dir("io_ply_ascii");
  const std::string path = dir.write("a.ply",
                                     "ply\nformat ascii 1.0\ncomment made by hand\n"
                                     "element vertex 4\n"
                                     "property float nx\nproperty float x\nproperty float y\n"
                                     "property double z\nproperty uchar red\n"
                                     "element face 2\n"
                                     "property list uchar float texcoord\n"
                                     "property list uchar int vertex_indices\n"
                                     "property int flags\n"
                                     "element edge 1\nproperty int vertex1\nproperty int vertex2\n"
                                     "end_header\n"
                                     "9 0 0 0 255\n9 1 0 0 255\n9 1 1 0 255\n9 0 1 0.5 255\n"
                                     "2 0.5 0.5 4 0 1 2 3 7\n"
                                     "0 3 0 2 1 8\n"
                                     "0 1\n");
  const SurfaceMesh m = readPly(path);
  ASSERT_EQ(m.numVertices(), 4);
  EXPECT_EQ(m.V.row(3), Eigen::RowVector3d(0, 1, 0.5));
  MatX3i expected(3, 3);
  expected << 0, 1, 2, 0, 2, 3, 0, 2, 1;
  EXPECT_EQ(m.F, expected);
}

/// The same PLY content as binary of either byte order.
std::string binaryPly(bool big) {
  Bytes b;
  b.big = big;
  b.text(std::string("ply\nformat ") + (big ? "binary_big_endian" : "binary_little_endian") +
         " 1.0\n"
         "element material 1\nproperty ushort id\n"
         "element vertex 4\nproperty float x\nproperty float y\nproperty double z\n"
         "property uchar red\n"
         "element face 2\nproperty list uchar float texcoord\n"
         "property list uchar uint vertex_indices\nproperty short flags\n"
         "end_header\n");
  b.put<uint16_t>(7);
  const double P[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0.5}};
  for (const auto& p : P)
    b.put<float>(float(p[0])).put<float>(float(p[1])).put<double>(p[2]).put<uint8_t>(200);
  b.put<uint8_t>(2).put<float>(0.5f).put<float>(0.25f);
  b.put<uint8_t>(4).put<uint32_t>(0).put<uint32_t>(1).put<uint32_t>(2).put<uint32_t>(3);
  b.put<int16_t>(-1);
  b.put<uint8_t>(0);
  b.put<uint8_t>(3).put<uint32_t>(0).put<uint32_t>(2).put<uint32_t>(1);
  b.put<int16_t>(5);
  return b.s;
}

TEST(MeshIoRead, PlyBinaryBothEndiannesses) {
  ScratchDir dir("io_ply_bin");
  for (bool big : {false, true}) {
    const SurfaceMesh m = readPly(dir.write("a.ply", binaryPly(big)));
    ASSERT_EQ(m.numVertices(), 4) << big;
    EXPECT_EQ(m.V.row(3), Eigen::RowVector3d(0, 1, 0.5)) << big;
    MatX3i expected(3, 3);
    expected << 0, 1, 2, 0, 2, 3, 0, 2, 1;
    EXPECT_EQ(m.F, expected) << big;
  }
}

/// Legacy VTK POLYDATA of a mesh, ASCII or BINARY (big-endian float points, int cells).
std::string vtkPolyData(const SurfaceMesh& m, bool binary) {
  Bytes b;
  b.big = true;
  b.text("# vtk DataFile Version 3.0\nhand made\n" + std::string(binary ? "BINARY" : "ASCII") +
         "\nDATASET POLYDATA\nPOINTS " + std::to_string(m.numVertices()) + " float\n");
  for (int i = 0; i < m.numVertices(); ++i) {
    for (int d = 0; d < 3; ++d) {
      if (binary)
        b.put<float>(float(m.V(i, d)));
      else
        b.text(std::to_string(m.V(i, d)) + (d < 2 ? " " : "\n"));
    }
  }
  b.text("\nPOLYGONS " + std::to_string(m.numFaces()) + " " + std::to_string(4 * m.numFaces()) +
         "\n");
  for (int f = 0; f < m.numFaces(); ++f) {
    if (binary)
      b.put<int32_t>(3).put<int32_t>(m.F(f, 0)).put<int32_t>(m.F(f, 1)).put<int32_t>(m.F(f, 2));
    else
      b.text("3 " + std::to_string(m.F(f, 0)) + " " + std::to_string(m.F(f, 1)) + " " +
             std::to_string(m.F(f, 2)) + "\n");
  }
  b.text("\nPOINT_DATA " + std::to_string(m.numVertices()) + "\nSCALARS s float\n");
  return b.s;
}

TEST(MeshIoRead, VtkPolyDataAsciiAndBinary) {
  ScratchDir dir("io_vtk_poly");
  SurfaceMesh m = octahedron();
  m.V *= 0.5;
  for (bool binary : {false, true}) {
    const LoadedMesh r = readVtk(dir.write("a.vtk", vtkPolyData(m, binary)));
    EXPECT_FALSE(r.volume.has_value());
    EXPECT_EQ(r.surface.V, m.V) << binary;
    EXPECT_EQ(r.surface.F, m.F) << binary;
  }
}

TEST(MeshIoRead, VtkUnstructuredGridTetsAreReoriented) {
  ScratchDir dir("io_vtk_ug");
  const std::string path = dir.write("a.vtk",
                                     "# vtk DataFile Version 2.0\nug\nASCII\n"
                                     "DATASET UNSTRUCTURED_GRID\n"
                                     "POINTS 6 double\n"
                                     "0 0 0 1 0 0 0 1 0 0 0 1 0 0 -1 7 7 7\n"
                                     "CELLS 3 14\n"
                                     "4 0 1 2 3\n"
                                     "4 0 1 2 4\n"  // negative: node order reversed on read
                                     "3 0 1 2\n"
                                     "CELL_TYPES 3\n10 10 5\n"
                                     "CELL_DATA 3\n");
  const LoadedMesh r = readVtk(path);
  ASSERT_TRUE(twoTetsOneReoriented(r));
  for (int t = 0; t < 2; ++t) {
    const auto& T = r.volume->T;
    const auto& V = r.volume->V;
    EXPECT_GT(tetVolume(V.row(T(t, 0)), V.row(T(t, 1)), V.row(T(t, 2)), V.row(T(t, 3))), 0);
  }
  EXPECT_EQ(r.surface.numFaces(), 6);     // the shared face is interior
  EXPECT_EQ(r.surface.numVertices(), 6);  // node 5 (unused) kept, unreferenced
  const MeshReport rep = validateSurface(r.surface);
  EXPECT_TRUE(rep.usable());
  EXPECT_TRUE(rep.has(MeshDefect::UnreferencedVertices));
  EXPECT_NEAR(signedVolume(r.surface.V, r.surface.F), 2.0 / 6.0, 1e-12);
}

TEST(MeshIoRead, VtkBinaryUnstructuredTrianglesAndNewCellLayout) {
  ScratchDir dir("io_vtk_ug_bin");
  Bytes b;
  b.big = true;
  b.text("# vtk DataFile Version 3.0\nx\nBINARY\nDATASET UNSTRUCTURED_GRID\nPOINTS 4 double\n");
  const double P[4][3] = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0}, {0, 1, 0}};
  for (const auto& p : P) b.put<double>(p[0]).put<double>(p[1]).put<double>(p[2]);
  b.text("\nCELLS 2 9\n");
  b.put<int32_t>(4).put<int32_t>(0).put<int32_t>(1).put<int32_t>(2).put<int32_t>(3);
  b.put<int32_t>(3).put<int32_t>(0).put<int32_t>(2).put<int32_t>(1);
  b.text("\nCELL_TYPES 2\n").put<int32_t>(9).put<int32_t>(5).text("\n");
  LoadedMesh r = readVtk(dir.write("a.vtk", b.s));
  EXPECT_FALSE(r.volume.has_value());
  MatX3i expected(3, 3);
  expected << 0, 1, 2, 0, 2, 3, 0, 2, 1;
  EXPECT_EQ(r.surface.F, expected);

  // VTK 5.1 OFFSETS / CONNECTIVITY layout, ASCII, with a METADATA block.
  r = readVtk(dir.write("b.vtk",
                        "# vtk DataFile Version 5.1\nx\nASCII\nDATASET POLYDATA\n"
                        "POINTS 4 float\n0 0 0 1 0 0 1 1 0 0 1 0\n"
                        "METADATA\nINFORMATION 0\n\n"
                        "POLYGONS 3 7\nOFFSETS vtktypeint64\n0 4 7\n"
                        "CONNECTIVITY vtktypeint64\n0 1 2 3 0 2 1\n"));
  EXPECT_EQ(r.surface.F, expected);
}

TEST(MeshIoRead, Msh22ArbitraryTagsMixedElements) {
  ScratchDir dir("io_msh22");
  const std::string path = dir.write("a.msh",
                                     "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n"
                                     "$PhysicalNames\n1\n3 1 \"tissue\"\n$EndPhysicalNames\n"
                                     "$Nodes\n6\n"
                                     "10 0 0 0\n20 1 0 0\n30 0 1 0\n40 0 0 1\n55 0 0 -1\n"
                                     "99 5 5 5\n"
                                     "$EndNodes\n"
                                     "$Elements\n5\n"
                                     "1 15 2 0 1 10\n"
                                     "2 1 2 0 1 10 20\n"
                                     "3 2 2 0 1 10 20 30\n"
                                     "4 4 2 1 1 10 20 30 40\n"
                                     "5 4 2 1 1 10 20 30 55\n"  // negative orientation
                                     "$EndElements\n");
  const LoadedMesh r = readMsh(path);
  ASSERT_TRUE(twoTetsOneReoriented(r));
  EXPECT_EQ(r.volume->T.row(0), Eigen::RowVector4i(0, 1, 2, 3));
  EXPECT_EQ(r.volume->T.row(1), Eigen::RowVector4i(0, 2, 1, 4));
  EXPECT_EQ(r.surface.numFaces(), 6);
  EXPECT_EQ(r.surface.V.rows(), 6);  // surface vertex i is node i
  EXPECT_TRUE(validateSurface(r.surface).usable());
}

TEST(MeshIoRead, MshTrianglesOnlyAndLegacy10) {
  ScratchDir dir("io_msh_tri");
  LoadedMesh r = readMsh(dir.write("a.msh",
                                   "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n3\n"
                                   "1 0 0 0\n2 1 0 0\n3 0 1 0\n$EndNodes\n$Elements\n1\n"
                                   "1 2 0 1 3 2\n$EndElements\n"));
  EXPECT_FALSE(r.volume.has_value());
  EXPECT_EQ(r.surface.F.row(0), Eigen::RowVector3i(0, 2, 1));

  r = readMsh(dir.write("b.msh",
                        "$NOD\n4\n1 0 0 0\n2 1 0 0\n3 0 1 0\n4 0 0 1\n$ENDNOD\n"
                        "$ELM\n1\n1 4 1 1 4 1 2 3 4\n$ENDELM\n"));
  ASSERT_TRUE(r.volume.has_value());
  EXPECT_EQ(r.volume->numTets(), 1);
  EXPECT_TRUE(validateSurface(r.surface).ok());
}

TEST(MeshIoRead, ReadMeshDispatchesOnExtension) {
  ScratchDir dir("io_dispatch");
  writeObj(dir.file("A.OBJ"), octahedron());
  EXPECT_EQ(readMesh(dir.file("A.OBJ")).surface.numFaces(), 8);
  writeOff(dir.file("a.off"), octahedron());
  EXPECT_EQ(readMesh(dir.file("a.off")).surface.numFaces(), 8);
  const std::string p = dir.write("a.xyz", "1 2 3\n");
  const std::string problem = expectInputError([&] { readMesh(p); }, p, "");
  EXPECT_NE(problem.find("unknown mesh extension"), std::string::npos) << problem;
  const std::string missing = dir.file("missing.stl");
  expectInputError([&] { readMesh(missing); }, missing, "");
  std::filesystem::create_directory(dir.file("folder.obj"));
  expectInputError([&] { readMesh(dir.file("folder.obj")); }, dir.file("folder.obj"), "");
}

// ---------------------------------------------------------------- malformed input

TEST(MeshIoMalformed, TruncatedBinaryStl) {
  ScratchDir dir("io_bad_stl");
  std::string data = binaryStl("COLOR= truncated", octahedron());
  data.resize(data.size() - 10);
  const std::string p = dir.write("a.stl", data);
  const std::string problem = expectInputError([&] { readStl(p); }, p, "byte 80");
  EXPECT_NE(problem.find("truncated"), std::string::npos) << problem;
  const std::string tiny = dir.write("b.stl", "COLOR=");
  expectInputError([&] { readStl(tiny); }, tiny, "byte 0");
}

TEST(MeshIoMalformed, NanInBinaryStlNamesTheTriangle) {
  ScratchDir dir("io_nan_stl");
  SurfaceMesh m = octahedron();
  m.V(4, 2) = std::numeric_limits<double>::quiet_NaN();  // first used by triangle 0
  m.F.row(0) << 0, 2, 1;                                 // keep vertex 4 out of triangle 0 ...
  m.F.row(1) << 2, 4, 1;  // ... so triangle 1 (at byte 84 + 50) is the first bad one
  const std::string p = dir.write("a.stl", binaryStl("x", m));
  const std::string problem = expectInputError([&] { readStl(p); }, p, "byte 134");
  EXPECT_NE(problem.find("NaN"), std::string::npos) << problem;
}

TEST(MeshIoMalformed, ObjGarbageIndexAndNan) {
  ScratchDir dir("io_bad_obj");
  std::string p = dir.write("a.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0.x\nf 1 2 3\n");
  std::string problem = expectInputError([&] { readObj(p); }, p, "line 3");
  EXPECT_NE(problem.find("0.x"), std::string::npos) << problem;
  p = dir.write("b.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 3\nf 1 2 4\n");
  problem = expectInputError([&] { readObj(p); }, p, "line 6");
  EXPECT_NE(problem.find("out of range"), std::string::npos) << problem;
  p = dir.write("c.obj", "v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n");
  expectInputError([&] { readObj(p); }, p, "line 2");
  p = dir.write("d.obj", "v 0 0 0\nv 1 0 0\nv 0 1 inf\nf 1 2 3\n");
  expectInputError([&] { readObj(p); }, p, "line 3");
  p = dir.write("e.obj", "v 0 0 0\nf 1 -2 1\n");
  expectInputError([&] { readObj(p); }, p, "line 2");
  p = dir.write("f.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n");
  problem = expectInputError([&] { readObj(p); }, p, "");
  EXPECT_NE(problem.find("no triangles"), std::string::npos) << problem;
  p = dir.write("g.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2\n");
  expectInputError([&] { readObj(p); }, p, "line 4");
}

TEST(MeshIoMalformed, OffPlyVtkMsh) {
  ScratchDir dir("io_bad_misc");
  std::string p = dir.write("a.off", "OFF\n1000000 1 0\n0 0 0\n");
  expectInputError([&] { readOff(p); }, p, "line 2");
  p = dir.write("b.off", "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 3\n");
  expectInputError([&] { readOff(p); }, p, "line 6");
  p = dir.write("c.off",
                "OFF\n3 1 0\n0 0 0\n1 0 0\n# a comment long enough to pass the size check\n");
  expectInputError([&] { readOff(p); }, p, "line 6");  // end of file: the line after the last

  std::string ply = binaryPly(false);
  ply.resize(ply.size() - 3);
  p = dir.write("a.ply", ply);
  const std::string problem =
      expectInputError([&] { readPly(p); }, p, "byte " + std::to_string(ply.size() - 12));
  EXPECT_NE(problem.find("truncated"), std::string::npos) << problem;
  p = dir.write("b.ply",
                "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                "property float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                "end_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 5\n");
  expectInputError([&] { readPly(p); }, p, "line 13");

  SurfaceMesh m = octahedron();
  std::string vtk = vtkPolyData(m, true);
  const size_t cut = vtk.find("POLYGONS") + 30;
  p = dir.write("a.vtk", vtk.substr(0, cut));
  expectInputError([&] { readVtk(p); }, p, "byte " + std::to_string(vtk.find("POLYGONS") + 14));
  m.F(7, 2) = 6;
  p = dir.write("b.vtk", vtkPolyData(m, false));
  expectInputError([&] { readVtk(p); }, p, "element 7");

  p = dir.write("a.msh",
                "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n3\n1 0 0 0\n2 1 0 0\n3 0 1 0\n"
                "$EndNodes\n$Elements\n1\n1 2 0 1 2 4\n$EndElements\n");
  expectInputError([&] { readMsh(p); }, p, "line 12");
  p = dir.write("b.msh", "$MeshFormat\n4.1 0 8\n$EndMeshFormat\n");
  EXPECT_NE(expectInputError([&] { readMsh(p); }, p, "line 2").find("re-save as 2.2"),
            std::string::npos);
}

// ---------------------------------------------------------------- robustness

/// Random corruptions of valid files: every reader either returns a well-formed mesh or throws
/// InputError; nothing else escapes, nothing reads out of bounds (run under ASan to see that).
TEST(MeshIoRobustness, MutatedFilesThrowInputErrorOrLoad) {
  ScratchDir dir("io_fuzz");
  SurfaceMesh m = octahedron();
  std::vector<std::pair<std::string, std::string>> seeds;
  writeObj(dir.file("s.obj"), m);
  writeOff(dir.file("s.off"), m);
  TetMesh t;
  t.V = m.V;
  t.T.resize(2, 4);
  t.T << 0, 2, 4, 5, 1, 3, 4, 5;
  writeMsh(dir.file("s.msh"), t);
  seeds.emplace_back(".obj", slurp(dir.file("s.obj")));
  seeds.emplace_back(".off", slurp(dir.file("s.off")));
  seeds.emplace_back(".msh", slurp(dir.file("s.msh")));
  seeds.emplace_back(".stl", binaryStl("COLOR=", m));
  seeds.emplace_back(".ply", binaryPly(false));
  seeds.emplace_back(".ply", binaryPly(true));
  seeds.emplace_back(".vtk", vtkPolyData(m, true));
  seeds.emplace_back(".vtk", vtkPolyData(m, false));
  std::mt19937 rng(12345);
  int loaded = 0, refused = 0;
  for (const auto& [ext, seed] : seeds) {
    for (int iter = 0; iter < 2000; ++iter) {
      std::string data = seed;
      const int edits = 1 + int(rng() % 4);
      for (int e = 0; e < edits && !data.empty(); ++e) {
        const size_t at = rng() % data.size();
        switch (rng() % 4) {
          case 0:
            data[at] = char(rng());
            break;
          case 1:
            data.resize(at);
            break;
          case 2:
            data.insert(at, 1, "0123456789 -.e\n/#$"[rng() % 18]);
            break;
          default:
            data[at] = char(data[at] ^ (1 << (rng() % 8)));
        }
      }
      const std::string p = "fuzz" + ext;
      try {
        const LoadedMesh r = readMeshFromMemory(data, p);
        const SurfaceMesh& s = r.surface;
        ASSERT_GT(s.numFaces(), 0);
        ASSERT_TRUE(s.V.allFinite());
        ASSERT_GE(s.F.minCoeff(), 0);
        ASSERT_LT(s.F.maxCoeff(), s.numVertices());
        validateSurface(s);  // must not crash on whatever loaded
        ++loaded;
      } catch (const InputError& e) {
        ASSERT_EQ(e.file(), p);
        ++refused;
      } catch (const std::exception& e) {
        FAIL() << ext << " iteration " << iter << ": unexpected " << e.what();
      }
    }
  }
  EXPECT_GT(refused, 0);
  EXPECT_GT(loaded, 0);
}

}  // namespace
}  // namespace deform
