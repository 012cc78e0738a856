// Internal: the vector loop of the batched four-point constraint kernels
// (isometric_bending_avx2.cpp, tet_volume_avx2.cpp), written once. Like the kernels' math headers
// it includes nothing with inline functions and has internal linkage, so that it can be compiled
// with -mavx2.
#pragma once

#include <cstddef>

namespace deform::simd {

namespace {  // internal linkage on purpose (see the header comment)

/// Whole groups of W constraints of one colour from begin on: when projecting (measure ==
/// nullptr) two groups at a time, both computed (compute(i, update)) before either is committed
/// (commit(i, update)), so that their sqrt and divide latencies overlap (the constraints of one
/// colour share no movable particle); then one group at a time (group(i), which projects or
/// measures and returns the group's degenerate count). Adds the degenerate constraints to
/// *degenerate and returns how many constraints it handled; the caller does the tail.
template <std::size_t W, class Update, class Compute, class Commit, class Group>
std::size_t pairedGroups(std::size_t begin, std::size_t end, bool measuring, long long* degenerate,
                         Compute&& compute, Commit&& commit, Group&& group) {
  std::size_t i = begin;
  if (!measuring)
    for (; i + 2 * W <= end; i += 2 * W) {
      Update u0, u1;
      compute(i, u0);
      compute(i + W, u1);
      commit(i, u0);
      commit(i + W, u1);
      *degenerate += u0.degenerate + u1.degenerate;
    }
  for (; i + W <= end; i += W) *degenerate += group(i);
  return i - begin;
}

}  // namespace

}  // namespace deform::simd
