#include <deform/sdk/cache.h>
#include <deform/sdk/error.h>
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <thread>

namespace deform {
namespace {

namespace fs = std::filesystem;

// A fresh folder per test, removed afterwards.
class CacheTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const auto* info = ::testing::UnitTest::GetInstance()->current_test_info();
    m_dir = fs::temp_directory_path() /
            ("deform_cache_test_" + std::to_string(::getpid()) + "_" + info->name());
    fs::remove_all(m_dir);
  }
  void TearDown() override { fs::remove_all(m_dir); }

  static std::vector<char> payload(size_t n, char seed) {
    std::vector<char> p(n);
    for (size_t i = 0; i < n; ++i) p[i] = static_cast<char>(seed + 31 * i);
    return p;
  }
  static CacheKey key(const std::string& s) {
    CacheKey k;
    k.add("test").add(s);
    return k;
  }
  fs::path onlyEntry(const std::string& kind) const {
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(m_dir / kind)) files.push_back(e.path());
    EXPECT_EQ(files.size(), 1u);
    return files.empty() ? fs::path() : files[0];
  }
  /// A lookup of key(name) in test.kind misses as one corrupt event and deletes the entry.
  ::testing::AssertionResult readsCorrupt(Cache& c, const std::string& name,
                                          const fs::path& entry) const {
    c.clearEvents();
    if (c.get("test.kind", key(name)).has_value()) return ::testing::AssertionFailure() << "a hit";
    if (c.events().size() != 1 || c.events()[0].what != Cache::EventKind::Corrupt)
      return ::testing::AssertionFailure() << c.events().size() << " events, not one corrupt";
    if (fs::exists(entry)) return ::testing::AssertionFailure() << "the entry is still there";
    return ::testing::AssertionSuccess();
  }

  fs::path m_dir;
};

std::vector<Cache::EventKind> kinds(const Cache& c) {
  std::vector<Cache::EventKind> k;
  for (const auto& e : c.events()) k.push_back(e.what);
  return k;
}

using EK = Cache::EventKind;

TEST(Sha256, FipsTestVectors) {
  // FIPS 180-2, appendix B.1 and B.2.
  EXPECT_EQ(sha256Hex("abc", 3),
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
  const std::string two = "abcdbcdecdefdefgefghfghighijhijkijkljklmklmnlmnomnopnopq";
  EXPECT_EQ(sha256Hex(two.data(), two.size()),
            "248d6a61d20638b8e5c026930c3e6039a33ce45964ff2167f6ecedd419db06c1");
  EXPECT_EQ(sha256Hex("", 0), "e3b0c44298fc1c149afbf4c8996fb92427ae41e4649b934ca495991b7852b855");
}

TEST(Sha256, FileMatchesBufferAndMissingFileIsInputError) {
  const fs::path p = fs::temp_directory_path() / ("deform_sha_" + std::to_string(::getpid()));
  { std::ofstream(p, std::ios::binary) << "abc"; }
  EXPECT_EQ(sha256File(p.string()), sha256Hex("abc", 3));
  fs::remove(p);
  EXPECT_THROW(sha256File(p.string()), InputError);
}

TEST(CacheKeyTest, SensitiveToEveryValueAndToOrder) {
  MatX3 V(2, 3);
  V << 0, 1, 2, 3, 4, 5;
  MatX3i F(1, 3);
  F << 0, 1, 2;
  MatX4i T(1, 4);
  T << 0, 1, 2, 3;
  VecX x(3);
  x << 1, 2, 3;
  auto build = [&](int variant) {
    CacheKey k;
    k.add("organ").add(variant == 1 ? 1.5 : 1.0).add(variant == 2 ? 8LL : 7LL);
    MatX3 v = V;
    if (variant == 3) v(1, 2) = std::nextafter(5.0, 6.0);
    k.add(v);
    MatX3i f = F;
    if (variant == 4) f(0, 2) = 3;
    k.add(f);
    MatX4i t = T;
    if (variant == 5) t(0, 0) = 4;
    k.add(t);
    VecX y = x;
    if (variant == 6) y[2] = -3;
    k.add(y);
    if (variant == 7) k.add("");  // even an empty string counts
    return k.hex();
  };
  const std::string base = build(0);
  EXPECT_EQ(base.size(), 64u);
  EXPECT_EQ(base, build(0));  // deterministic
  for (int v = 1; v <= 7; ++v) EXPECT_NE(build(v), base) << "variant " << v;

  CacheKey ab, ba;
  ab.add(1.0).add(2.0);
  ba.add(2.0).add(1.0);
  EXPECT_NE(ab.hex(), ba.hex());
}

TEST(CacheKeyTest, FramingSeparatesConcatenationsAndTypes) {
  CacheKey a, b;
  a.add("ab").add("c");
  b.add("a").add("bc");
  EXPECT_NE(a.hex(), b.hex());
  CacheKey i, d;
  i.add(1LL);
  d.add(1.0);
  EXPECT_NE(i.hex(), d.hex());
  CacheKey i1, i2;
  i1.add(3);
  i2.add(3LL);
  EXPECT_EQ(i1.hex(), i2.hex());
  // Same numbers, different shapes.
  VecX six(6);
  six << 0, 1, 2, 3, 4, 5;
  MatX3 twoRows(2, 3);
  twoRows << 0, 1, 2, 3, 4, 5;
  CacheKey s, m;
  s.add(six);
  m.add(twoRows);
  EXPECT_NE(s.hex(), m.hex());
}

TEST(CacheKeyTest, NegativeZeroHashesLikeZeroAndHexDoesNotConsume) {
  CacheKey p, n;
  p.add(0.0);
  n.add(-0.0);
  EXPECT_EQ(p.hex(), n.hex());
  MatX3 a = MatX3::Zero(1, 3), b = MatX3::Zero(1, 3);
  b(0, 1) = -0.0;
  CacheKey ka, kb;
  ka.add(a);
  kb.add(b);
  EXPECT_EQ(ka.hex(), kb.hex());

  CacheKey k;
  k.add("x");
  const std::string h1 = k.hex();
  EXPECT_EQ(k.hex(), h1);
  CacheKey copy = k;
  copy.add("y");
  EXPECT_EQ(k.hex(), h1);  // the copy is independent
  EXPECT_NE(copy.hex(), h1);
  k.add("y");
  EXPECT_EQ(k.hex(), copy.hex());
}

TEST_F(CacheTest, RoundTripAndMissOnOtherKey) {
  Cache c(m_dir);
  EXPECT_TRUE(fs::is_directory(m_dir));
  EXPECT_FALSE(c.get("test.kind", key("a")).has_value());
  const auto p = payload(10000, 3);
  c.put("test.kind", key("a"), p);
  const auto got = c.get("test.kind", key("a"));
  ASSERT_TRUE(got.has_value());
  EXPECT_EQ(*got, p);
  EXPECT_FALSE(c.get("test.kind", key("b")).has_value());
  EXPECT_FALSE(c.get("other.kind", key("a")).has_value());
  EXPECT_EQ(kinds(c), (std::vector<EK>{EK::Miss, EK::Stored, EK::Hit, EK::Miss, EK::Miss}));
  EXPECT_EQ(c.events()[2].key, key("a").hex());
  EXPECT_EQ(c.events()[2].kind, "test.kind");
  // A second Cache on the same folder (another run) sees the entry; empty payloads work too.
  Cache again(m_dir);
  EXPECT_TRUE(again.get("test.kind", key("a")).has_value());
  again.put("test.kind", key("empty"), {});
  const auto empty = again.get("test.kind", key("empty"));
  ASSERT_TRUE(empty.has_value());
  EXPECT_TRUE(empty->empty());
}

TEST_F(CacheTest, ByteWriterReaderRoundTripThroughTheCache) {
  MatX3 V(2, 3);
  V << 1, 2, 3, 4, 5, 6;
  ByteWriter w;
  w.pod<int>(42);
  w.matrix(V);
  w.string("spheres");
  Cache c(m_dir);
  c.put("test.kind", key("bw"), w.bytes());
  const auto got = c.get("test.kind", key("bw"));
  ASSERT_TRUE(got.has_value());
  ByteReader r(*got);
  EXPECT_EQ(r.pod<int>(), 42);
  MatX3 back;
  r.matrix(back);
  EXPECT_EQ(back, V);
  EXPECT_EQ(r.string(), "spheres");
  EXPECT_TRUE(r.atEnd());
  EXPECT_THROW(r.pod<int>(), std::runtime_error);
}

TEST_F(CacheTest, FlippedPayloadByteIsCorruptAndRemoved) {
  Cache c(m_dir);
  c.put("test.kind", key("a"), payload(1000, 1));
  const fs::path entry = onlyEntry("test.kind");
  {
    std::fstream f(entry, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(-10, std::ios::end);
    char ch = 0;
    f.read(&ch, 1);
    ch ^= 0x01;
    f.seekp(-10, std::ios::end);
    f.write(&ch, 1);
  }
  EXPECT_TRUE(readsCorrupt(c, "a", entry));
  // The next lookup is a plain miss, and a new put heals it.
  EXPECT_FALSE(c.get("test.kind", key("a")).has_value());
  EXPECT_EQ(c.events().back().what, EK::Miss);
  c.put("test.kind", key("a"), payload(1000, 1));
  EXPECT_EQ(c.get("test.kind", key("a")), payload(1000, 1));
}

// Issue 35: a cache on a full (or otherwise unwritable) disk is a warning, not a failed run.
TEST_F(CacheTest, AFailedStoreIsAnEventNotAnError) {
  Cache c(m_dir);
  fs::create_directories(m_dir);
  std::ofstream(m_dir / "test.kind") << "a file where the kind's folder belongs";
  EXPECT_NO_THROW(c.put("test.kind", key("a"), payload(100, 1)));
  ASSERT_EQ(kinds(c), std::vector<EK>{EK::StoreFailed});
  EXPECT_NE(c.events().back().detail.find("test.kind"), std::string::npos)
      << c.events().back().detail;
  // The write itself failing (here: the entry's name is taken by a folder) is the same.
  fs::remove(m_dir / "test.kind");
  c.put("test.kind", key("b"), payload(100, 1));
  const fs::path entry = onlyEntry("test.kind");
  fs::remove(entry);
  fs::create_directories(entry / "x");
  c.clearEvents();
  EXPECT_NO_THROW(c.put("test.kind", key("b"), payload(100, 2)));
  EXPECT_EQ(kinds(c), std::vector<EK>{EK::StoreFailed});
}

// Issue 35: an entry whose payload passes the checksum but that the caller cannot parse (an
// entry re-signed after truncation) is not a hit.
TEST_F(CacheTest, ARejectedHitIsCorruptAndRemoved) {
  Cache c(m_dir);
  c.put("test.kind", key("a"), payload(100, 1));
  const fs::path entry = onlyEntry("test.kind");
  c.clearEvents();
  ASSERT_TRUE(c.get("test.kind", key("a")).has_value());
  c.reject("test.kind", key("a"));
  EXPECT_EQ(kinds(c), std::vector<EK>{EK::Corrupt});
  EXPECT_FALSE(fs::exists(entry));
}

TEST_F(CacheTest, FlippedHeaderByteIsCorrupt) {
  Cache c(m_dir);
  for (int offset : {0, 8, 16, 30, 60}) {  // magic, version, size, key digest, payload digest
    c.put("test.kind", key("h"), payload(100, 2));
    const fs::path entry = onlyEntry("test.kind");
    {
      std::fstream f(entry, std::ios::in | std::ios::out | std::ios::binary);
      f.seekg(offset);
      char ch = 0;
      f.read(&ch, 1);
      ch ^= 0x40;
      f.seekp(offset);
      f.write(&ch, 1);
    }
    EXPECT_TRUE(readsCorrupt(c, "h", entry)) << "offset " << offset;
  }
}

TEST_F(CacheTest, TruncatedEntriesAreCorrupt) {
  Cache c(m_dir);
  for (size_t keep : {size_t(0), size_t(5), size_t(40), size_t(88), size_t(500)}) {
    c.put("test.kind", key("t"), payload(1000, 4));
    const fs::path entry = onlyEntry("test.kind");
    fs::resize_file(entry, keep);
    EXPECT_TRUE(readsCorrupt(c, "t", entry)) << "kept " << keep;
  }
}

TEST_F(CacheTest, EntryUnderAnotherKeysNameIsCorrupt) {
  Cache c(m_dir);
  c.put("test.kind", key("a"), payload(64, 5));
  const fs::path a = onlyEntry("test.kind");
  const fs::path b = m_dir / "test.kind" / (key("b").hex() + ".bin");
  fs::rename(a, b);
  c.clearEvents();
  EXPECT_FALSE(c.get("test.kind", key("b")).has_value());
  EXPECT_EQ(kinds(c), std::vector<EK>{EK::Corrupt});
}

TEST_F(CacheTest, DisabledCacheStoresNothing) {
  Cache c("");
  EXPECT_TRUE(c.dir().empty());
  c.put("test.kind", key("a"), payload(10, 1));
  EXPECT_FALSE(c.get("test.kind", key("a")).has_value());
  EXPECT_EQ(kinds(c), (std::vector<EK>{EK::Disabled, EK::Disabled}));
}

TEST_F(CacheTest, UncreatableDirectoryIsInputErrorNamingIt) {
  fs::create_directories(m_dir);
  { std::ofstream(m_dir / "file") << "x"; }
  const fs::path bad = m_dir / "file" / "cache";
  try {
    Cache c(bad);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), bad.string());
  }
}

TEST_F(CacheTest, ConcurrentThreadsPuttingOneKeyLeaveAValidEntry) {
  fs::create_directories(m_dir);
  const auto p = payload(1 << 18, 7);
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&] {
      Cache c(m_dir);
      for (int i = 0; i < 10; ++i) c.put("test.kind", key("same"), p);
    });
  }
  for (auto& t : threads) t.join();
  Cache c(m_dir);
  EXPECT_EQ(c.get("test.kind", key("same")), p);
  EXPECT_EQ(kinds(c), std::vector<EK>{EK::Hit});
  // No temporary files left behind.
  EXPECT_EQ(fs::path(onlyEntry("test.kind")).filename(), key("same").hex() + ".bin");
}

TEST_F(CacheTest, ConcurrentProcessesPuttingOneKeyLeaveAValidEntry) {
  fs::create_directories(m_dir);
  const auto p = payload(1 << 18, 9);
  std::vector<pid_t> children;
  for (int k = 0; k < 3; ++k) {
    const pid_t pid = ::fork();
    ASSERT_GE(pid, 0);
    if (pid == 0) {
      int rc = 0;
      try {
        Cache c(m_dir);
        for (int i = 0; i < 10; ++i) {
          c.put("test.kind", key("same"), p);
          // Readers racing the writers must see either nothing or a whole entry.
          auto got = c.get("test.kind", key("same"));
          if (got && *got != p) rc = 2;
          if (c.events().back().what == EK::Corrupt) rc = 3;
        }
      } catch (...) {
        rc = 1;
      }
      ::_exit(rc);
    }
    children.push_back(pid);
  }
  for (pid_t pid : children) {
    int status = 0;
    ASSERT_EQ(::waitpid(pid, &status, 0), pid);
    ASSERT_TRUE(WIFEXITED(status));
    EXPECT_EQ(WEXITSTATUS(status), 0);
  }
  Cache c(m_dir);
  EXPECT_EQ(c.get("test.kind", key("same")), p);
}

TEST(CacheDefaultDir, EnvironmentOrder) {
  auto save = [](const char* n) {
    const char* v = std::getenv(n);
    return v ? std::optional<std::string>(v) : std::nullopt;
  };
  auto restore = [](const char* n, const std::optional<std::string>& v) {
    if (v)
      ::setenv(n, v->c_str(), 1);
    else
      ::unsetenv(n);
  };
  const auto dc = save("DEFORM_CACHE_DIR"), xdg = save("XDG_CACHE_HOME"), home = save("HOME");
  ::setenv("DEFORM_CACHE_DIR", "/tmp/a", 1);
  ::setenv("XDG_CACHE_HOME", "/tmp/x", 1);
  ::setenv("HOME", "/tmp/h", 1);
  EXPECT_EQ(Cache::defaultDir(), fs::path("/tmp/a"));
  ::unsetenv("DEFORM_CACHE_DIR");
  EXPECT_EQ(Cache::defaultDir(), fs::path("/tmp/x/deformbench"));
  ::unsetenv("XDG_CACHE_HOME");
  EXPECT_EQ(Cache::defaultDir(), fs::path("/tmp/h/.cache/deformbench"));
  restore("DEFORM_CACHE_DIR", dc);
  restore("XDG_CACHE_HOME", xdg);
  restore("HOME", home);
}

}  // namespace
}  // namespace deform
