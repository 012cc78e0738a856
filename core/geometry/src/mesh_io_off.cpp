// Object File Format reader (OFF and its ST/C/N variants; extra per-vertex or per-face values
// such as colours are ignored). One vertex or face per line, '#' starts a comment.
#include <deform/geometry/mesh_io.h>

#include "mesh_io_util.h"

namespace deform {

SurfaceMesh io::readOffData(std::string_view data, const std::string& path) {
  io::Cursor cur(data, path);
  std::vector<std::string_view> tok;
  std::string_view line;
  // Next line with content, comments stripped.
  auto next = [&](const char* what) {
    while (cur.nextLine(line)) {
      const size_t hash = line.find('#');
      if (hash != std::string_view::npos) line = line.substr(0, hash);
      io::splitTokens(line, tok);
      if (!tok.empty()) return;
    }
    cur.setMark(cur.pos());
    cur.fail(std::string("truncated file: expected ") + what);
  };

  next("the OFF header");
  const std::string_view magic = tok[0];
  if (magic.size() < 3 || magic.substr(magic.size() - 3) != "OFF") {
    cur.fail("not an OFF file (first word is '" + std::string(magic.substr(0, 20)) + "')");
  }
  if (magic.find('n') != std::string_view::npos || magic.find('4') != std::string_view::npos) {
    cur.fail("only 3-dimensional OFF is supported, not '" + std::string(magic) + "'");
  }
  if (tok.size() > 1 && tok[1] == "BINARY") cur.fail("binary OFF is not supported");
  if (tok.size() == 1)
    next("vertex and face counts");
  else
    tok.erase(tok.begin());
  long long nv = 0, nf = 0;
  if (tok.size() < 2 || !io::parseInteger(tok[0], nv) || !io::parseInteger(tok[1], nf)) {
    cur.fail("expected vertex, face and edge counts");
  }
  if (nv < 0 || nf < 0 || nv > io::kMaxCount || nf > io::kMaxCount) cur.fail("invalid counts");
  // Every vertex takes at least 6 bytes ("0 0 0\n") and every face 8 ("3 0 1 2\n").
  if (6 * nv + 8 * nf > static_cast<long long>(cur.remaining()) + 1) {
    cur.fail("truncated file: header declares " + std::to_string(nv) + " vertices and " +
             std::to_string(nf) + " faces, more than the " + std::to_string(cur.remaining()) +
             " remaining bytes can hold");
  }

  io::SurfaceBuilder mesh;
  mesh.xyz.reserve(3 * size_t(nv));
  mesh.tri.reserve(3 * size_t(nf));
  for (long long i = 0; i < nv; ++i) {
    next("a vertex");
    if (tok.size() < 3) cur.fail("vertex needs 3 coordinates");
    double p[3];
    for (int k = 0; k < 3; ++k) {
      if (!io::parseReal(tok[k], p[k])) {
        cur.fail("bad vertex coordinate '" + std::string(tok[k].substr(0, 40)) + "'");
      }
    }
    io::requireFinite(cur, p[0], p[1], p[2]);
    mesh.xyz.insert(mesh.xyz.end(), p, p + 3);
  }
  std::vector<int> poly;
  for (long long i = 0; i < nf; ++i) {
    next("a face");
    long long n = 0;
    if (!io::parseInteger(tok[0], n)) cur.fail("bad face corner count");
    if (n < 3) cur.fail("face with " + std::to_string(n) + " corners (at least 3 needed)");
    if (static_cast<long long>(tok.size()) < n + 1)
      cur.fail("face has fewer indices than its count");
    poly.clear();
    for (long long k = 1; k <= n; ++k) {
      long long idx = 0;
      if (!io::parseInteger(tok[k], idx)) {
        cur.fail("bad face index '" + std::string(tok[k].substr(0, 40)) + "'");
      }
      if (idx < 0 || idx >= nv) {
        cur.fail("face index " + std::to_string(idx) + " out of range (" + std::to_string(nv) +
                 " vertices)");
      }
      poly.push_back(static_cast<int>(idx));
    }
    mesh.addPolygon(poly.data(), poly.size());
  }
  return mesh.build(path);
}

SurfaceMesh readOff(const std::string& path) {
  return io::readOffData(io::readWholeFile(path), path);
}

}  // namespace deform
