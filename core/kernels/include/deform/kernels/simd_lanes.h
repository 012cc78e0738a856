// deformbench kernels: the lane interface of the batched kernels (the core's isometric bending,
// the hybrid FEM+PBD model's batched projections, fem_hex's element rotations). A kernel written
// once as a template over L runs one item per call with ScalarLanes<T> (the reference, and the
// tail of each colour) or eight / four per call with the AVX2 lanes of
// deform/kernels/simd_lanes_avx2.h (eight doubles: deform/kernels/simd_lanes_avx512.h).
//
// L::T is the scalar, L::V a vector of kWidth lanes, L::M a lane mask. Positions are padded rows
// (x, y, z, 0): loadRows / addRows take each lane's row offset in scalars, loadPoints /
// addPoints each lane's point index (offset 4 * index).
#pragma once

#include <cmath>

namespace deform::simd {

/// One lane: the scalar reference.
template <class Scalar>
struct ScalarLanes {
  using T = Scalar;
  using V = Scalar;
  using M = bool;
  static constexpr int kWidth = 1;
  static V set1(T v) { return v; }
  static V load(const T* p) { return *p; }
  static void store(T* p, V v) { *p = v; }
  static V sqrt(V a) { return std::sqrt(a); }
  static V min(V a, V b) { return a < b ? a : b; }
  static V max(V a, V b) { return a > b ? a : b; }
  static V abs(V a) { return std::fabs(a); }
  static M gt(V a, V b) { return a > b; }
  static M lt(V a, V b) { return a < b; }
  static M le(V a, V b) { return a <= b; }
  static M ne(V a, V b) { return a != b; }
  static M band(M a, M b) { return a && b; }
  static M notMask(M a) { return !a; }
  static V select(M m, V a, V b) { return m ? a : b; }
  static int count(M m) { return m ? 1 : 0; }
  static unsigned orBytes(const unsigned char* m) { return *m; }
  static bool anyByte(const unsigned char* m) { return *m != 0; }
  static void loadRows(const T* x4, const int* off, V& x, V& y, V& z) { load3(x4 + *off, x, y, z); }
  static void addRows(T* x4, const int* off, V dx, V dy, V dz) { add3(x4 + *off, dx, dy, dz); }
  static void loadPoints(const T* x4, const int* idx, V& x, V& y, V& z) {
    load3(x4 + 4 * static_cast<long>(*idx), x, y, z);
  }
  static void addPoints(T* x4, const int* idx, V dx, V dy, V dz) {
    add3(x4 + 4 * static_cast<long>(*idx), dx, dy, dz);
  }

 private:
  static void load3(const T* p, V& x, V& y, V& z) {
    x = p[0];
    y = p[1];
    z = p[2];
  }
  static void add3(T* p, V dx, V dy, V dz) {
    p[0] += dx;
    p[1] += dy;
    p[2] += dz;
  }
};

}  // namespace deform::simd
