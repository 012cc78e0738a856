#include <deform/internal/atomic_file.h>
#include <deform/sdk/cache.h>
#include <deform/sdk/error.h>
#include <fcntl.h>
#include <openssl/evp.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cassert>
#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <limits>
#include <random>
#include <stdexcept>

namespace deform {

namespace fs = std::filesystem;

namespace {

using Digest = std::array<unsigned char, 32>;

EVP_MD_CTX* newSha256() {
  EVP_MD_CTX* ctx = EVP_MD_CTX_new();
  if (!ctx || EVP_DigestInit_ex(ctx, EVP_sha256(), nullptr) != 1) {
    EVP_MD_CTX_free(ctx);
    throw std::runtime_error("OpenSSL: cannot initialise SHA-256");
  }
  return ctx;
}

std::string toHex(const unsigned char* d, size_t n) {
  static const char* kDigits = "0123456789abcdef";
  std::string s(2 * n, '0');
  for (size_t i = 0; i < n; ++i) {
    s[2 * i] = kDigits[d[i] >> 4];
    s[2 * i + 1] = kDigits[d[i] & 15];
  }
  return s;
}

Digest sha256(const void* data, size_t n) {
  Digest d{};
  unsigned int len = 0;
  if (EVP_Digest(data, n, d.data(), &len, EVP_sha256(), nullptr) != 1 || len != d.size()) {
    throw std::runtime_error("OpenSSL: SHA-256 failed");
  }
  return d;
}

bool fromHex(const std::string& hex, Digest& out) {
  if (hex.size() != 2 * out.size()) return false;
  auto nibble = [](char c) -> int {
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    return -1;
  };
  for (size_t i = 0; i < out.size(); ++i) {
    const int hi = nibble(hex[2 * i]), lo = nibble(hex[2 * i + 1]);
    if (hi < 0 || lo < 0) return false;
    out[i] = static_cast<unsigned char>(hi * 16 + lo);
  }
  return true;
}

// Fixed-width little-endian integers, so an entry's header reads the same on every host.
void putU32(std::string& s, uint32_t v) {
  for (int i = 0; i < 4; ++i) s.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}
void putU64(std::string& s, uint64_t v) {
  for (int i = 0; i < 8; ++i) s.push_back(static_cast<char>((v >> (8 * i)) & 0xff));
}
uint64_t getLE(const char* p, int bytes) {
  uint64_t v = 0;
  for (int i = 0; i < bytes; ++i) v |= uint64_t(static_cast<unsigned char>(p[i])) << (8 * i);
  return v;
}

// Entry layout: magic (8) | format version u32 | reserved u32 | payload size u64 |
// SHA-256 of the key (32) | SHA-256 of the payload (32) | payload.
constexpr char kMagic[8] = {'D', 'F', 'B', 'C', 'A', 'C', 'H', 'E'};
constexpr uint32_t kFormatVersion = 1;
constexpr size_t kHeaderSize = 8 + 4 + 4 + 8 + 32 + 32;

// Kinds become folder names: keep them to a portable, traversal-free alphabet.
bool validKind(const std::string& kind) {
  if (kind.empty() || kind == "." || kind == "..") return false;
  for (char c : kind) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '.' || c == '_' || c == '-';
    if (!ok) return false;
  }
  return true;
}

std::string errnoText(int err) {
  return std::strerror(err);
}

}  // namespace

// ---------------------------------------------------------------------------------------------
// CacheKey

struct CacheKey::State {
  EVP_MD_CTX* ctx = nullptr;
};

CacheKey::CacheKey() : m_state(new State) {
  m_state->ctx = newSha256();
}

CacheKey::~CacheKey() {
  EVP_MD_CTX_free(m_state->ctx);
  delete m_state;
}

CacheKey::CacheKey(const CacheKey& other) : m_state(new State) {
  m_state->ctx = EVP_MD_CTX_new();
  if (!m_state->ctx || EVP_MD_CTX_copy_ex(m_state->ctx, other.m_state->ctx) != 1) {
    EVP_MD_CTX_free(m_state->ctx);
    delete m_state;
    throw std::runtime_error("OpenSSL: cannot copy SHA-256 state");
  }
}

CacheKey& CacheKey::operator=(const CacheKey& other) {
  if (this != &other && EVP_MD_CTX_copy_ex(m_state->ctx, other.m_state->ctx) != 1) {
    throw std::runtime_error("OpenSSL: cannot copy SHA-256 state");
  }
  return *this;
}

void CacheKey::raw(const void* data, size_t n) {
  if (n != 0 && EVP_DigestUpdate(m_state->ctx, data, n) != 1) {
    throw std::runtime_error("OpenSSL: SHA-256 update failed");
  }
}

namespace {
// Every value is framed as tag byte + fixed-width sizes, so concatenations cannot collide.
std::string frame(char tag, std::initializer_list<uint64_t> sizes) {
  std::string s(1, tag);
  for (uint64_t n : sizes) putU64(s, n);
  return s;
}

double normalised(double v) {
  if (v == 0.0) return 0.0;                                            // -0.0 and 0.0 alike
  if (std::isnan(v)) return std::numeric_limits<double>::quiet_NaN();  // one NaN
  return v;
}
}  // namespace

// Doubles are hashed with -0.0 and NaN normalised, in batches (the data may be large).
void CacheKey::addReals(const double* data, size_t n) {
  std::array<double, 768> buf;
  for (size_t done = 0; done < n;) {
    const size_t batch = std::min(buf.size(), n - done);
    for (size_t i = 0; i < batch; ++i) buf[i] = normalised(data[done + i]);
    raw(buf.data(), batch * sizeof(double));
    done += batch;
  }
}

CacheKey& CacheKey::add(std::string_view s) {
  const std::string h = frame('s', {s.size()});
  raw(h.data(), h.size());
  raw(s.data(), s.size());
  return *this;
}

CacheKey& CacheKey::add(double v) {
  const double n = normalised(v);
  uint64_t bits;
  std::memcpy(&bits, &n, sizeof bits);
  std::string h = frame('d', {});
  putU64(h, bits);
  raw(h.data(), h.size());
  return *this;
}

CacheKey& CacheKey::add(long long v) {
  std::string h = frame('i', {});
  putU64(h, static_cast<uint64_t>(v));
  raw(h.data(), h.size());
  return *this;
}

CacheKey& CacheKey::add(const MatX3& m) {
  const std::string h = frame('M', {uint64_t(m.rows()), uint64_t(m.cols())});
  raw(h.data(), h.size());
  addReals(m.data(), size_t(m.size()));
  return *this;
}

CacheKey& CacheKey::add(const VecX& v) {
  const std::string h = frame('v', {uint64_t(v.size())});
  raw(h.data(), h.size());
  addReals(v.data(), size_t(v.size()));
  return *this;
}

CacheKey& CacheKey::add(const MatX3i& m) {
  const std::string h = frame('F', {uint64_t(m.rows()), uint64_t(m.cols())});
  raw(h.data(), h.size());
  raw(m.data(), sizeof(int) * size_t(m.size()));
  return *this;
}

CacheKey& CacheKey::add(const MatX4i& m) {
  const std::string h = frame('T', {uint64_t(m.rows()), uint64_t(m.cols())});
  raw(h.data(), h.size());
  raw(m.data(), sizeof(int) * size_t(m.size()));
  return *this;
}

std::string CacheKey::hex() const {
  EVP_MD_CTX* copy = EVP_MD_CTX_new();
  Digest d{};
  unsigned int len = 0;
  const bool ok = copy && EVP_MD_CTX_copy_ex(copy, m_state->ctx) == 1 &&
                  EVP_DigestFinal_ex(copy, d.data(), &len) == 1 && len == d.size();
  EVP_MD_CTX_free(copy);
  if (!ok) throw std::runtime_error("OpenSSL: SHA-256 final failed");
  return toHex(d.data(), d.size());
}

std::string sha256Hex(const void* data, size_t n) {
  const Digest d = sha256(data, n);
  return toHex(d.data(), d.size());
}

std::string sha256File(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, "", "cannot open for reading: " + errnoText(errno));
  EVP_MD_CTX* ctx = newSha256();
  std::array<char, 1 << 16> buf;
  bool ok = true;
  while (ok && in) {
    in.read(buf.data(), buf.size());
    const std::streamsize got = in.gcount();
    if (got > 0) ok = EVP_DigestUpdate(ctx, buf.data(), size_t(got)) == 1;
  }
  const bool readError = in.bad();
  Digest d{};
  unsigned int len = 0;
  ok = ok && EVP_DigestFinal_ex(ctx, d.data(), &len) == 1;
  EVP_MD_CTX_free(ctx);
  if (readError) throw InputError(path, "", "read error");
  if (!ok) throw std::runtime_error("OpenSSL: SHA-256 failed");
  return toHex(d.data(), d.size());
}

// ---------------------------------------------------------------------------------------------
// writeFileAtomic

void writeFileAtomic(const fs::path& path, std::string_view contents) {
  // The temporary name must be unique across threads, processes and hosts sharing the folder:
  // pid + per-process counter + random bits. O_EXCL guarantees we never share a temp file.
  static std::atomic<unsigned long long> counter{0};
  std::random_device rd;
  const unsigned long long rnd = (static_cast<unsigned long long>(rd()) << 32) ^ rd();
  char suffix[96];
  std::snprintf(suffix, sizeof suffix, ".tmp.%ld.%llu.%016llx", static_cast<long>(::getpid()),
                counter.fetch_add(1), rnd);
  const fs::path tmp = path.parent_path() / (path.filename().string() + suffix);

  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0644);
  if (fd < 0) {
    throw InputError(path.string(), "", "cannot create temporary file: " + errnoText(errno));
  }
  auto failWith = [&](const std::string& what, int err) {
    ::close(fd);
    ::unlink(tmp.c_str());
    throw InputError(path.string(), "", what + ": " + errnoText(err));
  };
  const char* p = contents.data();
  size_t left = contents.size();
  while (left > 0) {
    const ssize_t n = ::write(fd, p, left);
    if (n < 0) {
      if (errno == EINTR) continue;
      failWith("write failed", errno);
    }
    p += n;
    left -= size_t(n);
  }
  if (::fsync(fd) != 0) failWith("fsync failed", errno);
  if (::close(fd) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    throw InputError(path.string(), "", "close failed: " + errnoText(err));
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const int err = errno;
    ::unlink(tmp.c_str());
    throw InputError(path.string(), "", "rename failed: " + errnoText(err));
  }
  // Make the rename itself durable; failure here loses durability, not correctness.
  const fs::path dir = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  const int dfd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dfd >= 0) {
    ::fsync(dfd);
    ::close(dfd);
  }
}

// ---------------------------------------------------------------------------------------------
// Cache

Cache::Cache(fs::path dir) : m_dir(std::move(dir)) {
  if (m_dir.empty()) return;
  std::error_code ec;
  fs::create_directories(m_dir, ec);
  if (ec || !fs::is_directory(m_dir)) {
    throw InputError(m_dir.string(), "",
                     "cannot create the cache directory" +
                         (ec ? ": " + ec.message() : std::string(": not a directory")));
  }
}

fs::path Cache::defaultDir() {
  auto env = [](const char* name) -> std::string {
    const char* v = std::getenv(name);
    return v ? std::string(v) : std::string();
  };
  if (std::string d = env("DEFORM_CACHE_DIR"); !d.empty()) return d;
  // The XDG spec says relative values are invalid and must be ignored.
  if (std::string d = env("XDG_CACHE_HOME"); !d.empty() && d[0] == '/') {
    return fs::path(d) / "deformbench";
  }
  if (std::string h = env("HOME"); !h.empty()) return fs::path(h) / ".cache" / "deformbench";
  return {};  // nowhere sensible: caching disabled
}

fs::path Cache::entryPath(const std::string& kind, const std::string& hex) const {
  return m_dir / kind / (hex + ".bin");
}

std::optional<std::vector<char>> Cache::get(const std::string& kind, const CacheKey& key) {
  assert(validKind(kind) && "Cache: kind must be [A-Za-z0-9._-]+");
  if (!validKind(kind)) throw std::logic_error("Cache: invalid kind '" + kind + "'");
  const std::string hex = key.hex();
  if (m_dir.empty()) {
    m_events.push_back({kind, hex, EventKind::Disabled});
    return std::nullopt;
  }
  const fs::path path = entryPath(kind, hex);
  // Read through one descriptor: what is checked is the file that was opened, even when a
  // concurrent writer renames a new entry into place meanwhile.
  const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  struct stat st {};
  if (fd < 0 || ::fstat(fd, &st) != 0) {
    if (fd >= 0) ::close(fd);
    m_events.push_back({kind, hex, EventKind::Miss});
    return std::nullopt;
  }
  // Payloads can be large (dense BEM matrices): read once, straight into the result buffer.
  std::vector<char> bytes(st.st_size > 0 ? size_t(st.st_size) : 0);
  size_t got = 0;
  while (got < bytes.size()) {
    const ssize_t n = ::read(fd, bytes.data() + got, bytes.size() - got);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    got += size_t(n);
  }
  ::close(fd);
  const bool readOk = got == bytes.size();

  Digest keyDigest{};
  fromHex(hex, keyDigest);
  bool ok = readOk && bytes.size() >= kHeaderSize &&
            std::memcmp(bytes.data(), kMagic, sizeof kMagic) == 0 &&
            getLE(bytes.data() + 8, 4) == kFormatVersion &&
            getLE(bytes.data() + 16, 8) == bytes.size() - kHeaderSize &&
            std::memcmp(bytes.data() + 24, keyDigest.data(), 32) == 0;
  if (ok) {
    const Digest d = sha256(bytes.data() + kHeaderSize, bytes.size() - kHeaderSize);
    ok = std::memcmp(bytes.data() + 56, d.data(), 32) == 0;
  }
  if (!ok) {
    // Remove the bad entry unless a concurrent writer has already renamed a new one into place.
    struct stat now {};
    if (::stat(path.c_str(), &now) == 0 && now.st_ino == st.st_ino && now.st_dev == st.st_dev)
      ::unlink(path.c_str());
    m_events.push_back({kind, hex, EventKind::Corrupt});
    return std::nullopt;
  }
  m_events.push_back({kind, hex, EventKind::Hit});
  bytes.erase(bytes.begin(), bytes.begin() + kHeaderSize);
  return bytes;
}

void Cache::put(const std::string& kind, const CacheKey& key, const std::vector<char>& payload) {
  assert(validKind(kind) && "Cache: kind must be [A-Za-z0-9._-]+");
  if (!validKind(kind)) throw std::logic_error("Cache: invalid kind '" + kind + "'");
  const std::string hex = key.hex();
  if (m_dir.empty()) {
    m_events.push_back({kind, hex, EventKind::Disabled});
    return;
  }
  const fs::path folder = m_dir / kind;
  std::error_code ec;
  fs::create_directories(folder, ec);
  if (ec || !fs::is_directory(folder)) {
    m_events.push_back({kind, hex, EventKind::StoreFailed,
                        folder.string() + ": cannot create the cache directory" +
                            (ec ? ": " + ec.message() : "")});
    return;
  }
  Digest keyDigest{};
  fromHex(hex, keyDigest);
  const Digest payloadDigest = sha256(payload.data(), payload.size());
  std::string bytes;
  bytes.reserve(kHeaderSize + payload.size());
  bytes.append(kMagic, sizeof kMagic);
  putU32(bytes, kFormatVersion);
  putU32(bytes, 0);
  putU64(bytes, payload.size());
  bytes.append(reinterpret_cast<const char*>(keyDigest.data()), keyDigest.size());
  bytes.append(reinterpret_cast<const char*>(payloadDigest.data()), payloadDigest.size());
  bytes.append(payload.data(), payload.size());
  try {
    writeFileAtomic(entryPath(kind, hex), bytes);
  } catch (const std::exception& e) {
    // A cache is an optimisation: a full disk costs the next run its precomputation, not this
    // run its result.
    m_events.push_back({kind, hex, EventKind::StoreFailed, e.what()});
    return;
  }
  m_events.push_back({kind, hex, EventKind::Stored});
}

void Cache::reject(const std::string& kind, const CacheKey& key) {
  const std::string hex = key.hex();
  for (auto it = m_events.rbegin(); it != m_events.rend(); ++it) {
    if (it->kind == kind && it->key == hex && it->what == EventKind::Hit) {
      it->what = EventKind::Corrupt;
      it->detail = "the payload passed its checksum but could not be read";
      break;
    }
  }
  if (!m_dir.empty() && validKind(kind)) {
    std::error_code ec;
    fs::remove(entryPath(kind, hex), ec);
  }
}

}  // namespace deform
