// Wavefront OBJ reader: `v` and `f` lines only; every other statement (vn, vt, mtllib, usemtl,
// g, o, s, l, p, ...) is ignored.
#include <deform/geometry/mesh_io.h>

#include <cmath>

#include "mesh_io_util.h"

namespace deform {

SurfaceMesh io::readObjData(std::string_view data, const std::string& path) {
  io::Cursor cur(data, path);
  io::SurfaceBuilder mesh;
  std::vector<size_t> faceLine;  // byte offset of each triangle's line, for late range errors
  std::vector<std::string_view> tok;
  std::vector<int> poly;
  std::string_view line;
  while (cur.nextLine(line)) {
    io::splitTokens(line, tok);
    if (tok.empty() || tok[0].front() == '#') continue;
    if (tok[0] == "v") {
      double p[3];
      io::parseVertex(cur, tok, p);
      mesh.xyz.insert(mesh.xyz.end(), p, p + 3);
      if (mesh.numVertices() > io::kMaxCount) cur.fail("too many vertices");
    } else if (tok[0] == "f") {
      if (tok.size() < 4) cur.fail("face needs at least 3 corners");
      poly.clear();
      for (size_t k = 1; k < tok.size(); ++k) {
        // Corner forms: v, v/vt, v//vn, v/vt/vn; only v matters.
        const std::string_view corner = tok[k].substr(0, tok[k].find('/'));
        long long idx = 0;
        if (!io::parseInteger(corner, idx)) {
          cur.fail("bad face index '" + std::string(tok[k].substr(0, 40)) + "'");
        }
        if (idx == 0) cur.fail("face index 0 (OBJ indices start at 1)");
        // Negative indices count back from the last vertex defined so far.
        const long long resolved = idx > 0 ? idx - 1 : mesh.numVertices() + idx;
        if (resolved < 0 || resolved > io::kMaxCount) {
          cur.fail("face index " + std::to_string(idx) + " out of range (" +
                   std::to_string(mesh.numVertices()) + " vertices so far)");
        }
        poly.push_back(static_cast<int>(resolved));
      }
      mesh.addPolygon(poly.data(), poly.size());
      faceLine.resize(static_cast<size_t>(mesh.numTriangles()), cur.mark());
    }
  }
  // Positive indices may in principle refer to vertices defined further down, so check at the end.
  const long long nv = mesh.numVertices();
  for (size_t i = 0; i < mesh.tri.size(); ++i) {
    if (mesh.tri[i] >= nv) {
      cur.failAt(faceLine[i / 3], "face index " + std::to_string(mesh.tri[i] + 1) +
                                      " out of range (" + std::to_string(nv) + " vertices)");
    }
  }
  return mesh.build(path);
}

SurfaceMesh readObj(const std::string& path) {
  return io::readObjData(io::readWholeFile(path), path);
}

}  // namespace deform
