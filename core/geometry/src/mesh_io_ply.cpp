// PLY reader: ascii, binary_little_endian and binary_big_endian. Uses the `vertex` element's x, y,
// z and the `face` element's vertex_indices (or vertex_index) list; every other element and
// property is read past according to its declared type.
#include <deform/geometry/mesh_io.h>

#include <cmath>
#include <optional>

#include "mesh_io_util.h"

namespace deform {
namespace {

struct PlyProperty {
  std::string name;
  bool isList = false;
  io::ScalarType countType = io::ScalarType::UInt8;
  io::ScalarType type = io::ScalarType::Float32;
};

struct PlyElement {
  std::string name;
  long long count = 0;
  std::vector<PlyProperty> props;
};

std::optional<io::ScalarType> plyType(std::string_view s) {
  using io::ScalarType;
  if (s == "char" || s == "int8") return ScalarType::Int8;
  if (s == "uchar" || s == "uint8") return ScalarType::UInt8;
  if (s == "short" || s == "int16") return ScalarType::Int16;
  if (s == "ushort" || s == "uint16") return ScalarType::UInt16;
  if (s == "int" || s == "int32") return ScalarType::Int32;
  if (s == "uint" || s == "uint32") return ScalarType::UInt32;
  if (s == "float" || s == "float32") return ScalarType::Float32;
  if (s == "double" || s == "float64") return ScalarType::Float64;
  return std::nullopt;
}

bool isIntegerType(io::ScalarType t) {
  return t != io::ScalarType::Float32 && t != io::ScalarType::Float64;
}

enum class PlyFormat { Ascii, BinaryLittle, BinaryBig };

struct PlyHeader {
  std::optional<PlyFormat> format;  ///< set (a header without one is refused)
  std::vector<PlyElement> elements;
};

// The header from "ply" to end_header; cur is then at the first element's data.
PlyHeader readPlyHeader(io::Cursor& cur) {
  std::vector<std::string_view> tok;
  std::string_view line;
  PlyHeader header;
  std::optional<PlyFormat>& format = header.format;
  std::vector<PlyElement>& elements = header.elements;
  if (!cur.nextLine(line) || line != "ply") cur.fail("not a PLY file (first line is not 'ply')");
  bool ended = false;
  while (!ended && cur.nextLine(line)) {
    io::splitTokens(line, tok);
    if (tok.empty()) continue;
    if (tok[0] == "format") {
      if (tok.size() < 2) cur.fail("incomplete format line");
      if (tok[1] == "ascii")
        format = PlyFormat::Ascii;
      else if (tok[1] == "binary_little_endian")
        format = PlyFormat::BinaryLittle;
      else if (tok[1] == "binary_big_endian")
        format = PlyFormat::BinaryBig;
      else
        cur.fail("unknown PLY format '" + std::string(tok[1].substr(0, 40)) + "'");
    } else if (tok[0] == "comment" || tok[0] == "obj_info") {
      continue;
    } else if (tok[0] == "element") {
      long long n = 0;
      if (tok.size() < 3 || !io::parseInteger(tok[2], n) || n < 0 || n > io::kMaxCount) {
        cur.fail("bad element line");
      }
      // The reader looks up x, y, z and the index list by element name, so these must be unique.
      if (tok[1] == "vertex" || tok[1] == "face") {
        for (const PlyElement& e : elements) {
          if (e.name == tok[1]) cur.fail("second '" + e.name + "' element");
        }
      }
      elements.push_back({std::string(tok[1]), n, {}});
    } else if (tok[0] == "property") {
      if (elements.empty()) cur.fail("property before any element");
      PlyProperty p;
      if (tok.size() >= 5 && tok[1] == "list") {
        const auto ct = plyType(tok[2]), it = plyType(tok[3]);
        if (!ct || !it || !isIntegerType(*ct)) cur.fail("bad list property types");
        p.isList = true;
        p.countType = *ct;
        p.type = *it;
        p.name = std::string(tok[4]);
      } else if (tok.size() >= 3 && tok[1] != "list") {
        const auto t = plyType(tok[1]);
        if (!t) cur.fail("unknown property type '" + std::string(tok[1].substr(0, 40)) + "'");
        p.type = *t;
        p.name = std::string(tok[2]);
      } else {
        cur.fail("bad property line");
      }
      elements.back().props.push_back(p);
    } else if (tok[0] == "end_header") {
      ended = true;
    } else {
      cur.fail("unknown PLY header keyword '" + std::string(tok[0].substr(0, 40)) + "'");
    }
  }
  if (!ended) cur.fail("truncated file: no end_header");
  if (!format) cur.fail("PLY header has no format line");

  return header;
}

}  // namespace

SurfaceMesh io::readPlyData(std::string_view data, const std::string& path) {
  io::Cursor cur(data, path);
  const PlyHeader header = readPlyHeader(cur);
  const std::optional<PlyFormat>& format = header.format;
  const std::vector<PlyElement>& elements = header.elements;

  const PlyElement* vertexEl = nullptr;
  const PlyElement* faceEl = nullptr;
  int ix = -1, iy = -1, iz = -1, iface = -1;
  for (const PlyElement& e : elements) {
    if (e.name == "vertex") {
      vertexEl = &e;
      for (size_t k = 0; k < e.props.size(); ++k) {
        if (e.props[k].isList) continue;
        if (e.props[k].name == "x") ix = int(k);
        if (e.props[k].name == "y") iy = int(k);
        if (e.props[k].name == "z") iz = int(k);
      }
    } else if (e.name == "face") {
      faceEl = &e;
      for (size_t k = 0; k < e.props.size(); ++k) {
        const auto& p = e.props[k];
        if (!p.isList) continue;
        if (p.name == "vertex_indices" || p.name == "vertex_index")
          iface = int(k);
        else if (iface < 0)
          iface = int(k);
      }
    }
  }
  if (!vertexEl || ix < 0 || iy < 0 || iz < 0) {
    throw InputError(path, "", "PLY header has no vertex element with x, y, z");
  }
  if (!faceEl || iface < 0) {
    throw InputError(path, "", "PLY header has no face element with a vertex index list");
  }
  if (!isIntegerType(faceEl->props[size_t(iface)].type)) {
    throw InputError(path, "", "PLY face indices must have an integer type");
  }

  const bool binary = *format != PlyFormat::Ascii;
  const bool bigEndian = *format == PlyFormat::BinaryBig;
  cur.setBinary(binary);
  const long long nv = vertexEl->count;
  io::SurfaceBuilder mesh;
  std::vector<int> poly;

  // One scalar value of type t, from either encoding.
  auto value = [&](io::ScalarType t, const char* what) -> double {
    if (binary) return io::decodeScalar(cur.take(io::scalarSize(t), what), t, bigEndian);
    const double v = cur.real(what);
    if (isIntegerType(t) && std::trunc(v) != v) cur.fail(std::string("non-integer ") + what);
    return v;
  };

  for (const PlyElement& e : elements) {
    if (e.props.empty() || e.count == 0) continue;
    size_t minBytes = 0;  // smallest possible encoding of one instance
    for (const auto& p : e.props) {
      minBytes += binary ? io::scalarSize(p.isList ? p.countType : p.type) : 2;
    }
    cur.requireFits(e.count, minBytes, (e.name + " elements").c_str());
    const bool isVertex = &e == vertexEl, isFace = &e == faceEl;
    if (isVertex) mesh.xyz.reserve(3 * size_t(e.count));
    if (isFace) mesh.tri.reserve(3 * size_t(e.count));
    for (long long i = 0; i < e.count; ++i) {
      double p[3] = {0, 0, 0};
      for (size_t k = 0; k < e.props.size(); ++k) {
        const PlyProperty& prop = e.props[k];
        if (!prop.isList) {
          const double v = value(prop.type, "a property value");
          if (isVertex) {
            if (int(k) == ix) p[0] = v;
            if (int(k) == iy) p[1] = v;
            if (int(k) == iz) p[2] = v;
          }
          continue;
        }
        const size_t countAt = cur.pos();
        const double n = value(prop.countType, "a list length");
        if (n < 0) cur.fail("negative list length");
        // ASCII accepts "inf" or 1e30 as an integer; only a count in range may be cast.
        if (!(n <= double(io::kMaxCount))) cur.fail("invalid list length");
        const auto count = static_cast<long long>(n);
        cur.requireFits(count, binary ? io::scalarSize(prop.type) : 2, "list entries");
        const bool indices = isFace && int(k) == iface;
        if (indices) {
          if (count < 3) {
            cur.failAt(countAt, "face with " + std::to_string(count) + " corners (at least 3)");
          }
          poly.clear();
        }
        if (binary && !indices) {
          cur.take(size_t(count) * io::scalarSize(prop.type), "list entries");
          continue;
        }
        for (long long j = 0; j < count; ++j) {
          const double v = value(prop.type, "a list entry");
          if (!indices) continue;
          if (v < 0 || v >= double(nv)) {
            const std::string shown =
                std::fabs(v) < 1e18 ? std::to_string(static_cast<long long>(v)) : std::to_string(v);
            cur.fail("face index " + shown + " out of range (" + std::to_string(nv) + " vertices)");
          }
          poly.push_back(static_cast<int>(v));
        }
        if (indices) mesh.addPolygon(poly.data(), poly.size());
      }
      if (isVertex) {
        io::requireFinite(cur, p[0], p[1], p[2]);
        mesh.xyz.insert(mesh.xyz.end(), p, p + 3);
      }
    }
  }
  return mesh.build(path);
}

SurfaceMesh readPly(const std::string& path) {
  return io::readPlyData(io::readWholeFile(path), path);
}

}  // namespace deform
