// deformbench SDK: the on-disk precomputation cache. Entries are keyed by a SHA-256 of every
// input that affects the result, carry a checksum of their payload, and are written atomically
// (temporary file in the same folder + rename), so a killed run or two concurrent runs never
// leave a corrupt entry; a corrupt entry found anyway is deleted and reported as a miss.
#pragma once

#include <deform/sdk/types.h>

#include <cstring>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace deform {

/// Incremental SHA-256 over typed values (each value is prefixed by its type and size, so
/// ("ab","c") and ("a","bc") differ).
class CacheKey {
 public:
  CacheKey();
  ~CacheKey();
  CacheKey(const CacheKey&);
  CacheKey& operator=(const CacheKey&);

  CacheKey& add(std::string_view s);
  CacheKey& add(const char* s) { return add(std::string_view(s)); }
  CacheKey& add(double v);
  CacheKey& add(long long v);
  CacheKey& add(int v) { return add(static_cast<long long>(v)); }
  CacheKey& add(const MatX3& m);
  CacheKey& add(const MatX3i& m);
  CacheKey& add(const MatX4i& m);
  CacheKey& add(const VecX& v);

  /// Hex digest of everything added so far (does not consume the key).
  std::string hex() const;

 private:
  void raw(const void* data, size_t n);
  void addReals(const double* data, size_t n);
  struct State;
  State* m_state;
};

/// SHA-256 of a byte buffer, hex.
std::string sha256Hex(const void* data, size_t n);
/// SHA-256 of a file's contents, hex; throws InputError if unreadable.
std::string sha256File(const std::string& path);

/// Little binary serialisation for cache payloads.
class ByteWriter {
 public:
  template <class T>
  void pod(const T& v) {
    const char* p = reinterpret_cast<const char*>(&v);
    m_bytes.insert(m_bytes.end(), p, p + sizeof(T));
  }
  template <class Derived>
  void matrix(const Eigen::PlainObjectBase<Derived>& m) {
    pod<long long>(m.rows());
    pod<long long>(m.cols());
    const char* p = reinterpret_cast<const char*>(m.data());
    m_bytes.insert(m_bytes.end(), p, p + sizeof(typename Derived::Scalar) * m.size());
  }
  void string(const std::string& s) {
    pod<long long>(static_cast<long long>(s.size()));
    m_bytes.insert(m_bytes.end(), s.begin(), s.end());
  }
  std::vector<char>& bytes() { return m_bytes; }

 private:
  std::vector<char> m_bytes;
};

/// Reads what ByteWriter wrote; throws std::runtime_error on a short or inconsistent buffer
/// (the cache treats that as a corrupt entry).
class ByteReader {
 public:
  explicit ByteReader(const std::vector<char>& bytes) : m_bytes(bytes) {}
  template <class T>
  T pod() {
    need(sizeof(T));
    T v;
    std::memcpy(&v, m_bytes.data() + m_pos, sizeof(T));
    m_pos += sizeof(T);
    return v;
  }
  template <class Derived>
  void matrix(Eigen::PlainObjectBase<Derived>& m) {
    const long long r = pod<long long>(), c = pod<long long>();
    if (r < 0 || c < 0) throw std::runtime_error("cache payload: negative size");
    if (Derived::ColsAtCompileTime != Eigen::Dynamic && c != Derived::ColsAtCompileTime)
      throw std::runtime_error("cache payload: column count mismatch");
    need(sizeof(typename Derived::Scalar) * size_t(r) * size_t(c));
    m.resize(r, c);
    // An empty matrix has no storage (data() is null), which memcpy must not be handed.
    if (m.size() > 0)
      std::memcpy(m.data(), m_bytes.data() + m_pos, sizeof(typename Derived::Scalar) * m.size());
    m_pos += sizeof(typename Derived::Scalar) * m.size();
  }
  std::string string() {
    const long long n = pod<long long>();
    if (n < 0) throw std::runtime_error("cache payload: negative size");
    need(size_t(n));
    std::string s(m_bytes.data() + m_pos, size_t(n));
    m_pos += size_t(n);
    return s;
  }
  bool atEnd() const { return m_pos == m_bytes.size(); }

 private:
  void need(size_t n) const {
    if (m_pos + n > m_bytes.size()) throw std::runtime_error("cache payload: truncated");
  }
  const std::vector<char>& m_bytes;
  size_t m_pos = 0;
};

class Cache {
 public:
  /// StoreFailed: put() could not write the entry (a full disk, a read-only folder); the run
  /// goes on without it and `detail` says why.
  enum class EventKind { Hit, Miss, Corrupt, Stored, Disabled, StoreFailed };
  struct Event {
    std::string kind;  ///< what was cached, e.g. "metaballs.spheres"
    std::string key;   ///< hex digest
    EventKind what;
    std::string detail = {};  ///< StoreFailed: the reason
  };

  /// dir empty: caching disabled (get always misses, put does nothing).
  explicit Cache(std::filesystem::path dir);

  /// $DEFORM_CACHE_DIR, else $XDG_CACHE_HOME/deformbench, else $HOME/.cache/deformbench.
  static std::filesystem::path defaultDir();

  std::optional<std::vector<char>> get(const std::string& kind, const CacheKey& key);
  /// Stores an entry. Never throws for the disk's trouble: a failed write (ENOSPC, EACCES, ...)
  /// is an event StoreFailed with the reason, and the caller goes on with what it computed.
  void put(const std::string& kind, const CacheKey& key, const std::vector<char>& payload);
  /// The caller could not use the payload get() returned (a payload that passes the checksum
  /// but does not parse, e.g. an entry re-signed after truncation): the entry is deleted and
  /// its Hit event becomes Corrupt, so the run does not count it as a hit.
  void reject(const std::string& kind, const CacheKey& key);

  const std::filesystem::path& dir() const { return m_dir; }
  const std::vector<Event>& events() const { return m_events; }
  void clearEvents() { m_events.clear(); }

 private:
  std::filesystem::path entryPath(const std::string& kind, const std::string& hex) const;
  std::filesystem::path m_dir;
  std::vector<Event> m_events;
};

}  // namespace deform
