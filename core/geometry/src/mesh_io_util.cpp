#include "mesh_io_util.h"

#include <algorithm>
#include <bit>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <new>
#include <string>

namespace deform::io {

std::string readWholeFile(const std::string& path) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);  // follows symbolic links
  if (fs::is_directory(st)) throw InputError(path, "", "is a directory");
  // A device (a link to /dev/zero reads forever), a socket: no mesh. Pipes are read (a shell's
  // <(...)), up to the same limit as files.
  if (fs::is_character_file(st) || fs::is_block_file(st) || fs::is_socket(st))
    throw InputError(path, "", "not a regular file (a device or a socket): not a mesh file");
  constexpr size_t kMaxBytes = size_t(1) << 32;
  if (fs::is_regular_file(st) && fs::file_size(path, ec) > kMaxBytes && !ec)
    throw InputError(path, "", "file larger than 4 GiB: too large for a surface mesh");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "", std::string("cannot open file: ") + std::strerror(errno));
  // Read in chunks rather than trusting a seek to the end, so pipes and odd files work too.
  constexpr size_t kChunk = size_t(1) << 20;
  std::string data;
  while (in) {
    const size_t old = data.size();
    if (old >= kMaxBytes) throw InputError(path, "", "more than 4 GiB read: not a mesh file");
    try {
      data.resize(old + kChunk);
    } catch (const std::bad_alloc&) {
      throw InputError(
          path, "",
          "out of memory after reading " + std::to_string(old >> 20) + " MiB of the file");
    }
    in.read(data.data() + old, static_cast<std::streamsize>(kChunk));
    data.resize(old + static_cast<size_t>(in.gcount()));
  }
  if (in.bad()) throw InputError(path, "", "cannot read file");
  return data;
}

std::string lowerExtension(const std::string& path) {
  const size_t slash = path.find_last_of("/\\");
  const size_t dot = path.find_last_of('.');
  if (dot == std::string::npos || (slash != std::string::npos && dot < slash)) return "";
  std::string ext = path.substr(dot);
  std::transform(ext.begin(), ext.end(), ext.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return ext;
}

bool parseReal(std::string_view tok, double& out) {
  if (!tok.empty() && tok.front() == '+') tok.remove_prefix(1);
  if (tok.empty() || tok.front() == '+') return false;
  const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), out);
  // from_chars reports out-of-range (e.g. 1e999) as an error; treat it as garbage too.
  return r.ec == std::errc() && r.ptr == tok.data() + tok.size();
}

bool parseInteger(std::string_view tok, long long& out) {
  if (!tok.empty() && tok.front() == '+') tok.remove_prefix(1);
  if (tok.empty()) return false;
  const auto r = std::from_chars(tok.data(), tok.data() + tok.size(), out);
  return r.ec == std::errc() && r.ptr == tok.data() + tok.size();
}

void splitTokens(std::string_view line, std::vector<std::string_view>& out) {
  out.clear();
  size_t i = 0;
  const size_t n = line.size();
  while (i < n) {
    while (i < n && isBlank(line[i])) ++i;
    const size_t start = i;
    while (i < n && !isBlank(line[i])) ++i;
    if (i > start) out.push_back(line.substr(start, i - start));
  }
}

bool Cursor::nextLine(std::string_view& line) {
  if (m_pos >= m_data.size()) return false;
  m_mark = m_pos;
  size_t end = m_data.find('\n', m_pos);
  if (end == std::string_view::npos) end = m_data.size();
  line = m_data.substr(m_pos, end - m_pos);
  if (!line.empty() && line.back() == '\r') line.remove_suffix(1);
  m_pos = std::min(end + 1, m_data.size());
  return true;
}

void Cursor::skipSpace() {
  while (m_pos < m_data.size() && isSpace(m_data[m_pos])) ++m_pos;
}

std::string_view Cursor::token(const char* what) {
  skipSpace();
  m_mark = m_pos;
  if (m_pos >= m_data.size()) fail(std::string("unexpected end of file, expected ") + what);
  const size_t start = m_pos;
  while (m_pos < m_data.size() && !isSpace(m_data[m_pos])) ++m_pos;
  return m_data.substr(start, m_pos - start);
}

double Cursor::real(const char* what) {
  const std::string_view t = token(what);
  double v = 0;
  if (!parseReal(t, v)) {
    fail(std::string("expected ") + what + ", got '" + std::string(t.substr(0, 40)) + "'");
  }
  return v;
}

long long Cursor::integer(const char* what) {
  const std::string_view t = token(what);
  long long v = 0;
  if (!parseInteger(t, v)) {
    fail(std::string("expected ") + what + ", got '" + std::string(t.substr(0, 40)) + "'");
  }
  return v;
}

const unsigned char* Cursor::take(size_t n, const char* what) {
  m_mark = m_pos;
  if (n > remaining()) {
    failAt(m_pos, std::string("truncated file: ") + what + " needs " + std::to_string(n) +
                      " bytes, only " + std::to_string(remaining()) + " left");
  }
  const auto* p = reinterpret_cast<const unsigned char*>(m_data.data() + m_pos);
  m_pos += n;
  return p;
}

void Cursor::requireFits(long long n, size_t itemBytes, const char* what) {
  if (n < 0 || n > kMaxCount) fail(std::string("invalid ") + what + " count " + std::to_string(n));
  if (static_cast<unsigned long long>(n) * itemBytes > remaining()) {
    fail(std::string("truncated file: ") + std::to_string(n) + " " + what + " need at least " +
         std::to_string(static_cast<unsigned long long>(n) * itemBytes) + " bytes, only " +
         std::to_string(remaining()) + " left");
  }
}

std::string Cursor::lineOf(size_t offset) const {
  offset = std::min(offset, m_data.size());
  const auto lines = std::count(m_data.begin(), m_data.begin() + static_cast<long>(offset), '\n');
  return "line " + std::to_string(lines + 1);
}

std::string Cursor::placeOf(size_t offset) const {
  return m_binary ? "byte " + std::to_string(offset) : lineOf(offset);
}

void Cursor::fail(const std::string& problem) const {
  throw InputError(m_file, place(), problem);
}

void Cursor::failAt(size_t offset, const std::string& problem) const {
  throw InputError(m_file, placeOf(offset), problem);
}

size_t scalarSize(ScalarType t) {
  switch (t) {
    case ScalarType::Int8:
    case ScalarType::UInt8:
      return 1;
    case ScalarType::Int16:
    case ScalarType::UInt16:
      return 2;
    case ScalarType::Int32:
    case ScalarType::UInt32:
    case ScalarType::Float32:
      return 4;
    case ScalarType::Int64:
    case ScalarType::UInt64:
    case ScalarType::Float64:
      return 8;
  }
  return 1;
}

namespace {
template <class T>
T load(const unsigned char* p, bool bigEndian) {
  unsigned char b[sizeof(T)];
  std::memcpy(b, p, sizeof(T));
  const bool hostBig = std::endian::native == std::endian::big;
  if (bigEndian != hostBig) std::reverse(b, b + sizeof(T));
  T v;
  std::memcpy(&v, b, sizeof(T));
  return v;
}
}  // namespace

double decodeScalar(const unsigned char* p, ScalarType t, bool bigEndian) {
  switch (t) {
    case ScalarType::Int8:
      return load<int8_t>(p, bigEndian);
    case ScalarType::UInt8:
      return load<uint8_t>(p, bigEndian);
    case ScalarType::Int16:
      return load<int16_t>(p, bigEndian);
    case ScalarType::UInt16:
      return load<uint16_t>(p, bigEndian);
    case ScalarType::Int32:
      return load<int32_t>(p, bigEndian);
    case ScalarType::UInt32:
      return load<uint32_t>(p, bigEndian);
    case ScalarType::Int64:
      return static_cast<double>(load<int64_t>(p, bigEndian));
    case ScalarType::UInt64:
      return static_cast<double>(load<uint64_t>(p, bigEndian));
    case ScalarType::Float32:
      return load<float>(p, bigEndian);
    case ScalarType::Float64:
      return load<double>(p, bigEndian);
  }
  return 0;
}

SurfaceMesh SurfaceBuilder::build(const std::string& file) const {
  if (tri.empty()) throw InputError(file, "", "no triangles (empty mesh)");
  SurfaceMesh m;
  m.V = Eigen::Map<const MatX3>(xyz.data(), static_cast<Eigen::Index>(xyz.size() / 3), 3);
  m.F = Eigen::Map<const MatX3i>(tri.data(), static_cast<Eigen::Index>(tri.size() / 3), 3);
  return m;
}

LoadedMesh loadedFromTets(const std::vector<double>& xyz, const std::vector<int>& tets) {
  LoadedMesh out;
  TetMesh vol;
  vol.V = Eigen::Map<const MatX3>(xyz.data(), static_cast<Eigen::Index>(xyz.size() / 3), 3);
  vol.T = Eigen::Map<const MatX4i>(tets.data(), static_cast<Eigen::Index>(tets.size() / 4), 4);
  for (Eigen::Index t = 0; t < vol.T.rows(); ++t) {
    const Real v = tetVolume(vol.V.row(vol.T(t, 0)), vol.V.row(vol.T(t, 1)), vol.V.row(vol.T(t, 2)),
                             vol.V.row(vol.T(t, 3)));
    if (v < 0) {
      std::swap(vol.T(t, 1), vol.T(t, 2));
      ++out.reorientedTets;
    } else if (v == 0) {
      ++out.degenerateTets;
    }
  }
  out.surface = tetBoundary(vol);
  out.volume = std::move(vol);
  return out;
}

void requireFinite(const Cursor& c, double x, double y, double z) {
  if (!std::isfinite(x) || !std::isfinite(y) || !std::isfinite(z)) {
    c.fail("non-finite coordinate (NaN or Inf)");
  }
}

void parseVertex(const Cursor& c, const std::vector<std::string_view>& tok, double p[3]) {
  if (tok.size() < 4) c.fail("vertex needs 3 coordinates");
  for (int k = 0; k < 3; ++k) {
    if (!parseReal(tok[1 + k], p[k])) {
      c.fail("bad vertex coordinate '" + std::string(tok[1 + k].substr(0, 40)) + "'");
    }
  }
  requireFinite(c, p[0], p[1], p[2]);
}

}  // namespace deform::io
