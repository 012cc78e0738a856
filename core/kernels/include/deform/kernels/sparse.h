// deformbench SDK: sparse matrices and the sparse Cholesky factorisation every implicit model
// uses: CHOLMOD's supernodal LL^T through Eigen's CholmodSupport module. Analyse the pattern once
// (analyzePattern), refactorise numerically when values change (factorize), check info().
#pragma once

#include <deform/sdk/types.h>

#include <cstdint>
#include <new>

#include <Eigen/CholmodSupport>
#include <Eigen/SparseCore>

namespace deform {

using SparseMatrix = Eigen::SparseMatrix<Real, Eigen::ColMajor, int>;
using Triplet = Eigen::Triplet<Real, int>;

/// Supernodal CHOLMOD Cholesky of a symmetric positive definite matrix (lower triangle read).
using SparseCholesky = Eigen::CholmodSupernodalLLT<SparseMatrix, Eigen::Lower>;

/// While an object of this class lives, OpenMP parallel regions run on the calling thread only.
/// Why: CHOLMOD 3 (SuiteSparse 5, Debian 12) runs parts of its supernodal numerical
/// factorisation (cholmod_super_numeric) in OpenMP regions with a hard-coded num_threads(4),
/// which OMP_NUM_THREADS=1 does not limit; the project's numerics are single-threaded, and on a
/// shared 2-core machine those extra threads mostly wait for each other (measured on the 51k-tet
/// liver: 22k involuntary context switches and 0.9 s kernel time in one solve). Sets OpenMP's
/// max-active-levels to 0 (no region is active, so each runs with one thread) and restores it on
/// destruction; does nothing when the OpenMP runtime (libgomp) is not loaded. Wrap calls of
/// SparseCholesky::factorize / compute in it.
class SerialOpenMpScope {
 public:
  SerialOpenMpScope();
  ~SerialOpenMpScope();
  SerialOpenMpScope(const SerialOpenMpScope&) = delete;
  SerialOpenMpScope& operator=(const SerialOpenMpScope&) = delete;

 private:
  int m_saved = -1;  ///< previous max-active-levels, -1: nothing changed
};

/// Routes CHOLMOD's large allocations (>= 2 MiB: the factor's values, the supernodal update
/// workspace, permuted copies of the matrix) to memory mapped in 2 MiB-aligned blocks, and keeps
/// freed blocks for reuse (up to 1 GiB); smaller requests go to malloc. Why: each numerical
/// factorisation allocates and frees tens of MB, which glibc returns to the kernel and
/// page-faults back in 4 KiB at a time (measured on the 51k-tet liver Neo-Hookean solve: 48,800
/// minor faults and 0.3-0.5 s of kernel time out of 2.8 s). The blocks are not advised for
/// transparent huge pages: on a VM whose host backs freed memory lazily that was 20% slower
/// (see sparse.cpp). Installs itself once per process (SuiteSparse's allocator hooks are
/// global); memory CHOLMOD obtained before is still freed correctly. Thread-safe. Call before
/// creating a SparseCholesky.
void installCholmodAllocator();

/// Large-array memory from the same cached 2 MiB-aligned mappings that
/// installCholmodAllocator() gives CHOLMOD (requests under 2 MiB go to malloc). For arrays that
/// are rebuilt per solve (index tables of tens of MB): glibc maps and unmaps those each time and
/// the kernel faults them in 4 KiB at a time (measured on the 51k-tet liver: a fault costs ~14 us
/// in this VM, ~4k faults per 16 MB table). largePageFree must get the size that was allocated.
void* largePageAllocate(size_t bytes);
void largePageFree(void* p, size_t bytes) noexcept;

/// std::allocator for largePageAllocate (see above): std::vector<int, LargePageAllocator<int>>.
template <class T>
struct LargePageAllocator {
  using value_type = T;
  LargePageAllocator() = default;
  template <class U>
  LargePageAllocator(const LargePageAllocator<U>& /*other*/) {}
  T* allocate(size_t n) {
    if (n > SIZE_MAX / sizeof(T)) throw std::bad_array_new_length();
    void* p = largePageAllocate(n * sizeof(T));
    if (!p) throw std::bad_alloc();
    return static_cast<T*>(p);
  }
  void deallocate(T* p, size_t n) noexcept { largePageFree(p, n * sizeof(T)); }
  template <class U>
  bool operator==(const LargePageAllocator<U>& /*other*/) const {
    return true;
  }
};

}  // namespace deform
