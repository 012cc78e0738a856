// STL reader (ASCII and binary). Corners are merged into shared vertices by exact coordinate, in
// first-seen order; stored facet normals are ignored (orientation comes from the winding).
#include <deform/geometry/mesh_io.h>

#include <array>
#include <cmath>
#include <unordered_map>

#include "mesh_io_util.h"

namespace deform {
namespace {

struct CornerHash {
  size_t operator()(const std::array<double, 3>& p) const {
    size_t h = 1469598103934665603ull;
    for (double x : p) {
      uint64_t b;
      std::memcpy(&b, &x, sizeof b);
      h = (h ^ (b + 0x9e3779b97f4a7c15ull + (h << 6) + (h >> 2))) * 1099511628211ull;
    }
    return h;
  }
};

/// Maps corners to vertex indices by exact coordinate.
class CornerMerger {
 public:
  CornerMerger(io::SurfaceBuilder& mesh, size_t expectedCorners) : m_mesh(mesh) {
    m_index.reserve(expectedCorners / 4 + 16);
  }
  int add(double x, double y, double z) {
    // +0.0 turns -0.0 into 0.0 so the two compare (and hash) equal, as they are the same point.
    const std::array<double, 3> key = {x + 0.0, y + 0.0, z + 0.0};
    const auto [it, inserted] = m_index.try_emplace(key, static_cast<int>(m_mesh.numVertices()));
    if (inserted) m_mesh.xyz.insert(m_mesh.xyz.end(), key.begin(), key.end());
    return it->second;
  }

 private:
  io::SurfaceBuilder& m_mesh;
  std::unordered_map<std::array<double, 3>, int, CornerHash> m_index;
};

SurfaceMesh readBinaryStl(io::Cursor& cur, uint32_t n) {
  io::SurfaceBuilder mesh;
  mesh.tri.reserve(3 * size_t(n));
  CornerMerger merge(mesh, 3 * size_t(n));
  cur.take(84, "header");
  for (uint32_t t = 0; t < n; ++t) {
    const unsigned char* rec = cur.take(50, "triangle");
    int idx[3];
    for (int k = 0; k < 3; ++k) {
      double p[3];
      for (int d = 0; d < 3; ++d) {
        p[d] = io::decodeScalar(rec + 12 + 12 * k + 4 * d, io::ScalarType::Float32, false);
      }
      io::requireFinite(cur, p[0], p[1], p[2]);
      idx[k] = merge.add(p[0], p[1], p[2]);
    }
    mesh.addPolygon(idx, 3);
  }
  return mesh.build(cur.file());
}

SurfaceMesh readAsciiStl(io::Cursor& cur) {
  io::SurfaceBuilder mesh;
  CornerMerger merge(mesh, cur.size() / 40);
  std::vector<std::string_view> tok;
  std::vector<int> loop;
  bool inLoop = false, inFacet = false, inSolid = false;
  std::string_view line;
  while (cur.nextLine(line)) {
    io::splitTokens(line, tok);
    if (tok.empty()) continue;
    const std::string_view kw = tok[0];
    if (kw == "solid") {
      if (inSolid) cur.fail("'solid' inside a solid");
      inSolid = true;
    } else if (kw == "endsolid") {
      if (!inSolid || inFacet) cur.fail("unexpected 'endsolid'");
      inSolid = false;
    } else if (kw == "facet") {
      if (!inSolid || inFacet) cur.fail("unexpected 'facet'");
      inFacet = true;
    } else if (kw == "outer") {
      if (!inFacet || inLoop) cur.fail("unexpected 'outer loop'");
      inLoop = true;
      loop.clear();
    } else if (kw == "vertex") {
      if (!inLoop) cur.fail("'vertex' outside 'outer loop'");
      double p[3];
      io::parseVertex(cur, tok, p);
      loop.push_back(merge.add(p[0], p[1], p[2]));
    } else if (kw == "endloop") {
      if (!inLoop) cur.fail("unexpected 'endloop'");
      if (loop.size() < 3) cur.fail("facet with fewer than 3 vertices");
      mesh.addPolygon(loop.data(), loop.size());
      inLoop = false;
    } else if (kw == "endfacet") {
      if (!inFacet || inLoop) cur.fail("unexpected 'endfacet'");
      inFacet = false;
    } else {
      cur.fail("unknown ASCII STL keyword '" + std::string(kw.substr(0, 40)) + "'");
    }
  }
  if (inFacet || inLoop) cur.fail("truncated file: end of file inside a facet");
  if (mesh.numVertices() > io::kMaxCount) cur.fail("too many vertices");
  return mesh.build(cur.file());
}

}  // namespace

SurfaceMesh io::readStlData(std::string_view data, const std::string& path) {
  io::Cursor cur(data, path);
  // Binary if the size matches 84 + 50 n exactly; the header is free text (OpenHELP files start
  // with "COLOR="), so its first word proves nothing.
  if (data.size() >= 84) {
    const auto n = static_cast<uint32_t>(io::decodeScalar(
        reinterpret_cast<const unsigned char*>(data.data()) + 80, io::ScalarType::UInt32, false));
    if (84 + 50 * static_cast<unsigned long long>(n) == data.size()) {
      cur.setBinary(true);
      return readBinaryStl(cur, n);
    }
  }
  size_t first = 0;
  while (first < data.size() && io::isSpace(data[first])) ++first;
  // A truncated binary file may also start with "solid": call it ASCII only if it has ASCII
  // keywords beyond the header.
  if (data.compare(first, 5, "solid") == 0 && (data.find("facet", first) != std::string::npos ||
                                               data.find("endsolid", first) != std::string::npos)) {
    return readAsciiStl(cur);
  }
  cur.setBinary(true);
  if (data.size() < 84) {
    cur.failAt(0, "truncated file: " + std::to_string(data.size()) +
                      " bytes is too short for a binary STL (84-byte header) and it is not ASCII");
  }
  const auto n = static_cast<uint32_t>(io::decodeScalar(
      reinterpret_cast<const unsigned char*>(data.data()) + 80, io::ScalarType::UInt32, false));
  cur.failAt(
      80, "binary STL declares " + std::to_string(n) + " triangles, which needs " +
              std::to_string(84 + 50 * static_cast<unsigned long long>(n)) +
              " bytes, but the file has " + std::to_string(data.size()) +
              (84 + 50 * static_cast<unsigned long long>(n) > data.size() ? " (truncated)" : ""));
}

SurfaceMesh readStl(const std::string& path) {
  return io::readStlData(io::readWholeFile(path), path);
}

}  // namespace deform
