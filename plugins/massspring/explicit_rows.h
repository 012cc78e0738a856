// The explicit integrators' inner loops (symplectic and explicit Euler) on node rows: each node's
// position and velocity as one row of eight doubles (x, y, z, 0, vx, vy, vz, 0: one 64-byte cache
// line) and its force as a row of four (fx, fy, fz, 0). A scalar path, an AVX2 one
// (explicit_rows_avx2.cpp, four springs per vector step) and an AVX-512 one
// (explicit_rows_avx512.cpp, eight), the fastest chosen at run time, do the same operations in
// the same order as MassSpringModel::springForces() and the integration loop did before them,
// without fused multiply-adds (the files are compiled with -ffp-contract=off): the results are
// identical bit for bit on every path.
//
// Plain types only: the vector units include this header and nothing with inline library code
// (see deform/kernels/simd_rows_avx2.h for why).
#pragma once

#include <cstddef>

namespace deform::massspring::rows {

/// Springs as structure of arrays, in the order their forces are summed. a and b are the nodes'
/// offsets in the position/velocity rows (8 x node index); the force rows are at a / 2, b / 2.
struct SpringArrays {
  const int* a;
  const int* b;
  const double* rest;  ///< L, m
  const double* k;     ///< N/m
  const double* c;     ///< N s/m
  std::size_t n;
};

/// f_a += m d and f_b -= m d for one spring (d = x_b - x_a, m its force factor): the equal and
/// opposite pair of the scalar loops (here and MassSpringModel::springForces()). Internal linkage,
/// so that the AVX-512 unit's flags never reach another unit's copy.
static inline void addSpringPair(double* fa, double* fb, double m, double d0, double d1,
                                 double d2) {
  fa[0] += m * d0;
  fa[1] += m * d1;
  fa[2] += m * d2;
  fb[0] -= m * d0;
  fb[1] -= m * d1;
  fb[2] -= m * d2;
}

/// f4 (4 doubles per node) += the spring forces (elastic + axial dashpot) at the positions and
/// velocities in xv (8 doubles per node): per spring, with d = x_b - x_a, l = |d|,
/// m = (k (l - L) + c (v_b - v_a) . d / l) / l, f_a += m d and f_b -= m d, in spring order.
/// Springs of (near) zero length (|d|^2 <= 1e-24 m^2) add nothing; returns their number.
long long addSpringForces(const double* xv, const SpringArrays& s, double* f4, bool simd = true);

/// The paths of addSpringForces() and integrate(), all with the same bits.
enum class Simd { Scalar, Avx2, Avx512 };

/// The path the simd = true calls take on this CPU (checked once per process).
Simd simdPath();

/// addSpringForces() on a given path, which this CPU must run (path <= simdPath()): for tests.
long long addSpringForces(const double* xv, const SpringArrays& s, double* f4, Simd path);

/// One explicit substep of n nodes: a = f w + g - alpha v; symplectic: v += h a, x += h v;
/// explicit: x += h v, v += h a (a from the old v). Nodes with w == 0 do not move. Returns false
/// when a coordinate leaves [c - half, c + half] or a velocity is not finite (NaN included).
struct IntegrateArgs {
  const double* w;  ///< inverse masses, n
  double g[3];      ///< gravity, m/s^2
  double alpha;     ///< mass damping, 1/s
  double h;         ///< substep, s
  double c[3];      ///< centre of the divergence box
  double half;      ///< half side of the divergence box
  bool symplectic;
};
bool integrate(double* xv, const double* f4, std::size_t n, const IntegrateArgs& args,
               bool simd = true);

/// integrate() on a given path, which this CPU must run: for tests.
bool integrate(double* xv, const double* f4, std::size_t n, const IntegrateArgs& args, Simd path);

namespace detail {
// The vector bodies (explicit_rows_avx2.cpp, explicit_rows_avx512.cpp): the springs
// [0, return value) / every node (one four-wide update for both).
std::size_t addSpringForcesAvx2(const double* xv, const SpringArrays& s, double* f4,
                                long long* degenerate);
bool integrateAvx2(double* xv, const double* f4, std::size_t n, const IntegrateArgs& args);
std::size_t addSpringForcesAvx512(const double* xv, const SpringArrays& s, double* f4,
                                  long long* degenerate);
}  // namespace detail

}  // namespace deform::massspring::rows
