// Gmsh reader: format 2.2 ASCII ($MeshFormat/$Nodes/$Elements) and legacy 1.0 ($NOD/$ELM).
// Elements used: tetrahedra (type 4; type 11, the 10-node tet, by its 4 corners) and triangles
// (type 2; type 9 by its 3 corners); other element types and sections are skipped. Node tags may
// be arbitrary positive numbers; nodes are numbered 0.. in file order.
#include <deform/geometry/mesh_io.h>

#include <unordered_map>

#include "mesh_io_util.h"

namespace deform {
namespace {

/// Corners used of a Gmsh element type (0 for types we skip).
int cornerCount(long long type) {
  switch (type) {
    case 4:
    case 11:
      return 4;
    case 2:
    case 9:
      return 3;
    default:
      return 0;
  }
}

class MshReader {
 public:
  MshReader(std::string_view data, const std::string& path) : m_cur(data, path) {}

  LoadedMesh read() {
    bool sawFormat = false;
    while (nextLine(false)) {
      const std::string_view sec = m_tok[0];
      if (sec == "$MeshFormat") {
        readFormat();
        sawFormat = true;
      } else if (sec == "$Nodes" || sec == "$NOD") {
        if (sec == "$Nodes" && !sawFormat) m_cur.fail("$Nodes before $MeshFormat");
        readNodes(sec == "$NOD" ? "$ENDNOD" : "$EndNodes");
      } else if (sec == "$Elements" || sec == "$ELM") {
        if (!m_haveNodes) m_cur.fail("elements before nodes");
        readElements(sec == "$ELM", sec == "$ELM" ? "$ENDELM" : "$EndElements");
      } else if (sec.size() > 1 && sec[0] == '$') {
        skipSection(sec);
      } else {
        m_cur.fail("expected a $Section, got '" + std::string(sec.substr(0, 40)) + "'");
      }
    }
    const std::string& file = m_cur.file();
    if (!m_haveNodes) throw InputError(file, "", "no nodes");
    if (!m_tets.empty()) return io::loadedFromTets(m_xyz, m_tets);
    io::SurfaceBuilder surf;
    surf.xyz = m_xyz;
    surf.tri = m_tris;
    if (surf.tri.empty()) throw InputError(file, "", "no tetrahedra or triangles (empty mesh)");
    LoadedMesh out;
    out.surface = surf.build(file);
    return out;
  }

 private:
  /// Next non-blank line split into m_tok; false (or a throw when required) at end of file.
  bool nextLine(bool required, const char* what = "") {
    std::string_view line;
    while (m_cur.nextLine(line)) {
      io::splitTokens(line, m_tok);
      if (!m_tok.empty()) return true;
    }
    if (required) {
      m_cur.setMark(m_cur.pos());
      m_cur.fail(std::string("truncated file: expected ") + what);
    }
    return false;
  }

  void expectEnd(const char* end) {
    nextLine(true, end);
    if (m_tok[0] != end) {
      m_cur.fail(std::string("expected ") + end + ", got '" + std::string(m_tok[0].substr(0, 40)) +
                 "'");
    }
  }

  void readFormat() {
    nextLine(true, "the format version");
    double version = 0;
    long long fileType = -1;
    if (m_tok.size() < 2 || !io::parseReal(m_tok[0], version) ||
        !io::parseInteger(m_tok[1], fileType)) {
      m_cur.fail("bad $MeshFormat line");
    }
    if (version < 2 || version >= 3) {
      m_cur.fail("Gmsh format " + std::string(m_tok[0].substr(0, 10)) +
                 " is not supported, re-save as 2.2");
    }
    if (fileType != 0) m_cur.fail("binary Gmsh files are not supported, re-save as ASCII 2.2");
    expectEnd("$EndMeshFormat");
  }

  long long countLine(const char* what) {
    nextLine(true, what);
    long long n = 0;
    if (!io::parseInteger(m_tok[0], n) || n < 0 || n > io::kMaxCount) {
      m_cur.fail(std::string("bad ") + what);
    }
    // Each node or element line takes at least 8 bytes ("1 0 0 0\n", "1 15 0 1\n").
    m_cur.requireFits(n, 8, what);
    return n;
  }

  void readNodes(const char* end) {
    if (m_haveNodes) m_cur.fail("second node section");
    const long long n = countLine("node count");
    m_xyz.reserve(3 * size_t(n));
    m_index.reserve(size_t(n));
    for (long long i = 0; i < n; ++i) {
      nextLine(true, "a node");
      long long tag = 0;
      double p[3];
      if (m_tok.size() < 4 || !io::parseInteger(m_tok[0], tag)) m_cur.fail("bad node line");
      for (int k = 0; k < 3; ++k) {
        if (!io::parseReal(m_tok[1 + k], p[k])) {
          m_cur.fail("bad node coordinate '" + std::string(m_tok[1 + k].substr(0, 40)) + "'");
        }
      }
      io::requireFinite(m_cur, p[0], p[1], p[2]);
      if (!m_index.try_emplace(tag, static_cast<int>(i)).second) {
        m_cur.fail("duplicate node tag " + std::to_string(tag));
      }
      m_xyz.insert(m_xyz.end(), p, p + 3);
    }
    expectEnd(end);
    m_haveNodes = true;
  }

  void readElements(bool legacy, const char* end) {
    const long long n = countLine("element count");
    for (long long i = 0; i < n; ++i) {
      nextLine(true, "an element");
      long long type = 0, skip = 0;
      // 2.2: tag type ntags tags... nodes...   1.0: tag type physical elementary nnodes nodes...
      if (m_tok.size() < 3 || !io::parseInteger(m_tok[1], type)) m_cur.fail("bad element line");
      const int corners = cornerCount(type);
      if (corners == 0) continue;
      if (legacy) {
        long long nn = 0;
        if (m_tok.size() < 5 || !io::parseInteger(m_tok[4], nn)) m_cur.fail("bad element line");
        if (nn < corners) m_cur.fail("element with too few nodes");
        skip = 5;
      } else {
        long long ntags = 0;
        if (!io::parseInteger(m_tok[2], ntags) || ntags < 0 || ntags > 1000) {
          m_cur.fail("bad element tag count");
        }
        skip = 3 + ntags;
      }
      if (static_cast<long long>(m_tok.size()) < skip + corners) {
        m_cur.fail("element of type " + std::to_string(type) + " has too few nodes");
      }
      std::vector<int>& out = corners == 4 ? m_tets : m_tris;
      for (int k = 0; k < corners; ++k) {
        long long tag = 0;
        const std::string_view t = m_tok[size_t(skip + k)];
        if (!io::parseInteger(t, tag)) {
          m_cur.fail("bad node tag '" + std::string(t.substr(0, 40)) + "'");
        }
        const auto it = m_index.find(tag);
        if (it == m_index.end()) m_cur.fail("element names unknown node " + std::to_string(tag));
        out.push_back(it->second);
      }
    }
    expectEnd(end);
  }

  void skipSection(std::string_view sec) {
    const std::string end = "$End" + std::string(sec.substr(1));
    const size_t start = m_cur.mark();
    std::string_view line;
    while (m_cur.nextLine(line)) {
      io::splitTokens(line, m_tok);
      if (!m_tok.empty() && m_tok[0] == end) return;
    }
    m_cur.failAt(start, "truncated file: section " + std::string(sec.substr(0, 40)) + " has no " +
                            end.substr(0, 40));
  }

  io::Cursor m_cur;
  std::vector<std::string_view> m_tok;
  bool m_haveNodes = false;
  std::vector<double> m_xyz;
  std::unordered_map<long long, int> m_index;  // node tag -> 0-based index
  std::vector<int> m_tets, m_tris;
};

}  // namespace

LoadedMesh io::readMshData(std::string_view data, const std::string& path) {
  return MshReader(data, path).read();
}

LoadedMesh readMsh(const std::string& path) {
  return io::readMshData(io::readWholeFile(path), path);
}

}  // namespace deform
