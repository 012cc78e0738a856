#include <deform/kernels/sparse.h>

#include <SuiteSparse_config.h>
#include <dlfcn.h>
#include <sys/mman.h>

#include <malloc.h>
#include <cstdlib>
#include <cstring>
#include <map>
#include <mutex>
#include <unordered_map>

namespace deform {

namespace {

/// omp_get/set_max_active_levels of an already loaded libgomp (CHOLMOD pulls it in), looked up
/// at run time so that the core does not link an OpenMP runtime of its own.
struct OpenMpLevels {
  int (*get)() = nullptr;
  void (*set)(int) = nullptr;
};

const OpenMpLevels& openMpLevels() {
  static const OpenMpLevels levels = [] {
    OpenMpLevels l;
    void* gomp = dlopen("libgomp.so.1", RTLD_LAZY | RTLD_NOLOAD);
    if (!gomp) return l;
    l.get = reinterpret_cast<int (*)()>(dlsym(gomp, "omp_get_max_active_levels"));
    l.set = reinterpret_cast<void (*)(int)>(dlsym(gomp, "omp_set_max_active_levels"));
    if (!l.get || !l.set) l = OpenMpLevels{};
    return l;  // the handle stays open: libgomp is in use by CHOLMOD for the whole run
  }();
  return levels;
}

/// The allocator behind installCholmodAllocator() and largePageAllocate(). Large blocks are
/// anonymous mappings rounded up to whole 2 MiB pages; `live` maps each handed-out block to its
/// mapped size (so free and realloc recognise them, and anything else is malloc's), `cache` holds
/// freed blocks by size.
class PageCache {
 public:
  static constexpr size_t kPage = size_t(2) << 20;
  static constexpr size_t kCacheLimit = size_t(1) << 30;

  static PageCache& instance() {
    static PageCache* a = new PageCache;  // never destroyed: CHOLMOD may free
    return *a;                            // in other static destructors
  }

  void* allocate(size_t bytes, bool zero) {
    if (bytes < kPage) return zero ? std::calloc(bytes, 1) : std::malloc(bytes);
    const size_t size = (bytes + kPage - 1) / kPage * kPage;
    std::lock_guard lock(m_mutex);
    // Reuse the smallest cached block that fits without wasting more than half of it.
    auto it = m_cache.lower_bound(size);
    void* p = nullptr;
    size_t got = size;
    if (it != m_cache.end() && it->first <= 2 * size) {
      p = it->second;
      got = it->first;
      m_cached -= got;
      m_cache.erase(it);
      if (zero) std::memset(p, 0, bytes);
    } else {
      p = map(size);  // fresh anonymous pages are zero
      if (!p) return nullptr;
    }
    m_live[p] = got;
    return p;
  }

  /// Returns false when p is not one of this allocator's blocks.
  bool release(void* p) {
    std::lock_guard lock(m_mutex);
    const auto it = m_live.find(p);
    if (it == m_live.end()) return false;
    const size_t size = it->second;
    m_live.erase(it);
    m_cache.emplace(size, p);
    m_cached += size;
    while (m_cached > kCacheLimit) {  // drop the largest cached blocks first
      const auto last = std::prev(m_cache.end());
      munmap(last->second, last->first);
      m_cached -= last->first;
      m_cache.erase(last);
    }
    return true;
  }

  /// Usable size of one of this allocator's blocks, 0 for any other pointer.
  size_t blockSize(void* p) {
    std::lock_guard lock(m_mutex);
    const auto it = m_live.find(p);
    return it == m_live.end() ? 0 : it->second;
  }

 private:
  static void* map(size_t size) {
    // Over-map by one page to align the block to a 2 MiB boundary, so that where the system
    // makes every large mapping a transparent huge page (THP "always") the block is one. No
    // MADV_HUGEPAGE of our own: on a VM whose host backs freed memory lazily, a fresh 2 MiB page
    // cost ~7 ms to fault in, and a 39k-dof Neo-Hookean solve was 20% slower with the advice
    // (docs/notes/reference_fem-history.md, 2026-11-30).
    void* raw =
        mmap(nullptr, size + kPage, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
    if (raw == MAP_FAILED) return nullptr;
    const auto base = reinterpret_cast<uintptr_t>(raw);
    const uintptr_t aligned = (base + kPage - 1) / kPage * kPage;
    if (aligned > base) munmap(raw, aligned - base);
    const uintptr_t end = base + size + kPage;
    if (end > aligned + size) munmap(reinterpret_cast<void*>(aligned + size), end - aligned - size);
    return reinterpret_cast<void*>(aligned);
  }

  std::mutex m_mutex;
  std::unordered_map<void*, size_t> m_live;
  std::multimap<size_t, void*> m_cache;
  size_t m_cached = 0;
};

void* cholmodMalloc(size_t bytes) {
  return PageCache::instance().allocate(bytes, false);
}

void* cholmodCalloc(size_t count, size_t size) {
  if (size != 0 && count > SIZE_MAX / size) return nullptr;
  return PageCache::instance().allocate(count * size, true);
}

void cholmodFree(void* p) {
  if (p && !PageCache::instance().release(p)) std::free(p);
}

void* cholmodRealloc(void* p, size_t bytes) {
  PageCache& a = PageCache::instance();
  const size_t old = p ? a.blockSize(p) : 0;
  if (p && old == 0 && bytes < PageCache::kPage) return std::realloc(p, bytes);
  if (old >= bytes) return p;  // a large block shrinking (or growing within its pages)
  void* q = a.allocate(bytes, false);
  if (!q || !p) return q;
  std::memcpy(q, p, old ? old : bytes < malloc_usable_size(p) ? bytes : malloc_usable_size(p));
  cholmodFree(p);
  return q;
}

}  // namespace

void* largePageAllocate(size_t bytes) {
  return PageCache::instance().allocate(bytes, false);
}

void largePageFree(void* p, size_t /*bytes*/) noexcept {
  if (p && !PageCache::instance().release(p)) std::free(p);
}

void installCholmodAllocator() {
  static std::once_flag once;
  std::call_once(once, [] {
    SuiteSparse_config.malloc_func = cholmodMalloc;
    SuiteSparse_config.calloc_func = cholmodCalloc;
    SuiteSparse_config.realloc_func = cholmodRealloc;
    SuiteSparse_config.free_func = cholmodFree;
  });
}

SerialOpenMpScope::SerialOpenMpScope() {
  const OpenMpLevels& omp = openMpLevels();
  if (!omp.set) return;
  m_saved = omp.get();
  omp.set(0);
}

SerialOpenMpScope::~SerialOpenMpScope() {
  if (m_saved >= 0) openMpLevels().set(m_saved);
}

}  // namespace deform
