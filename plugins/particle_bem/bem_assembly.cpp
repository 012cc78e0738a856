#include "bem_assembly.h"

#include "sph_elasticity.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <map>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

// LAPACK (Fortran symbols; the trailing length is gfortran's hidden length of `trans`).
extern "C" {
void dgetrf_(const int* m, const int* n, double* a, const int* lda, int* ipiv, int* info);
void dgetrs_(const char* trans, const int* n, const int* nrhs, const double* a, const int* lda,
             const int* ipiv, double* b, const int* ldb, int* info, size_t transLength);
}

namespace deform::particle_bem {

namespace {

struct Element {
  Vec3 p[3];
  Vec3 n;
  Vec3 centroid;
  Real area, size;
  int v[3];
};

// Accumulates int_T K(x, y) N_k(y) dGamma over the sub-triangle with parent barycentric corners
// B (columns), into rowH/rowG (3 x 3N, columns of the element's nodes).
void integrateRegular(const KelvinKernel& K, const Vec3& x, const Element& e, const Mat3& B,
                      Real areaFactor, int level, const BemQuadrature& q, Eigen::Ref<MatX> rowH,
                      Eigen::Ref<MatX> rowG, long long& subdivided) {
  const Vec3 c = (e.p[0] * B.row(0).sum() + e.p[1] * B.row(1).sum() + e.p[2] * B.row(2).sum()) / 3;
  const Real size = e.size * std::pow(0.5, level);
  if (level < q.maxLevel && (x - c).norm() < q.nearFactor * size) {
    if (level == 0) ++subdivided;
    const Vec3 b0 = B.col(0), b1 = B.col(1), b2 = B.col(2);
    const Vec3 m01 = 0.5 * (b0 + b1), m12 = 0.5 * (b1 + b2), m20 = 0.5 * (b2 + b0);
    Mat3 S;
    S << b0, m01, m20;
    integrateRegular(K, x, e, S, areaFactor / 4, level + 1, q, rowH, rowG, subdivided);
    S << m01, b1, m12;
    integrateRegular(K, x, e, S, areaFactor / 4, level + 1, q, rowH, rowG, subdivided);
    S << m20, m12, b2;
    integrateRegular(K, x, e, S, areaFactor / 4, level + 1, q, rowH, rowG, subdivided);
    S << m12, m20, m01;
    integrateRegular(K, x, e, S, areaFactor / 4, level + 1, q, rowH, rowG, subdivided);
    return;
  }
  Mat3 U, T;
  for (const TrianglePoint& g : gaussTriangle7()) {
    const Vec3 N = B * Vec3(g.l0, g.l1, g.l2);  // parent barycentrics = shape functions
    const Vec3 y = N[0] * e.p[0] + N[1] * e.p[1] + N[2] * e.p[2];
    K.both(y - x, e.n, U, T);
    const Real w = g.w * e.area * areaFactor;
    for (int k = 0; k < 3; ++k) {
      rowH.middleCols<3>(3 * e.v[k]) += (w * N[k]) * T;
      rowG.middleCols<3>(3 * e.v[k]) += (w * N[k]) * U;
    }
  }
}

// int_e T*(x, y) N_k(y) and int_e U*(x, y) N_k(y) of one (source node i at x, element) pair
// into rowH / rowG (3 x 3N, columns of the element's nodes): seven-point rule (subdivided
// near x), or the Duffy rule from x when x is one of the element's vertices.
void integratePair(const KelvinKernel& K, const Vec3& x, int i, const Element& e,
                   const std::vector<TrianglePoint>& duffy, const BemQuadrature& q,
                   Eigen::Ref<MatX> rowH, Eigen::Ref<MatX> rowG, long long& subdivided,
                   long long& singular) {
  int local = -1;
  for (int k = 0; k < 3; ++k)
    if (e.v[k] == i) local = k;
  if (local < 0) {
    integrateRegular(K, x, e, Mat3::Identity(), 1.0, 0, q, rowH, rowG, subdivided);
    return;
  }
  ++singular;
  // Rotate so the source is the Duffy rule's first vertex.
  const int a = local, b = (local + 1) % 3, c = (local + 2) % 3;
  Mat3 U, T;
  for (const TrianglePoint& g : duffy) {
    const Vec3 y = g.l0 * e.p[a] + g.l1 * e.p[b] + g.l2 * e.p[c];
    K.both(y - x, e.n, U, T);
    const Real w = g.w * e.area;
    rowG.middleCols<3>(3 * e.v[a]) += (w * g.l0) * U;
    rowG.middleCols<3>(3 * e.v[b]) += (w * g.l1) * U;
    rowG.middleCols<3>(3 * e.v[c]) += (w * g.l2) * U;
    // T* N_i is strongly singular: its share goes into H_ii by the rigid-body trick.
    rowH.middleCols<3>(3 * e.v[b]) += (w * g.l1) * T;
    rowH.middleCols<3>(3 * e.v[c]) += (w * g.l2) * T;
  }
}

bool makeElement(const SurfaceMesh& s, int f, Element& e) {
  for (int k = 0; k < 3; ++k) {
    e.v[k] = s.F(f, k);
    e.p[k] = s.V.row(e.v[k]).transpose();
  }
  const Vec3 cr = (e.p[1] - e.p[0]).cross(e.p[2] - e.p[0]);
  e.area = 0.5 * cr.norm();
  if (!(e.area > 0)) return false;
  e.n = cr.normalized();
  e.centroid = (e.p[0] + e.p[1] + e.p[2]) / 3;
  e.size = std::max({(e.p[1] - e.p[0]).norm(), (e.p[2] - e.p[1]).norm(), (e.p[0] - e.p[2]).norm()});
  return true;
}

MatX rigidModes(const MatX3& V) {
  const int n = int(V.rows());
  const Vec3 c = V.colwise().mean().transpose();
  const Real L = std::max((V.rowwise() - c.transpose()).rowwise().norm().maxCoeff(), Real(1e-30));
  MatX R = MatX::Zero(3 * n, 6);
  for (int j = 0; j < n; ++j) {
    const Vec3 d = (V.row(j).transpose() - c) / L;
    for (int k = 0; k < 3; ++k) {
      R(3 * j + k, k) = 1;
      const Vec3 e = Vec3::Unit(k).cross(d);
      R.block<3, 1>(3 * j, 3 + k) = e;
    }
  }
  return R;
}

// A of the mixed system (see header); bordered when `fixed` is empty.
MatX mixedMatrix(const BemMatrices& bem, const MatX3& V, const std::vector<char>& isFixed,
                 bool bordered, const SupportColumns* support = nullptr) {
  const Eigen::Index n3 = bem.H.rows(), m = n3 + (bordered ? 6 : 0);
  MatX A = MatX::Zero(m, m);
  for (Eigen::Index j = 0; j < n3 / 3; ++j) {
    if (isFixed[j])
      A.block(0, 3 * j, n3, 3) = -bem.G.middleCols(3 * j, 3);
    else
      A.block(0, 3 * j, n3, 3) = bem.H.middleCols(3 * j, 3);
  }
  if (support)
    for (size_t k = 0; k < support->nodes.size(); ++k)
      A.block(0, 3 * support->nodes[k], n3, 3) = -support->G.middleCols(3 * k, 3);
  if (bordered) {
    const MatX R = rigidModes(V);
    A.block(0, n3, n3, 6) = R;
    A.block(n3, 0, 6, n3) = R.transpose();
  }
  return A;
}

// The dense, non-symmetric collocation system, factorised once and solved for many right-hand
// sides by LAPACK (dgetrf / dgetrs, partial pivoting): the system's LAPACK is OpenBLAS's, whose
// blocked kernels use the vector units of the CPU it runs on (the serial build: one thread, the
// same answer on every run). An exactly singular pivot is an error, not infinities.
class DenseLu {
 public:
  explicit DenseLu(MatX& A) : m_a(A), m_piv(static_cast<size_t>(A.rows())) {
    if (A.rows() != A.cols()) throw std::logic_error("DenseLu: the matrix is not square");
    const int n = static_cast<int>(A.rows());
    int info = 0;
    if (n > 0) dgetrf_(&n, &n, A.data(), &n, m_piv.data(), &info);
    if (info != 0)
      throw std::runtime_error(
          "particle_bem: the BEM system matrix is singular (LAPACK dgetrf "
          "pivot " +
          std::to_string(info) + " of " + std::to_string(n) + ")");
  }
  /// In place: X <- A^-1 X.
  void solveInPlace(MatX& X) const {
    const int n = static_cast<int>(m_a.rows()), nrhs = static_cast<int>(X.cols());
    if (X.rows() != m_a.rows()) throw std::logic_error("DenseLu: right-hand side rows differ");
    if (n == 0 || nrhs == 0) return;
    int info = 0;
    const char trans = 'N';
    dgetrs_(&trans, &n, &nrhs, m_a.data(), &n, m_piv.data(), X.data(), &n, &info, 1);
    if (info != 0) throw std::logic_error("DenseLu: dgetrs rejected its arguments");
  }

 private:
  static_assert(std::is_same_v<Real, double>, "LAPACK's d-routines need double");
  const MatX& m_a;
  std::vector<int> m_piv;
};

// A piece of an element for integrating a traction field: corners, the element's normal, and
// (for a source at one of its corners) the global vertex index at each corner, else -1.
struct FieldPatch {
  Vec3 p[3];
  int vertex[3];
  Real area, size;
  Vec3 centroid;
  std::array<Vec3, 7> y, t;  // seven-point rule: points and field values
};

Real longestEdge(const Vec3& a, const Vec3& b, const Vec3& c) {
  return std::max({(b - a).norm(), (c - b).norm(), (a - c).norm()});
}

// int_T U*(x, y) t(y) dGamma over the triangle (a, b, c), subdivided near x.
Vec3 integrateFieldNear(const KelvinKernel& K, const TractionField& field, const Vec3& x,
                        const Vec3& a, const Vec3& b, const Vec3& c, int level,
                        const BemQuadrature& q) {
  const Real size = longestEdge(a, b, c);
  if (level < q.maxLevel && (x - (a + b + c) / 3).norm() < q.nearFactor * size) {
    const Vec3 ab = 0.5 * (a + b), bc = 0.5 * (b + c), ca = 0.5 * (c + a);
    return integrateFieldNear(K, field, x, a, ab, ca, level + 1, q) +
           integrateFieldNear(K, field, x, ab, b, bc, level + 1, q) +
           integrateFieldNear(K, field, x, ca, bc, c, level + 1, q) +
           integrateFieldNear(K, field, x, bc, ca, ab, level + 1, q);
  }
  const Real area = 0.5 * (b - a).cross(c - a).norm();
  Vec3 sum = Vec3::Zero();
  for (const TrianglePoint& g : gaussTriangle7()) {
    const Vec3 y = g.l0 * a + g.l1 * b + g.l2 * c;
    sum += g.w * area * (K.displacement(y - x) * field(y));
  }
  return sum;
}

void subdivideUniform(const Vec3& a, const Vec3& b, const Vec3& c, const int v[3], int levels,
                      std::vector<FieldPatch>& out) {
  if (levels > 0) {
    const Vec3 ab = 0.5 * (a + b), bc = 0.5 * (b + c), ca = 0.5 * (c + a);
    const int none[3] = {-1, -1, -1};
    const int va[3] = {v[0], -1, -1}, vb[3] = {-1, v[1], -1}, vc[3] = {-1, -1, v[2]};
    subdivideUniform(a, ab, ca, va, levels - 1, out);
    subdivideUniform(ab, b, bc, vb, levels - 1, out);
    subdivideUniform(ca, bc, c, vc, levels - 1, out);
    subdivideUniform(bc, ca, ab, none, levels - 1, out);
    return;
  }
  FieldPatch f;
  f.p[0] = a;
  f.p[1] = b;
  f.p[2] = c;
  for (int k = 0; k < 3; ++k) f.vertex[k] = v[k];
  f.area = 0.5 * (b - a).cross(c - a).norm();
  f.size = longestEdge(a, b, c);
  f.centroid = (a + b + c) / 3;
  out.push_back(f);
}

}  // namespace

VecX integrateTractionField(const SurfaceMesh& s, Real young, Real poisson,
                            const TractionField& field, Real resolution, const BemQuadrature& q) {
  const KelvinKernel K(young, poisson);
  const int n = s.numVertices();
  std::vector<FieldPatch> all;
  for (int f = 0; f < s.numFaces(); ++f) {
    const Vec3 a = s.V.row(s.F(f, 0)), b = s.V.row(s.F(f, 1)), c = s.V.row(s.F(f, 2));
    if (!((b - a).cross(c - a).norm() > 0)) continue;  // degenerate: no area, no load
    int levels = 0;
    for (Real size = longestEdge(a, b, c); size > resolution && levels < 6; size *= 0.5) ++levels;
    const int v[3] = {s.F(f, 0), s.F(f, 1), s.F(f, 2)};
    subdivideUniform(a, b, c, v, levels, all);
  }
  Real tmax = 0;
  for (FieldPatch& f : all) {
    int k = 0;
    for (const TrianglePoint& g : gaussTriangle7()) {
      f.y[k] = g.l0 * f.p[0] + g.l1 * f.p[1] + g.l2 * f.p[2];
      f.t[k] = field(f.y[k]);
      tmax = std::max(tmax, f.t[k].norm());
      ++k;
    }
  }
  std::vector<FieldPatch> loaded;
  for (const FieldPatch& f : all) {
    Real m = 0;
    for (const Vec3& t : f.t) m = std::max(m, t.norm());
    for (const Vec3& p : f.p) m = std::max(m, field(p).norm());
    if (m > 1e-12 * tmax) loaded.push_back(f);
  }
  const std::vector<TrianglePoint> duffy = duffyTriangle(std::max(q.duffyOrder, 6));
  VecX b = VecX::Zero(3 * n);
  for (int i = 0; i < n; ++i) {
    const Vec3 x = s.V.row(i).transpose();
    Vec3 sum = Vec3::Zero();
    for (const FieldPatch& f : loaded) {
      int local = -1;
      for (int k = 0; k < 3; ++k)
        if (f.vertex[k] == i) local = k;
      if (local >= 0) {
        const Vec3& pa = f.p[local];
        const Vec3& pb = f.p[(local + 1) % 3];
        const Vec3& pc = f.p[(local + 2) % 3];
        for (const TrianglePoint& g : duffy) {
          const Vec3 y = g.l0 * pa + g.l1 * pb + g.l2 * pc;
          sum += g.w * f.area * (K.displacement(y - x) * field(y));
        }
      } else if ((x - f.centroid).norm() < q.nearFactor * f.size) {
        sum += integrateFieldNear(K, field, x, f.p[0], f.p[1], f.p[2], 0, q);
      } else {
        const auto& rule = gaussTriangle7();
        for (int k = 0; k < 7; ++k)
          sum += rule[k].w * f.area * (K.displacement(f.y[k] - x) * f.t[k]);
      }
    }
    b.segment<3>(3 * i) = sum;
  }
  return b;
}

BemMatrices assembleBem(const SurfaceMesh& s, Real young, Real poisson, const BemQuadrature& q) {
  const KelvinKernel K(young, poisson);
  const int n = s.numVertices(), nf = s.numFaces();
  BemMatrices out;
  std::vector<Element> elems;
  elems.reserve(nf);
  for (int f = 0; f < nf; ++f) {
    Element e;
    if (makeElement(s, f, e))
      elems.push_back(e);
    else
      ++out.degenerateTriangles;
  }
  const std::vector<TrianglePoint> duffy = duffyTriangle(q.duffyOrder);
  out.H = MatX::Zero(3 * n, 3 * n);
  out.G = MatX::Zero(3 * n, 3 * n);
  MatX rowH(3, 3 * n), rowG(3, 3 * n);
  for (int i = 0; i < n; ++i) {
    rowH.setZero();
    rowG.setZero();
    const Vec3 x = s.V.row(i).transpose();
    for (const Element& e : elems)
      integratePair(K, x, i, e, duffy, q, rowH, rowG, out.subdividedPairs, out.singularPairs);
    if (q.rigidBodyDiagonal) {
      Mat3 sum = Mat3::Zero();
      for (int j = 0; j < n; ++j)
        if (j != i) sum += rowH.middleCols<3>(3 * j);
      rowH.middleCols<3>(3 * i) = -sum;
    }
    out.H.middleRows(3 * i, 3) = rowH;
    out.G.middleRows(3 * i, 3) = rowG;
  }
  return out;
}

namespace {

/// The graded quadrature points of one support face as structure of arrays, for supportSums():
/// positions y, the face's shape functions N at y, and the weights dw.
struct SupportPoints {
  std::vector<Real> y0, y1, y2, n0, n1, n2, dw;
  void clear() {
    for (std::vector<Real>* v : {&y0, &y1, &y2, &n0, &n1, &n2, &dw}) v->clear();
  }
  void add(const Vec3& y, Real N0, Real N1, Real N2, Real w) {
    y0.push_back(y[0]);
    y1.push_back(y[1]);
    y2.push_back(y[2]);
    n0.push_back(N0);
    n1.push_back(N1);
    n2.push_back(N2);
    dw.push_back(w);
  }
};

// supportSums() in an AVX2 clone as well where the compiler targets x86-64 (chosen at load).
#if defined(__x86_64__) && defined(__GNUC__)
#define DEFORM_BEM_AVX2_CLONE __attribute__((target_clones("avx2", "default")))
#else
#define DEFORM_BEM_AVX2_CLONE
#endif

/// S[k] = sum_q N_k(y_q) U*(y_q - x) dw_q over the points (U*(r) = cu (c34 I + r r^T / |r|^2) /
/// |r|, symmetric: xx, yy, zz, xy, xz, yz); a point at x adds nothing. The hot loop of
/// singularSupport() (every point for every node): a vector reduction (omp simd, compiled for
/// AVX2 where the CPU has it), so its sums are in lane order, not point order.
DEFORM_BEM_AVX2_CLONE void supportSums(const SupportPoints& p, Real x0, Real x1, Real x2, Real cu,
                                       Real c34, Real S[3][6]) {
  const Real *y0 = p.y0.data(), *y1 = p.y1.data(), *y2 = p.y2.data(), *n0 = p.n0.data(),
             *n1 = p.n1.data(), *n2 = p.n2.data(), *dw = p.dw.data();
  const int m = static_cast<int>(p.dw.size());
  Real a0 = 0, a1 = 0, a2 = 0, a3 = 0, a4 = 0, a5 = 0, b0 = 0, b1 = 0, b2 = 0, b3 = 0, b4 = 0,
       b5 = 0, c0 = 0, c1 = 0, c2 = 0, c3 = 0, c4 = 0, c5 = 0;
#pragma omp simd reduction(+ : a0, a1, a2, a3, a4, a5, b0, b1, b2, b3, b4, b5) \
    reduction(+ : c0, c1, c2, c3, c4, c5)
  for (int q = 0; q < m; ++q) {
    const Real r0 = y0[q] - x0, r1 = y1[q] - x1, r2 = y2[q] - x2;
    const Real l2 = r0 * r0 + r1 * r1 + r2 * r2;
    // Arithmetic rather than a branch, so that the loop vectorises: a point at x adds 0.
    const Real away = l2 > 0 ? Real(1) : Real(0);
    const Real inv = away / std::sqrt(l2 + (1 - away));
    const Real c = cu * inv * dw[q], d = c * inv * inv, diag = c * c34;
    const Real u0 = diag + d * r0 * r0, u1 = diag + d * r1 * r1, u2 = diag + d * r2 * r2,
               u3 = d * r0 * r1, u4 = d * r0 * r2, u5 = d * r1 * r2;
    a0 += n0[q] * u0, a1 += n0[q] * u1, a2 += n0[q] * u2, a3 += n0[q] * u3, a4 += n0[q] * u4,
        a5 += n0[q] * u5;
    b0 += n1[q] * u0, b1 += n1[q] * u1, b2 += n1[q] * u2, b3 += n1[q] * u3, b4 += n1[q] * u4,
        b5 += n1[q] * u5;
    c0 += n2[q] * u0, c1 += n2[q] * u1, c2 += n2[q] * u2, c3 += n2[q] * u3, c4 += n2[q] * u4,
        c5 += n2[q] * u5;
  }
  const Real out[3][6] = {
      {a0, a1, a2, a3, a4, a5}, {b0, b1, b2, b3, b4, b5}, {c0, c1, c2, c3, c4, c5}};
  for (int k = 0; k < 3; ++k)
    for (int e = 0; e < 6; ++e) S[k][e] = out[k][e];
}

}  // namespace

SingularSupport singularSupport(const SurfaceMesh& s, Real young, Real poisson,
                                const std::vector<int>& fixed) {
  const int n = s.numVertices(), nf = s.numFaces();
  SingularSupport out;
  std::vector<char> isFixed(n, 0), onCurve(n, 0), support(nf, 0);
  for (int j : fixed) isFixed[j] = 1;
  for (int t = 0; t < nf; ++t)
    support[t] = isFixed[s.F(t, 0)] && isFixed[s.F(t, 1)] && isFixed[s.F(t, 2)];
  for (int t = 0; t < nf; ++t)
    if (!support[t])
      for (int k = 0; k < 3; ++k)
        if (isFixed[s.F(t, k)]) onCurve[s.F(t, k)] = 1;
  std::map<std::pair<int, int>, std::array<int, 2>> edgeFaces;
  for (int t = 0; t < nf; ++t)
    for (int k = 0; k < 3; ++k) {
      const int a = s.F(t, k), b = s.F(t, (k + 1) % 3);
      auto [it, fresh] =
          edgeFaces.try_emplace({std::min(a, b), std::max(a, b)}, std::array<int, 2>{-1, -1});
      it->second[it->second[0] < 0 ? 0 : 1] = t;
    }
  const KelvinKernel K(young, poisson);
  std::vector<Real> gx, gw;
  gaussLegendre01(5, gx, gw);
  // Graded towards tau = 0 (the curve) and sigma = 0 (a curve vertex of an edge face).
  const std::vector<Real> br = {0, 1.0 / 64, 1.0 / 32, 1.0 / 16, 0.125, 0.25, 0.5, 0.75, 1};
  std::vector<int> column(n, -1);
  std::vector<std::array<int, 3>> faces;  // (a, b, c) in collapse order
  std::vector<char> edgeType;
  for (int t = 0; t < nf; ++t) {
    if (!support[t]) continue;
    int curveEdges = 0, edge = -1, curveVertices = 0, vertex = -1;
    for (int k = 0; k < 3; ++k) {
      const int a = s.F(t, k), b = s.F(t, (k + 1) % 3);
      const auto& f2 = edgeFaces.at({std::min(a, b), std::max(a, b)});
      const int other = f2[0] == t ? f2[1] : f2[0];
      if (other >= 0 && !support[other]) {
        ++curveEdges;
        edge = k;
      }
      if (onCurve[a]) {
        ++curveVertices;
        vertex = k;
      }
    }
    if (curveVertices == 0 || curveEdges > 1) continue;
    const int k0 = curveEdges == 1 ? edge : vertex;
    faces.push_back({s.F(t, k0), s.F(t, (k0 + 1) % 3), s.F(t, (k0 + 2) % 3)});
    edgeType.push_back(curveEdges == 1);
    (curveEdges == 1 ? out.edgeFaces : out.vertexFaces)++;
    for (int j : faces.back())
      if (column[j] < 0) {
        column[j] = int(out.nodes.size());
        out.nodes.push_back(j);
      }
  }
  out.delta = MatX::Zero(3 * n, 3 * out.nodes.size());
  // Per face: its graded quadrature points, then for every node the three 3 x 3 sums
  // sum_q N_k(y_q) U*(y_q - x_i) dw_q, accumulated in registers (U* symmetric: six entries) and
  // added to delta once per face and node.
  SupportPoints points;
  const Real cu = K.displacementScale(), c34 = K.displacementDiagonal();
  for (size_t f = 0; f < faces.size(); ++f) {
    const Vec3 A = s.V.row(faces[f][0]).transpose(), B = s.V.row(faces[f][1]).transpose(),
               C = s.V.row(faces[f][2]).transpose();
    const Real area = 0.5 * (B - A).cross(C - A).norm();
    if (!(area > 0)) continue;
    points.clear();
    for (size_t ti = 0; ti + 1 < br.size(); ++ti)
      for (size_t si = 0; si + 1 < br.size(); ++si)
        for (size_t p = 0; p < gx.size(); ++p)
          for (size_t q = 0; q < gx.size(); ++q) {
            const Real tau = br[ti] + (br[ti + 1] - br[ti]) * gx[p];
            const Real sig = br[si] + (br[si + 1] - br[si]) * gx[q];
            const Real wq = gw[p] * gw[q] * (br[ti + 1] - br[ti]) * (br[si + 1] - br[si]);
            const Real t2 = tau * tau;
            if (edgeType[f]) {  // y = (1 - t)((1 - sig) A + sig B) + t C, dA = 2 area (1 - t)
              points.add((1 - t2) * ((1 - sig) * A + sig * B) + t2 * C, (1 - t2) * (1 - sig),
                         (1 - t2) * sig, t2,
                         4 * area * (1 - t2) * (1 - tau) * wq);  // (w - 1) dA with t = tau^2
            } else {  // y = A + rho ((1 - sig)(B - A) + sig (C - A)), dA = 2 area rho
              points.add(A + t2 * ((1 - sig) * (B - A) + sig * (C - A)), 1 - t2, t2 * (1 - sig),
                         t2 * sig, 4 * area * t2 * (1 - tau) * wq);
            }
          }
    for (int i = 0; i < n; ++i) {
      Real S[3][6];  // per corner k: xx, yy, zz, xy, xz, yz
      supportSums(points, s.V(i, 0), s.V(i, 1), s.V(i, 2), cu, c34, S);
      for (int k = 0; k < 3; ++k) {
        auto block = out.delta.block<3, 3>(3 * i, 3 * column[faces[f][k]]);
        block(0, 0) += S[k][0];
        block(1, 1) += S[k][1];
        block(2, 2) += S[k][2];
        block(0, 1) += S[k][3];
        block(1, 0) += S[k][3];
        block(0, 2) += S[k][4];
        block(2, 0) += S[k][4];
        block(1, 2) += S[k][5];
        block(2, 1) += S[k][5];
      }
    }
  }
  return out;
}

SupportColumns withSingularSupport(const SupportColumns& sc, const MatX& G,
                                   const SingularSupport& corr) {
  SupportColumns out;
  out.nodes = sc.nodes;
  for (int j : corr.nodes)
    if (std::find(sc.nodes.begin(), sc.nodes.end(), j) == sc.nodes.end()) out.nodes.push_back(j);
  out.G.resize(G.rows(), 3 * out.nodes.size());
  for (size_t k = 0; k < out.nodes.size(); ++k) {
    const int j = out.nodes[k];
    out.G.middleCols(3 * k, 3) =
        k < sc.nodes.size() ? MatX(sc.G.middleCols(3 * k, 3)) : MatX(G.middleCols(3 * j, 3));
    const auto c = std::find(corr.nodes.begin(), corr.nodes.end(), j);
    if (c != corr.nodes.end())
      out.G.middleCols(3 * k, 3) += corr.delta.middleCols(3 * (c - corr.nodes.begin()), 3);
  }
  return out;
}

void addToColumns(MatX& G, const SingularSupport& corr) {
  for (size_t k = 0; k < corr.nodes.size(); ++k)
    G.middleCols(3 * corr.nodes[k], 3) += corr.delta.middleCols(3 * k, 3);
}

SupportColumns supportColumns(const SurfaceMesh& s, Real young, Real poisson,
                              const std::vector<int>& fixed, const BemQuadrature& q) {
  const int n = s.numVertices();
  std::vector<char> isFixed(n, 0);
  for (int j : fixed) isFixed[j] = 1;
  // Support faces: all three nodes fixed. Boundary nodes: fixed, with a face that is not.
  std::vector<char> supportFace(s.numFaces(), 0), boundary(n, 0);
  for (int f = 0; f < s.numFaces(); ++f)
    supportFace[f] = isFixed[s.F(f, 0)] && isFixed[s.F(f, 1)] && isFixed[s.F(f, 2)];
  for (int f = 0; f < s.numFaces(); ++f)
    if (!supportFace[f])
      for (int k = 0; k < 3; ++k) boundary[s.F(f, k)] = isFixed[s.F(f, k)];
  SupportColumns out;
  std::vector<int> slot(n, -1);
  for (int j = 0; j < n; ++j)
    if (boundary[j]) {
      slot[j] = int(out.nodes.size());
      out.nodes.push_back(j);
    }
  // Elements on the support that touch a boundary node, with node indices made local (0..2)
  // so one pair's integrals land in a 3 x 9 block.
  std::vector<Element> elems;
  std::vector<std::array<int, 3>> global;
  for (int f = 0; f < s.numFaces(); ++f) {
    if (!supportFace[f]) continue;
    Element e;
    if (!makeElement(s, f, e)) continue;
    if (slot[e.v[0]] < 0 && slot[e.v[1]] < 0 && slot[e.v[2]] < 0) continue;
    global.push_back({e.v[0], e.v[1], e.v[2]});
    elems.push_back(e);
  }
  out.G = MatX::Zero(3 * n, 3 * out.nodes.size());
  const KelvinKernel K(young, poisson);
  const std::vector<TrianglePoint> duffy = duffyTriangle(q.duffyOrder);
  MatX h(3, 9), g(3, 9);
  long long sub = 0, sing = 0;
  for (int i = 0; i < n; ++i) {
    const Vec3 x = s.V.row(i).transpose();
    for (size_t a = 0; a < elems.size(); ++a) {
      Element e = elems[a];
      int local = -1;
      for (int k = 0; k < 3; ++k) {
        if (e.v[k] == i) local = k;
        e.v[k] = k;
      }
      h.setZero();
      g.setZero();
      integratePair(K, x, local, e, duffy, q, h, g, sub, sing);
      for (int k = 0; k < 3; ++k)
        if (slot[global[a][k]] >= 0)
          out.G.block<3, 3>(3 * i, 3 * slot[global[a][k]]) += g.middleCols<3>(3 * k);
    }
  }
  return out;
}

VecX nodalAreas(const SurfaceMesh& s) {
  VecX A = VecX::Zero(s.numVertices());
  for (int f = 0; f < s.numFaces(); ++f) {
    const Vec3 x0 = s.V.row(s.F(f, 0)), x1 = s.V.row(s.F(f, 1)), x2 = s.V.row(s.F(f, 2));
    const Real a = 0.5 * (x1 - x0).cross(x2 - x0).norm();
    for (int k = 0; k < 3; ++k) A[s.F(f, k)] += a / 3;
  }
  return A;
}

DeformationMatrix computeDeformationMatrix(BemMatrices&& bem, const SurfaceMesh& s,
                                           const MatX3& normals, const std::vector<int>& fixed,
                                           Real young, Real poisson, Real density,
                                           const SupportColumns* support) {
  const int n = s.numVertices();
  const Eigen::Index n3 = 3 * n;
  DeformationMatrix out;
  out.fixed = fixed;
  out.bordered = fixed.empty();
  std::vector<char> isFixed(n, 0);
  for (int j : fixed) isFixed[j] = 1;

  // Gravity right-hand sides (before H and G are released).
  Real lambda, mu;
  lame(young, poisson, lambda, mu);
  const Real alpha = -1 / (2 * lambda + 8 * mu);
  const Vec3 c = s.V.colwise().mean().transpose();
  MatX up = MatX::Zero(n3, 3), gravRhs = MatX::Zero(n3 + (out.bordered ? 6 : 0), 3);
  if (!out.bordered) {
    MatX pp = MatX::Zero(n3, 3);
    for (int k = 0; k < 3; ++k) {
      const Vec3 b = density * Vec3::Unit(k);
      for (int j = 0; j < n; ++j) {
        const Vec3 d = s.V.row(j).transpose() - c;
        up.block<3, 1>(3 * j, k) = alpha * b * d.squaredNorm();
        const Mat3 sigma = 2 * lambda * alpha * b.dot(d) * Mat3::Identity() +
                           2 * mu * alpha * (b * d.transpose() + d * b.transpose());
        pp.block<3, 1>(3 * j, k) = sigma * normals.row(j).transpose();
      }
    }
    for (int j = 0; j < n; ++j) {
      if (isFixed[j])
        gravRhs.topRows(n3) += bem.H.middleCols(3 * j, 3) * up.middleRows(3 * j, 3);
      else
        gravRhs.topRows(n3) -= bem.G.middleCols(3 * j, 3) * pp.middleRows(3 * j, 3);
    }
    if (support)  // a boundary node's traction on its free faces is the particular one
      for (size_t k = 0; k < support->nodes.size(); ++k) {
        const int j = support->nodes[k];
        gravRhs.topRows(n3) -= (bem.G.middleCols(3 * j, 3) - support->G.middleCols(3 * k, 3)) *
                               pp.middleRows(3 * j, 3);
      }
  }

  MatX A = mixedMatrix(bem, s.V, isFixed, out.bordered, support);
  bem.H.resize(0, 0);
  MatX B = std::move(bem.G);
  for (int j : fixed) B.middleCols(3 * j, 3).setZero();
  if (out.bordered) B.conservativeResize(n3 + 6, Eigen::NoChange);
  if (out.bordered) B.bottomRows(6).setZero();
  const DenseLu lu(A);
  lu.solveInPlace(B);
  lu.solveInPlace(gravRhs);
  B.conservativeResize(n3, Eigen::NoChange);
  for (int j : fixed) {
    B.middleRows(3 * j, 3).setZero();  // these rows held the reaction tractions
  }
  out.M = std::move(B);
  out.gravity = MatX::Zero(n3, 3);
  if (!out.bordered) {
    for (int j = 0; j < n; ++j)
      if (!isFixed[j])
        out.gravity.middleRows(3 * j, 3) = gravRhs.middleRows(3 * j, 3) + up.middleRows(3 * j, 3);
  }
  return out;
}

VecX solveBem(const BemMatrices& bem, const SurfaceMesh& s, const std::vector<int>& fixed,
              const VecX& traction) {
  VecX p = traction;
  for (int j : fixed) p.segment<3>(3 * j).setZero();
  return solveBemRhs(bem, s, fixed, bem.G * p);
}

VecX solveBemRhs(const BemMatrices& bem, const SurfaceMesh& s, const std::vector<int>& fixed,
                 const VecX& rhsIn, const SupportColumns* support) {
  const int n = s.numVertices();
  const Eigen::Index n3 = 3 * n;
  std::vector<char> isFixed(n, 0);
  for (int j : fixed) isFixed[j] = 1;
  const bool bordered = fixed.empty();
  MatX A = mixedMatrix(bem, s.V, isFixed, bordered, support);
  MatX rhs = MatX::Zero(A.rows(), 1);
  rhs.topRows(n3) = rhsIn;
  DenseLu(A).solveInPlace(rhs);
  VecX u = rhs.col(0).head(n3);
  for (int j : fixed) u.segment<3>(3 * j).setZero();
  return u;
}

VecX fixedFractions(const SurfaceMesh& s, const Box& box, int samples) {
  const int n = s.numVertices(), K = std::max(1, samples);
  VecX inside = VecX::Zero(n), total = VecX::Zero(n);
  for (int f = 0; f < s.numFaces(); ++f) {
    const Vec3 x[3] = {s.V.row(s.F(f, 0)), s.V.row(s.F(f, 1)), s.V.row(s.F(f, 2))};
    const Real w = 0.5 * (x[1] - x[0]).cross(x[2] - x[0]).norm() / (K * K);
    // Centroids of the K^2 sub-triangles: upright (i, j) and, where it exists, inverted.
    const auto add = [&](Real l1, Real l2) {
      const Vec3 N(1 - l1 - l2, l1, l2);
      const bool in = box.contains(N[0] * x[0] + N[1] * x[1] + N[2] * x[2]);
      for (int k = 0; k < 3; ++k) {
        total[s.F(f, k)] += w * N[k];
        if (in) inside[s.F(f, k)] += w * N[k];
      }
    };
    for (int i = 0; i < K; ++i)
      for (int j = 0; i + j < K; ++j) {
        add((i + 1.0 / 3) / K, (j + 1.0 / 3) / K);
        if (i + j < K - 1) add((i + 2.0 / 3) / K, (j + 2.0 / 3) / K);
      }
  }
  VecX phi = VecX::Zero(n);
  for (int j = 0; j < n; ++j)
    if (total[j] > 0) phi[j] = inside[j] / total[j];
  return phi;
}

VecX solveBemPartial(const BemMatrices& bem, const SurfaceMesh& s, const VecX& phi, Real young,
                     const VecX& rhsIn) {
  const int n = s.numVertices();
  const Eigen::Index n3 = 3 * n;
  const VecX area = nodalAreas(s);
  const Real clamped = 1 - 1e-9;
  bool anySupport = false;
  for (int j = 0; j < n; ++j) anySupport = anySupport || phi[j] > 0;
  std::vector<char> isFixed(n, 0);
  for (int j = 0; j < n; ++j) isFixed[j] = phi[j] >= clamped;
  MatX A = mixedMatrix(bem, s.V, isFixed, !anySupport);
  for (int j = 0; j < n; ++j)
    if (phi[j] > 0 && phi[j] < clamped && area[j] > 0) {
      const Real k = young / std::sqrt(area[j]) * phi[j] / (1 - phi[j]);
      A.block(0, 3 * j, n3, 3) += k * bem.G.middleCols(3 * j, 3);
    }
  MatX rhs = MatX::Zero(A.rows(), 1);
  rhs.topRows(n3) = rhsIn;
  DenseLu(A).solveInPlace(rhs);
  VecX u = rhs.col(0).head(n3);
  for (int j = 0; j < n; ++j)
    if (isFixed[j]) u.segment<3>(3 * j).setZero();
  return u;
}

}  // namespace deform::particle_bem
