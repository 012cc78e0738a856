// Mesh writers. Each builds the whole file in memory and then writes it atomically: a temporary
// file in the destination folder, renamed over the target, so a reader never sees half a file.
#include <deform/geometry/mesh_io.h>
#include <deform/sdk/error.h>

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <bit>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <type_traits>

namespace deform {
namespace {

void writeAtomically(const std::string& path, const std::string& contents) {
  static std::atomic<unsigned> counter{0};
  const std::string tmp =
      path + ".tmp-" + std::to_string(::getpid()) + "-" + std::to_string(counter.fetch_add(1));
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    if (!out) throw InputError(path, "", std::string("cannot write: ") + std::strerror(errno));
    out.write(contents.data(), static_cast<std::streamsize>(contents.size()));
    out.close();
    if (!out) {
      std::error_code ignored;
      std::filesystem::remove(tmp, ignored);
      throw InputError(path, "", "cannot write (disk full?)");
    }
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    throw InputError(path, "", "cannot write: " + ec.message());
  }
}

/// Shortest decimal text that reads back to the same double.
void appendReal(std::string& s, double v) {
  char buf[32];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  s.append(buf, r.ptr);
}

void appendInt(std::string& s, long long v) {
  char buf[24];
  const auto r = std::to_chars(buf, buf + sizeof buf, v);
  s.append(buf, r.ptr);
}

template <class T>
void appendLittleEndian(std::string& s, T v) {
  char b[sizeof(T)];
  std::memcpy(b, &v, sizeof(T));
  if constexpr (std::endian::native == std::endian::big) std::reverse(b, b + sizeof(T));
  s.append(b, sizeof(T));
}

std::string xmlEscape(const std::string& in) {
  std::string out;
  for (char c : in) {
    switch (c) {
      case '&':
        out += "&amp;";
        break;
      case '<':
        out += "&lt;";
        break;
      case '>':
        out += "&gt;";
        break;
      case '"':
        out += "&quot;";
        break;
      case '\'':
        out += "&apos;";
        break;
      default:
        out += c;
    }
  }
  return out;
}

void checkScalars(const std::vector<std::pair<std::string, VecX>>& scalars, Eigen::Index n) {
  for (const auto& [name, values] : scalars) {
    if (values.size() != n) {
      throw std::invalid_argument("point scalar '" + name + "' has " +
                                  std::to_string(values.size()) + " values for " +
                                  std::to_string(n) + " points");
    }
  }
}

void appendPointsXml(std::string& s, const MatX3& V,
                     const std::vector<std::pair<std::string, VecX>>& scalars) {
  if (!scalars.empty()) {
    s += "<PointData Scalars=\"" + xmlEscape(scalars.front().first) + "\">\n";
    for (const auto& [name, values] : scalars) {
      s += "<DataArray type=\"Float64\" Name=\"" + xmlEscape(name) + "\" format=\"ascii\">\n";
      for (Eigen::Index i = 0; i < values.size(); ++i) {
        appendReal(s, values[i]);
        s += '\n';
      }
      s += "</DataArray>\n";
    }
    s += "</PointData>\n";
  }
  s += "<Points>\n<DataArray type=\"Float64\" NumberOfComponents=\"3\" format=\"ascii\">\n";
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    for (int k = 0; k < 3; ++k) {
      appendReal(s, V(i, k));
      s += k < 2 ? ' ' : '\n';
    }
  }
  s += "</DataArray>\n</Points>\n";
}

/// The row's entries, each after a space (indices plus `offset`), then a newline.
template <class Row>
void appendSpacedRow(std::string& s, const Row& row, int offset = 0) {
  for (Eigen::Index k = 0; k < row.size(); ++k) {
    s += ' ';
    if constexpr (std::is_integral_v<typename Row::Scalar>)
      appendInt(s, row(k) + offset);
    else
      appendReal(s, row(k));
  }
  s += '\n';
}

/// The XML declaration and the root of a VTK XML file of `type` (PolyData, UnstructuredGrid),
/// opened down to the element of that type.
std::string vtkXmlHead(const std::string& type) {
  return "<?xml version=\"1.0\"?>\n<VTKFile type=\"" + type +
         "\" version=\"1.0\" byte_order=\"LittleEndian\" header_type=\"UInt64\">\n<" + type + ">\n";
}

/// connectivity + offsets arrays of equal-size cells (rows of an index matrix).
template <class IndexMatrix>
void appendCellsXml(std::string& s, const IndexMatrix& cells) {
  s += "<DataArray type=\"Int64\" Name=\"connectivity\" format=\"ascii\">\n";
  for (Eigen::Index i = 0; i < cells.rows(); ++i) {
    for (Eigen::Index k = 0; k < cells.cols(); ++k) {
      appendInt(s, cells(i, k));
      s += k + 1 < cells.cols() ? ' ' : '\n';
    }
  }
  s += "</DataArray>\n<DataArray type=\"Int64\" Name=\"offsets\" format=\"ascii\">\n";
  for (Eigen::Index i = 0; i < cells.rows(); ++i) {
    appendInt(s, (i + 1) * cells.cols());
    s += '\n';
  }
  s += "</DataArray>\n";
}

}  // namespace

void writeObj(const std::string& path, const SurfaceMesh& mesh) {
  std::string s = "# deformbench surface: " + std::to_string(mesh.numVertices()) + " vertices, " +
                  std::to_string(mesh.numFaces()) + " triangles\n";
  s.reserve(size_t(40) * size_t(mesh.numVertices() + mesh.numFaces()));
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) {
    s += 'v';
    appendSpacedRow(s, mesh.V.row(i));
  }
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    s += 'f';
    appendSpacedRow(s, mesh.F.row(f), 1);  // OBJ counts from 1
  }
  writeAtomically(path, s);
}

void writeOff(const std::string& path, const SurfaceMesh& mesh) {
  std::string s = "OFF\n";
  appendInt(s, mesh.numVertices());
  s += ' ';
  appendInt(s, mesh.numFaces());
  s += " 0\n";
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) {
    for (int k = 0; k < 3; ++k) {
      appendReal(s, mesh.V(i, k));
      s += k < 2 ? ' ' : '\n';
    }
  }
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    s += '3';
    appendSpacedRow(s, mesh.F.row(f));
  }
  writeAtomically(path, s);
}

void writeStl(const std::string& path, const SurfaceMesh& mesh) {
  std::string s = "binary STL written by deformbench";
  s.resize(80, ' ');
  appendLittleEndian<uint32_t>(s, static_cast<uint32_t>(mesh.numFaces()));
  s.reserve(84 + size_t(50) * size_t(mesh.numFaces()));
  for (Eigen::Index f = 0; f < mesh.F.rows(); ++f) {
    const Vec3 a = mesh.V.row(mesh.F(f, 0)), b = mesh.V.row(mesh.F(f, 1)),
               c = mesh.V.row(mesh.F(f, 2));
    const Vec3 n = (b - a).cross(c - a).normalized();  // zero for a degenerate triangle
    for (int k = 0; k < 3; ++k) appendLittleEndian<float>(s, std::isfinite(n[k]) ? float(n[k]) : 0);
    for (const Vec3* p : {&a, &b, &c}) {
      for (int k = 0; k < 3; ++k) appendLittleEndian<float>(s, static_cast<float>((*p)[k]));
    }
    appendLittleEndian<uint16_t>(s, 0);
  }
  writeAtomically(path, s);
}

void writeVtp(const std::string& path, const SurfaceMesh& mesh,
              const std::vector<std::pair<std::string, VecX>>& pointScalars) {
  checkScalars(pointScalars, mesh.V.rows());
  std::string s = vtkXmlHead("PolyData");
  s += "<Piece NumberOfPoints=\"" + std::to_string(mesh.numVertices()) +
       "\" NumberOfVerts=\"0\" NumberOfLines=\"0\" NumberOfStrips=\"0\" NumberOfPolys=\"" +
       std::to_string(mesh.numFaces()) + "\">\n";
  appendPointsXml(s, mesh.V, pointScalars);
  s += "<Polys>\n";
  appendCellsXml(s, mesh.F);
  s += "</Polys>\n</Piece>\n</PolyData>\n</VTKFile>\n";
  writeAtomically(path, s);
}

void writeVtu(const std::string& path, const TetMesh& mesh,
              const std::vector<std::pair<std::string, VecX>>& pointScalars) {
  checkScalars(pointScalars, mesh.V.rows());
  std::string s = vtkXmlHead("UnstructuredGrid");
  s += "<Piece NumberOfPoints=\"" + std::to_string(mesh.numVertices()) + "\" NumberOfCells=\"" +
       std::to_string(mesh.numTets()) + "\">\n";
  appendPointsXml(s, mesh.V, pointScalars);
  s += "<Cells>\n";
  appendCellsXml(s, mesh.T);
  s += "<DataArray type=\"UInt8\" Name=\"types\" format=\"ascii\">\n";
  for (Eigen::Index t = 0; t < mesh.T.rows(); ++t) s += "10\n";
  s += "</DataArray>\n</Cells>\n</Piece>\n</UnstructuredGrid>\n</VTKFile>\n";
  writeAtomically(path, s);
}

void writeMsh(const std::string& path, const TetMesh& mesh) {
  std::string s = "$MeshFormat\n2.2 0 8\n$EndMeshFormat\n$Nodes\n";
  appendInt(s, mesh.numVertices());
  s += '\n';
  for (Eigen::Index i = 0; i < mesh.V.rows(); ++i) {
    appendInt(s, i + 1);
    appendSpacedRow(s, mesh.V.row(i));
  }
  s += "$EndNodes\n$Elements\n";
  appendInt(s, mesh.numTets());
  s += '\n';
  for (Eigen::Index t = 0; t < mesh.T.rows(); ++t) {
    appendInt(s, t + 1);
    s += " 4 2 1 1";  // type 4 (tet), two tags: physical 1, elementary 1
    appendSpacedRow(s, mesh.T.row(t), 1);
  }
  s += "$EndElements\n";
  writeAtomically(path, s);
}

void writePvd(const std::string& path, const std::vector<std::pair<Real, std::string>>& series) {
  std::string s =
      "<?xml version=\"1.0\"?>\n"
      "<VTKFile type=\"Collection\" version=\"0.1\" byte_order=\"LittleEndian\">\n<Collection>\n";
  for (const auto& [time, file] : series) {
    s += "<DataSet timestep=\"";
    appendReal(s, time);
    s += "\" group=\"\" part=\"0\" file=\"" + xmlEscape(file) + "\"/>\n";
  }
  s += "</Collection>\n</VTKFile>\n";
  writeAtomically(path, s);
}

}  // namespace deform
