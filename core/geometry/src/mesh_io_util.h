// Internal helpers shared by the mesh readers (not part of the SDK): a bounds-checked cursor over
// a whole file held in memory that reads text lines, whitespace-separated tokens and big- or
// little-endian binary values, and reports failures as InputError with "line N" or "byte N".
#pragma once

#include <deform/geometry/mesh_io.h>
#include <deform/sdk/error.h>
#include <deform/sdk/mesh.h>

#include <cstdint>
#include <cstring>
#include <string>
#include <string_view>
#include <vector>

namespace deform::io {

/// Largest element count any reader accepts before looking at the file size (indices are int).
inline constexpr long long kMaxCount = 1LL << 30;

/// The whole file; throws InputError(path, "", ...) when it cannot be opened or read.
std::string readWholeFile(const std::string& path);

/// Lower-case extension with the dot (".obj"), empty if none.
std::string lowerExtension(const std::string& path);

/// Parses the whole token as a finite-or-not double ("+1.5" accepted). False on any garbage.
bool parseReal(std::string_view tok, double& out);
/// Parses the whole token as a signed integer. False on garbage or overflow.
bool parseInteger(std::string_view tok, long long& out);

/// Splits at blanks (space, tab, \r, \v, \f); empty tokens are never produced.
void splitTokens(std::string_view line, std::vector<std::string_view>& out);

inline bool isBlank(char c) {
  return c == ' ' || c == '\t' || c == '\r' || c == '\v' || c == '\f';
}
inline bool isSpace(char c) {
  return isBlank(c) || c == '\n';
}

/// A read position in a file held in memory. Every read is bounds-checked; errors name the
/// place of the item read last, as "line N" (text mode) or "byte N" (binary mode).
class Cursor {
 public:
  Cursor(std::string_view data, std::string file) : m_data(data), m_file(std::move(file)) {}

  const std::string& file() const { return m_file; }
  size_t pos() const { return m_pos; }
  size_t size() const { return m_data.size(); }
  size_t remaining() const { return m_data.size() - m_pos; }
  bool atEnd() const { return m_pos >= m_data.size(); }
  std::string_view data() const { return m_data; }
  void setBinary(bool binary) { m_binary = binary; }

  /// Next line without its terminator ("\n" or "\r\n"); false at end of file.
  bool nextLine(std::string_view& line);
  /// Skips blanks and newlines.
  void skipSpace();
  /// Next whitespace-separated token; throws "unexpected end of file" if there is none.
  std::string_view token(const char* what);
  /// Next token parsed as a number / integer; throws naming `what` on garbage.
  double real(const char* what);
  long long integer(const char* what);

  /// n raw bytes; throws "truncated" when fewer remain.
  const unsigned char* take(size_t n, const char* what);
  /// Throws unless n items of itemBytes each can still fit in the rest of the file.
  void requireFits(long long n, size_t itemBytes, const char* what);

  /// "line N" or "byte N" of an offset (line numbers are counted on demand).
  std::string placeOf(size_t offset) const;
  std::string lineOf(size_t offset) const;
  /// The place of the item read last.
  std::string place() const { return placeOf(m_mark); }
  size_t mark() const { return m_mark; }
  void setMark(size_t offset) { m_mark = offset; }

  [[noreturn]] void fail(const std::string& problem) const;
  [[noreturn]] void failAt(size_t offset, const std::string& problem) const;

 private:
  std::string_view m_data;
  std::string m_file;
  size_t m_pos = 0;
  size_t m_mark = 0;
  bool m_binary = false;
};

/// Scalar types of binary formats (PLY, VTK).
enum class ScalarType {
  Int8,
  UInt8,
  Int16,
  UInt16,
  Int32,
  UInt32,
  Int64,
  UInt64,
  Float32,
  Float64
};
size_t scalarSize(ScalarType t);
/// Decodes one value of type t at p (size scalarSize(t)), byte-swapping when bigEndian.
double decodeScalar(const unsigned char* p, ScalarType t, bool bigEndian);

/// Collects vertices and triangles while reading; polygons are fan-triangulated.
struct SurfaceBuilder {
  std::vector<double> xyz;  ///< 3 per vertex
  std::vector<int> tri;     ///< 3 per triangle
  long long numVertices() const { return static_cast<long long>(xyz.size() / 3); }
  long long numTriangles() const { return static_cast<long long>(tri.size() / 3); }
  void addPolygon(const int* idx, size_t n) {
    for (size_t k = 1; k + 1 < n; ++k) {
      tri.push_back(idx[0]);
      tri.push_back(idx[k]);
      tri.push_back(idx[k + 1]);
    }
  }
  /// Throws InputError(file, "", "no triangles") when empty.
  SurfaceMesh build(const std::string& file) const;
};

/// A LoadedMesh from all nodes (3 per node, finite) and tets (4 per tet, indices already checked):
/// negative tets get nodes 1 and 2 swapped and are counted, surface = tetBoundary(volume).
LoadedMesh loadedFromTets(const std::vector<double>& xyz, const std::vector<int>& tets);

/// The readers on a file's contents already in memory; `file` names it in errors.
SurfaceMesh readObjData(std::string_view data, const std::string& file);
SurfaceMesh readStlData(std::string_view data, const std::string& file);
SurfaceMesh readOffData(std::string_view data, const std::string& file);
SurfaceMesh readPlyData(std::string_view data, const std::string& file);
LoadedMesh readVtkData(std::string_view data, const std::string& file);
LoadedMesh readMshData(std::string_view data, const std::string& file);

/// Throws at the cursor's last place when x is NaN or Inf.
void requireFinite(const Cursor& c, double x, double y, double z);

/// The text formats' vertex line: tok[1..3] as a finite point p; throws at the cursor's last
/// place naming what is wrong (too few coordinates, a bad or non-finite one).
void parseVertex(const Cursor& c, const std::vector<std::string_view>& tok, double p[3]);

}  // namespace deform::io
