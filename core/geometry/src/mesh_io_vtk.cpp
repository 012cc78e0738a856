// Legacy VTK reader: DATASET POLYDATA (POLYGONS, TRIANGLE_STRIPS; VERTICES and LINES are read
// past) and UNSTRUCTURED_GRID (tetra 10 and quadratic tetra 24 give a volume; triangle 5,
// polygon 7, quad 9 and quadratic triangle 22 give a surface when there are no tets), ASCII or
// BINARY (big-endian), with the classic cell layout (count, ids...) or the 5.x OFFSETS /
// CONNECTIVITY layout. Attribute data (POINT_DATA, CELL_DATA, FIELD) is not needed and ends the
// parse.
#include <deform/geometry/mesh_io.h>

#include <algorithm>
#include <cmath>
#include <optional>

#include "mesh_io_util.h"

namespace deform {
namespace {

std::string upper(std::string_view s) {
  std::string u(s);
  std::transform(u.begin(), u.end(), u.begin(),
                 [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
  return u;
}

std::optional<io::ScalarType> vtkType(std::string_view s) {
  using io::ScalarType;
  const std::string t = upper(s);
  if (t == "UNSIGNED_CHAR") return ScalarType::UInt8;
  if (t == "CHAR") return ScalarType::Int8;
  if (t == "UNSIGNED_SHORT") return ScalarType::UInt16;
  if (t == "SHORT") return ScalarType::Int16;
  if (t == "UNSIGNED_INT") return ScalarType::UInt32;
  if (t == "INT") return ScalarType::Int32;
  if (t == "VTKTYPEINT64" || t == "VTKIDTYPE") return ScalarType::Int64;
  if (t == "VTKTYPEUINT64") return ScalarType::UInt64;
  if (t == "FLOAT") return ScalarType::Float32;
  if (t == "DOUBLE") return ScalarType::Float64;
  return std::nullopt;
}

/// Corners used of a VTK cell type: tetra 10 and quadratic tetra 24 (corners listed first) 4,
/// triangle 5 and quadratic triangle 22 3, quad 9 4, polygon 7 at least 3; 0 for cells we skip.
long long cornerCount(int type) {
  switch (type) {
    case 10:
    case 24:
    case 9:
      return 4;
    case 5:
    case 22:
    case 7:
      return 3;
    default:
      return 0;
  }
}

/// Cells as offsets into a flat id list: cell i is ids[offsets[i] .. offsets[i+1]).
struct CellList {
  std::vector<long long> offsets{0};
  std::vector<long long> ids;
  size_t size() const { return offsets.size() - 1; }
};

class VtkReader {
 public:
  VtkReader(std::string_view data, const std::string& path) : m_cur(data, path) {}

  LoadedMesh read() {
    std::string_view line;
    if (!m_cur.nextLine(line) || line.find("vtk DataFile Version") == std::string_view::npos) {
      m_cur.fail("not a legacy VTK file (no '# vtk DataFile Version' line)");
    }
    if (!m_cur.nextLine(line)) m_cur.fail("truncated file: no title line");
    std::vector<std::string_view> tok;
    do {
      if (!m_cur.nextLine(line)) m_cur.fail("truncated file: no ASCII/BINARY line");
      io::splitTokens(line, tok);
    } while (tok.empty());
    const std::string enc = upper(tok[0]);
    if (enc == "BINARY")
      m_binary = true;
    else if (enc != "ASCII")
      m_cur.fail("expected ASCII or BINARY, got '" + enc + "'");
    const std::string kw = upper(m_cur.token("DATASET"));
    if (kw != "DATASET") m_cur.fail("expected DATASET, got '" + kw.substr(0, 40) + "'");
    const std::string type = upper(m_cur.token("a dataset type"));
    if (type == "POLYDATA")
      m_unstructured = false;
    else if (type == "UNSTRUCTURED_GRID")
      m_unstructured = true;
    else
      m_cur.fail("dataset " + type + " is not supported (POLYDATA or UNSTRUCTURED_GRID)");
    restOfLine();

    while (true) {
      m_cur.skipSpace();
      if (m_cur.atEnd()) break;
      m_cur.setBinary(false);  // keywords are text, named by line
      const std::string key = upper(m_cur.token("a section keyword"));
      if (key == "POINTS") {
        readPoints();
      } else if (key == "POLYGONS" || key == "TRIANGLE_STRIPS" || key == "VERTICES" ||
                 key == "LINES" || key == "CELLS") {
        if (key == "CELLS" ? !m_unstructured : m_unstructured) {
          m_cur.fail(key + " does not belong in this dataset type");
        }
        CellList cells = readCells();
        if (key == "POLYGONS")
          m_polygons.push_back(std::move(cells));
        else if (key == "TRIANGLE_STRIPS")
          m_strips.push_back(std::move(cells));
        else if (key == "CELLS")
          m_cells = std::move(cells);
      } else if (key == "CELL_TYPES") {
        readCellTypes();
      } else if (key == "METADATA") {
        // 5.x writes an INFORMATION block after arrays; it ends at an empty line.
        restOfLine();
        while (m_cur.nextLine(line) && line.find_first_not_of(" \t\r") != std::string_view::npos) {
        }
      } else if (key == "POINT_DATA" || key == "CELL_DATA" || key == "FIELD") {
        break;
      } else {
        m_cur.fail("unknown section '" + key.substr(0, 40) + "'");
      }
    }
    return build();
  }

 private:
  void restOfLine() {
    std::string_view rest;
    m_cur.nextLine(rest);
  }

  io::ScalarType typeToken() {
    const std::string_view t = m_cur.token("a data type");
    const auto st = vtkType(t);
    if (!st) m_cur.fail("unsupported data type '" + std::string(t.substr(0, 40)) + "'");
    return *st;
  }

  long long count(const char* what) {
    const long long n = m_cur.integer(what);
    if (n < 0 || n > io::kMaxCount) m_cur.fail(std::string("invalid ") + what);
    return n;
  }

  /// n values of type t starting at the cursor (binary data starts after the keyword line).
  template <class Fn>
  void values(long long n, io::ScalarType t, const char* what, Fn&& fn) {
    m_cur.setBinary(m_binary);
    m_cur.setMark(m_cur.pos());
    const size_t sz = io::scalarSize(t);
    m_cur.requireFits(n, m_binary ? sz : 2, what);
    if (m_binary) {
      const unsigned char* p = m_cur.take(size_t(n) * sz, what);
      for (long long i = 0; i < n; ++i) {
        m_cur.setMark(m_cur.pos() - size_t(n - i) * sz);
        fn(io::decodeScalar(p + size_t(i) * sz, t, true));
      }
    } else {
      for (long long i = 0; i < n; ++i) fn(m_cur.real(what));
    }
  }

  long long asIndex(double v, const char* what) {
    if (!(v >= 0) || v > double(io::kMaxCount) || std::trunc(v) != v) {
      m_cur.fail(std::string("invalid ") + what + " " + std::to_string(v));
    }
    return static_cast<long long>(v);
  }

  void readPoints() {
    if (m_havePoints) m_cur.fail("second POINTS section");
    const long long n = count("point count");
    const io::ScalarType t = typeToken();
    restOfLine();
    // Reserve no more than the rest of the file can hold (values() checks the count itself).
    m_xyz.reserve(std::min(3 * size_t(n), m_cur.remaining()));
    values(3 * n, t, "point coordinates", [&](double v) {
      if (!std::isfinite(v)) m_cur.fail("non-finite coordinate (NaN or Inf)");
      m_xyz.push_back(v);
    });
    m_havePoints = true;
  }

  CellList readCells() {
    const long long n = count("cell count");
    const long long size = count("cell list size");
    restOfLine();
    CellList cells;
    // Binary data may begin with bytes that look like blanks, so only skip them in ASCII.
    if (!m_binary) m_cur.skipSpace();
    if (m_cur.data().substr(m_cur.pos(), 7) == "OFFSETS") {
      // 5.x layout: OFFSETS type / n values, CONNECTIVITY type / size values.
      m_cur.token("OFFSETS");
      io::ScalarType t = typeToken();
      restOfLine();
      cells.offsets.clear();
      values(n, t, "cell offsets", [&](double v) {
        const long long o = asIndex(v, "cell offset");
        if (!cells.offsets.empty() && o < cells.offsets.back()) m_cur.fail("decreasing offsets");
        cells.offsets.push_back(o);
      });
      m_cur.setBinary(false);
      if (upper(m_cur.token("CONNECTIVITY")) != "CONNECTIVITY") m_cur.fail("expected CONNECTIVITY");
      t = typeToken();
      restOfLine();
      values(size, t, "cell connectivity",
             [&](double v) { cells.ids.push_back(asIndex(v, "point index")); });
      if (cells.offsets.empty()) cells.offsets.push_back(0);
      if (cells.offsets.front() != 0 || cells.offsets.back() != size) {
        m_cur.fail("cell offsets do not match the connectivity size");
      }
      return cells;
    }
    // Classic layout: `size` ints, each cell as its id count followed by the ids.
    std::vector<long long> flat;
    flat.reserve(size_t(std::min<long long>(size, 1 << 24)));
    values(size, io::ScalarType::Int32, "cell list",
           [&](double v) { flat.push_back(asIndex(v, "cell list entry")); });
    size_t pos = 0;
    cells.offsets.reserve(std::min(size_t(n), flat.size()) + 1);
    cells.ids.reserve(flat.size());
    for (long long c = 0; c < n; ++c) {
      if (pos >= flat.size() || flat[pos] > static_cast<long long>(flat.size() - pos - 1)) {
        throw InputError(
            m_cur.file(), "element " + std::to_string(c),
            "cell list shorter than its cells need (size " + std::to_string(size) + ")");
      }
      const long long k = flat[pos++];
      cells.ids.insert(cells.ids.end(), flat.begin() + long(pos), flat.begin() + long(pos + k));
      pos += size_t(k);
      cells.offsets.push_back(static_cast<long long>(cells.ids.size()));
    }
    if (pos != flat.size()) m_cur.fail("cell list size does not match its cells");
    return cells;
  }

  void readCellTypes() {
    const long long n = count("cell type count");
    restOfLine();
    m_types.clear();
    m_types.reserve(std::min(size_t(n), m_cur.remaining()));
    values(n, io::ScalarType::Int32, "cell types",
           [&](double v) { m_types.push_back(static_cast<int>(asIndex(v, "cell type"))); });
  }

  int checkedId(long long id, size_t cell) const {
    if (id >= static_cast<long long>(m_xyz.size() / 3)) {
      throw InputError(m_cur.file(), "element " + std::to_string(cell),
                       "point index " + std::to_string(id) + " out of range (" +
                           std::to_string(m_xyz.size() / 3) + " points)");
    }
    return static_cast<int>(id);
  }

  LoadedMesh build() {
    const std::string& file = m_cur.file();
    if (!m_havePoints) throw InputError(file, "", "no POINTS section");
    io::SurfaceBuilder surf;
    surf.xyz = m_xyz;
    std::vector<int> poly, tets;
    auto cellIds = [&](const CellList& cl, size_t c, size_t take) {
      poly.clear();
      const long long b = cl.offsets[c], e = cl.offsets[c + 1];
      for (long long i = b; i < e && poly.size() < take; ++i) {
        poly.push_back(checkedId(cl.ids[size_t(i)], c));
      }
    };
    for (const CellList& cl : m_polygons) {
      for (size_t c = 0; c < cl.size(); ++c) {
        cellIds(cl, c, SIZE_MAX);
        if (poly.size() < 3) {
          throw InputError(file, "element " + std::to_string(c), "polygon with < 3 points");
        }
        surf.addPolygon(poly.data(), poly.size());
      }
    }
    for (const CellList& cl : m_strips) {
      for (size_t c = 0; c < cl.size(); ++c) {
        cellIds(cl, c, SIZE_MAX);
        // Strip triangle k is (k, k+1, k+2), every other one reversed to keep the winding.
        for (size_t k = 0; k + 2 < poly.size(); ++k) {
          const int t[3] = {poly[k], poly[k % 2 ? k + 2 : k + 1], poly[k % 2 ? k + 1 : k + 2]};
          surf.addPolygon(t, 3);
        }
      }
    }
    if (m_unstructured) {
      if (m_types.size() != m_cells.size()) {
        throw InputError(file, "",
                         "CELL_TYPES count " + std::to_string(m_types.size()) +
                             " differs from CELLS count " + std::to_string(m_cells.size()));
      }
      for (size_t c = 0; c < m_cells.size(); ++c) {
        const long long k = m_cells.offsets[c + 1] - m_cells.offsets[c];
        const int type = m_types[c];
        const long long need = cornerCount(type);
        if (need == 0) continue;
        if (k < need || ((type == 10 || type == 5 || type == 9) && k != need)) {
          throw InputError(
              file, "element " + std::to_string(c),
              "cell type " + std::to_string(type) + " with " + std::to_string(k) + " points");
        }
        if (type == 10 || type == 24) {
          cellIds(m_cells, c, 4);
          tets.insert(tets.end(), poly.begin(), poly.end());
        } else {
          cellIds(m_cells, c, type == 7 ? SIZE_MAX : size_t(need));
          surf.addPolygon(poly.data(), poly.size());
        }
      }
    }
    if (!tets.empty()) return io::loadedFromTets(m_xyz, tets);
    LoadedMesh out;
    out.surface = surf.build(file);
    return out;
  }

  io::Cursor m_cur;
  bool m_binary = false;
  bool m_unstructured = false;
  bool m_havePoints = false;
  std::vector<double> m_xyz;
  std::vector<CellList> m_polygons, m_strips;
  CellList m_cells;
  std::vector<int> m_types;
};

}  // namespace

LoadedMesh io::readVtkData(std::string_view data, const std::string& path) {
  return VtkReader(data, path).read();
}

LoadedMesh readVtk(const std::string& path) {
  return io::readVtkData(io::readWholeFile(path), path);
}

}  // namespace deform
