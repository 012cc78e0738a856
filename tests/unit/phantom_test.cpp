// Properties every built-in phantom must have, checked over every phantom and several
// resolutions with mesh.h primitives only (independent of mesh_check's validator).
#include <deform/geometry/phantom.h>
#include <deform/sdk/error.h>
#include <deform/sdk/mesh.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <limits>
#include <map>
#include <numeric>
#include <string>
#include <tuple>
#include <vector>

namespace deform {
namespace {

constexpr Real kMinQuality = 0.4;  // phantom.h promises 0.45

// 4 sqrt(3) area / (sum of squared edge lengths): 1 for an equilateral triangle, 0 degenerate.
Real triangleQuality(const Vec3& a, const Vec3& b, const Vec3& c) {
  const Real area = 0.5 * (b - a).cross(c - a).norm();
  const Real sum = (b - a).squaredNorm() + (c - b).squaredNorm() + (a - c).squaredNorm();
  return 4 * std::sqrt(Real(3)) * area / sum;
}

Real minQuality(const SurfaceMesh& m) {
  Real q = 1;
  for (int f = 0; f < m.numFaces(); ++f) {
    q = std::min(q, triangleQuality(m.V.row(m.F(f, 0)), m.V.row(m.F(f, 1)), m.V.row(m.F(f, 2))));
  }
  return q;
}

// Every directed edge occurs once and its reverse occurs once: closed, edge-manifold and
// consistently oriented. Returns the number of offending directed edges.
int badDirectedEdges(const SurfaceMesh& m) {
  std::vector<std::pair<int, int>> d;
  for (int f = 0; f < m.numFaces(); ++f) {
    for (int k = 0; k < 3; ++k) d.emplace_back(m.F(f, k), m.F(f, (k + 1) % 3));
  }
  std::sort(d.begin(), d.end());
  int bad = 0;
  for (size_t i = 0; i < d.size(); ++i) {
    if (i + 1 < d.size() && d[i] == d[i + 1]) ++bad;
    if (!std::binary_search(d.begin(), d.end(), std::make_pair(d[i].second, d[i].first))) ++bad;
  }
  return bad;
}

// Vertices whose incident triangles do not form a single fan around them (or that no triangle
// uses).
int nonManifoldVertices(const SurfaceMesh& m) {
  std::vector<std::vector<std::pair<int, int>>> link(m.numVertices());
  for (int f = 0; f < m.numFaces(); ++f) {
    for (int k = 0; k < 3; ++k) {
      link[m.F(f, k)].emplace_back(m.F(f, (k + 1) % 3), m.F(f, (k + 2) % 3));
    }
  }
  int bad = 0;
  for (auto& l : link) {
    if (l.size() < 3) {
      ++bad;
      continue;
    }
    std::map<int, int> next(l.begin(), l.end());
    if (next.size() != l.size()) {
      ++bad;
      continue;
    }
    size_t steps = 0;
    int cur = l.front().first;
    do {
      auto it = next.find(cur);
      if (it == next.end()) break;
      cur = it->second;
      ++steps;
    } while (cur != l.front().first && steps <= l.size());
    if (cur != l.front().first || steps != l.size()) ++bad;
  }
  return bad;
}

int components(const SurfaceMesh& m) {
  std::vector<int> parent(m.numVertices());
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int x) {
    while (parent[x] != x) x = parent[x] = parent[parent[x]];
    return x;
  };
  for (int f = 0; f < m.numFaces(); ++f) {
    for (int k = 1; k < 3; ++k) parent[find(m.F(f, k))] = find(m.F(f, 0));
  }
  int count = 0;
  for (int v = 0; v < m.numVertices(); ++v) count += (find(v) == v);
  return count;
}

// Smallest distance between two distinct vertices (sweep over x-sorted vertices).
Real minVertexDistance(const MatX3& V) {
  std::vector<int> order(V.rows());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) { return V(a, 0) < V(b, 0); });
  Real best = std::numeric_limits<Real>::infinity();
  for (size_t i = 0; i < order.size(); ++i) {
    for (size_t j = i + 1; j < order.size() && V(order[j], 0) - V(order[i], 0) < best; ++j) {
      best = std::min(best, (V.row(order[i]) - V.row(order[j])).norm());
    }
  }
  return best;
}

// Generalised winding number of the surface around p (Van Oosterom-Strackee solid angles): 1
// inside and 0 outside a closed, embedded, outward surface; 2 or -1 where it overlaps itself.
Real windingNumber(const SurfaceMesh& m, const Vec3& p) {
  Real total = 0;
  for (int f = 0; f < m.numFaces(); ++f) {
    const Vec3 a = Vec3(m.V.row(m.F(f, 0))) - p, b = Vec3(m.V.row(m.F(f, 1))) - p,
               c = Vec3(m.V.row(m.F(f, 2))) - p;
    const Real la = a.norm(), lb = b.norm(), lc = c.norm();
    const Real num = a.dot(b.cross(c));
    const Real den = la * lb * lc + a.dot(b) * lc + b.dot(c) * la + c.dot(a) * lb;
    total += 2 * std::atan2(num, den);
  }
  return total / (4 * std::acos(Real(-1)));
}

struct Expected {
  Vec3 sizeLo, sizeHi;  // bounding-box size range (m)
  int paperVertices;    // 0 where the papers give no figure
};

Expected expectedFor(const std::string& name) {
  if (name == "liver") return {{0.19, 0.14, 0.08}, {0.21, 0.17, 0.10}, 8128};
  if (name == "gallbladder") return {{0.08, 0.03, 0.025}, {0.095, 0.05, 0.035}, 1461};
  if (name == "stomach") return {{0.12, 0.14, 0.05}, {0.18, 0.20, 0.07}, 3349};
  if (name == "intestine") return {{0.10, 0.10, 0.026}, {0.15, 0.15, 0.028}, 887};
  if (name == "cube") return {{0.1, 0.1, 0.1}, {0.1, 0.1, 0.1}, 0};
  if (name == "sphere") return {{0.099, 0.099, 0.099}, {0.1, 0.1, 0.1}, 0};
  if (name == "steak") return {{0.11, 0.11, 0.018}, {0.13, 0.13, 0.024}, 0};
  if (name == "beam") return {{0.1, 0.01, 0.01}, {0.1, 0.01, 0.01}, 0};
  if (name == "cooks_membrane") return {{0.048, 0.06, 0.008}, {0.048, 0.06, 0.008}, 0};
  ADD_FAILURE() << "no expectations for " << name;
  return {};
}

class PhantomValidity : public ::testing::TestWithParam<std::tuple<std::string, Real>> {};

TEST_P(PhantomValidity, ClosedManifoldOrientedGenusZeroWellShaped) {
  const auto& [name, res] = GetParam();
  const SurfaceMesh m = makePhantom(name, res);
  ASSERT_GE(m.numVertices(), 90);
  ASSERT_TRUE(m.V.allFinite());
  ASSERT_GE(m.F.minCoeff(), 0);
  ASSERT_LT(m.F.maxCoeff(), m.numVertices());

  const MatX2i E = uniqueEdges(m.F);
  const MatX2i EF = edgeFaces(m.F, E);
  EXPECT_EQ(2 * E.rows(), 3 * m.F.rows()) << "some edge is not shared by exactly two triangles";
  EXPECT_EQ((EF.array() < 0).count(), 0) << "boundary edges";
  EXPECT_EQ(badDirectedEdges(m), 0) << "non-manifold or inconsistently oriented edges";
  EXPECT_EQ(nonManifoldVertices(m), 0);
  EXPECT_EQ(components(m), 1);
  EXPECT_EQ(m.numVertices() - E.rows() + m.numFaces(), 2) << "Euler characteristic";

  const Box box = boundingBox(m.V);
  const Real vol = signedVolume(m.V, m.F);
  EXPECT_GT(vol, 0);
  EXPECT_LE(vol, box.size().prod() * (1 + 1e-9));
  EXPECT_GT(vol, 0.05 * box.size().prod());

  const Real q = minQuality(m);
  EXPECT_GE(q, kMinQuality) << "worst triangle quality";
  EXPECT_GT(minVertexDistance(m.V), 1e-4 * box.diagonal()) << "(near-)duplicate vertices";
}

TEST_P(PhantomValidity, EmbeddedWithoutSelfOverlap) {
  const auto& [name, res] = GetParam();
  // Cook's membrane has a 47-degree wedge corner along z, where the averaged vertex normal
  // points out of the wedge: the probe below it is outside although the surface is embedded.
  if (name == "cooks_membrane") GTEST_SKIP() << "acute wedge corners";
  const SurfaceMesh m = makePhantom(name, res);
  const MatX3 N = vertexNormals(m.V, m.F);
  const MatX2i E = uniqueEdges(m.F);
  Real shortest = std::numeric_limits<Real>::infinity();
  for (int e = 0; e < E.rows(); ++e)
    shortest = std::min(shortest, (m.V.row(E(e, 0)) - m.V.row(E(e, 1))).norm());
  const Real eps = 0.05 * shortest;
  const int samples = 40;
  for (int s = 0; s < samples; ++s) {
    const int v = static_cast<int>((static_cast<long>(s) * m.numVertices()) / samples);
    const Vec3 p = m.V.row(v), n = N.row(v);
    EXPECT_NEAR(windingNumber(m, p - eps * n), 1.0, 0.05) << "inside near vertex " << v;
    EXPECT_NEAR(windingNumber(m, p + eps * n), 0.0, 0.05) << "outside near vertex " << v;
  }
}

std::vector<std::tuple<std::string, Real>> allCases() {
  std::vector<std::tuple<std::string, Real>> cases;
  for (const std::string& name : phantomNames()) {
    for (Real res : {1e-3, 0.27, 1.0, 1.7}) cases.emplace_back(name, res);
  }
  return cases;
}

std::string caseName(const ::testing::TestParamInfo<std::tuple<std::string, Real>>& info) {
  char res[32];
  std::snprintf(res, sizeof res, "%g", std::get<1>(info.param));
  std::string s = std::get<0>(info.param) + "_res" + res;
  std::replace(s.begin(), s.end(), '.', 'p');
  std::replace(s.begin(), s.end(), '-', 'm');
  return s;
}

INSTANTIATE_TEST_SUITE_P(AllPhantoms, PhantomValidity, ::testing::ValuesIn(allCases()), caseName);

class PhantomDefaults : public ::testing::TestWithParam<std::string> {};

TEST_P(PhantomDefaults, SizeCountAndCentre) {
  const std::string name = GetParam();
  const Expected ex = expectedFor(name);
  const SurfaceMesh m = makePhantom(name);
  const Box box = boundingBox(m.V);
  for (int k = 0; k < 3; ++k) {
    EXPECT_GE(box.size()[k], ex.sizeLo[k] - 1e-12) << "axis " << k;
    EXPECT_LE(box.size()[k], ex.sizeHi[k] + 1e-12) << "axis " << k;
  }
  if (name == "beam") {
    EXPECT_EQ(box.lo.x(), 0.0);
    EXPECT_EQ(box.hi.x(), 0.1);
    EXPECT_NEAR(box.lo.y(), -0.005, 1e-15);
    EXPECT_NEAR(box.hi.z(), 0.005, 1e-15);
    // An exact box: every vertex lies on one of its six faces.
    for (int v = 0; v < m.numVertices(); ++v) {
      const Vec3 p = m.V.row(v);
      const bool onFace = p.x() == 0.0 || p.x() == 0.1 ||
                          std::abs(std::abs(p.y()) - 0.005) < 1e-15 ||
                          std::abs(std::abs(p.z()) - 0.005) < 1e-15;
      ASSERT_TRUE(onFace) << "vertex " << v;
    }
  } else if (name == "cooks_membrane") {
    EXPECT_EQ(box.lo, Vec3::Zero());
    // The published corners, and the loaded edge's midpoint (48, 52) mm is a vertex.
    for (const Vec3& corner : {Vec3(0, 0, 0), Vec3(0.048, 0.044, 0), Vec3(0.048, 0.06, 0.008),
                               Vec3(0, 0.044, 0.008), Vec3(0.048, 0.052, 0)})
      EXPECT_LT((m.V.row(nearestVertex(m.V, corner)).transpose() - corner).norm(), 1e-15)
          << corner.transpose();
  } else {
    EXPECT_LT(box.center().norm(), 1e-9) << "not centred at the origin";
  }
  if (ex.paperVertices > 0) {
    EXPECT_NEAR(m.numVertices(), ex.paperVertices, 0.15 * ex.paperVertices);
  }
  if (name == "sphere") {
    for (int v = 0; v < m.numVertices(); ++v) EXPECT_NEAR(m.V.row(v).norm(), 0.05, 1e-12);
  }
  if (name == "cube") {
    EXPECT_NEAR(signedVolume(m.V, m.F), 1e-3, 1e-15);
    EXPECT_GE(m.numVertices(), 300);
    EXPECT_LE(m.numVertices(), 1500);
  }
  // The description is one line naming the phantom and its default vertex count.
  const std::string d = phantomDescription(name);
  EXPECT_EQ(d.rfind(name + ":", 0), 0u) << d;
  EXPECT_NE(d.find(std::to_string(m.numVertices()) + " vertices"), std::string::npos) << d;
  EXPECT_EQ(d.find('\n'), std::string::npos);
}

TEST_P(PhantomDefaults, ResolutionScalesVertexCountLinearly) {
  const std::string name = GetParam();
  const int v1 = makePhantom(name, 1.0).numVertices();
  int previous = 0;
  for (Real res : {0.25, 0.5, 1.0, 2.0, 4.0}) {
    const int v = makePhantom(name, res).numVertices();
    EXPECT_GT(v, previous) << "res " << res;
    EXPECT_NEAR(static_cast<Real>(v) / v1, res, 0.3 * res) << "res " << res;
    previous = v;
  }
  // The liver at the PBD benchmark's size (~2.2k vertices).
  if (name == "liver") {
    EXPECT_NEAR(makePhantom(name, 0.27).numVertices(), 2200, 0.15 * 2200);
  }
}

TEST_P(PhantomDefaults, SmallResolutionIsClampedToAUsableMesh) {
  const std::string name = GetParam();
  const SurfaceMesh tiny = makePhantom(name, 1e-6);
  EXPECT_GE(tiny.numVertices(), 90);
  EXPECT_LE(tiny.numVertices(), 400);
  EXPECT_EQ(tiny.V, makePhantom(name, 1e-3).V);
}

TEST_P(PhantomDefaults, DeterministicBitForBit) {
  const std::string name = GetParam();
  for (Real res : {0.3, 1.0}) {
    const SurfaceMesh a = makePhantom(name, res), b = makePhantom(name, res);
    ASSERT_EQ(a.V.rows(), b.V.rows());
    ASSERT_EQ(a.F.rows(), b.F.rows());
    EXPECT_EQ(a.F, b.F);
    EXPECT_EQ(0, std::memcmp(a.V.data(), b.V.data(), sizeof(Real) * a.V.size()));
  }
}

INSTANTIATE_TEST_SUITE_P(AllPhantoms, PhantomDefaults, ::testing::ValuesIn(phantomNames()));

TEST(Phantom, NamesAreTheDocumentedNine) {
  const std::vector<std::string> expected{"liver",     "gallbladder", "stomach",
                                          "intestine", "cube",        "sphere",
                                          "steak",     "beam",        "cooks_membrane"};
  EXPECT_EQ(phantomNames(), expected);
}

TEST(Phantom, BadNameThrowsInputErrorListingKnownNames) {
  try {
    makePhantom("spleen");
    FAIL() << "no throw";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "phantom:spleen");
    EXPECT_NE(e.problem().find("liver"), std::string::npos);
    EXPECT_NE(e.problem().find("beam"), std::string::npos);
  }
  EXPECT_THROW(phantomDescription("Liver"), InputError);
  EXPECT_THROW(makePhantom(""), InputError);
}

TEST(Phantom, BadResolutionThrowsInputError) {
  for (Real res : {0.0, -1.0, std::numeric_limits<Real>::quiet_NaN(),
                   std::numeric_limits<Real>::infinity(), 1e6}) {
    try {
      makePhantom("liver", res);
      FAIL() << "no throw for " << res;
    } catch (const InputError& e) {
      EXPECT_EQ(e.file(), "phantom:liver");
    }
  }
}

TEST(Phantom, OrganShapesAreNotConvexBlobs) {
  // The liver is a wedge: the right lobe (x < 0) is far thicker in z than the left lobe.
  const SurfaceMesh liver = makePhantom("liver");
  Real zLoR = 1, zHiR = -1, zLoL = 1, zHiL = -1;
  for (int v = 0; v < liver.numVertices(); ++v) {
    const Vec3 p = liver.V.row(v);
    if (p.x() < -0.03 && p.x() > -0.05) {
      zLoR = std::min(zLoR, p.z());
      zHiR = std::max(zHiR, p.z());
    }
    if (p.x() > 0.05 && p.x() < 0.07) {
      zLoL = std::min(zLoL, p.z());
      zHiL = std::max(zHiL, p.z());
    }
  }
  EXPECT_GT(zHiR - zLoR, 2.0 * (zHiL - zLoL));
  // Its underside is concave across the right lobe: along x = -0.03, the downward-facing surface
  // is higher at y = 0 than at its lowest point (a convex blob would be lowest near the middle).
  const MatX3 N = vertexNormals(liver.V, liver.F);
  Real zMin = 1, zMid = 1, yMid = 1;
  for (int v = 0; v < liver.numVertices(); ++v) {
    const Vec3 p = liver.V.row(v);
    if (std::abs(p.x() + 0.03) > 0.003 || N(v, 2) > -0.3) continue;
    zMin = std::min(zMin, p.z());
    if (std::abs(p.y()) < yMid) {
      yMid = std::abs(p.y());
      zMid = p.z();
    }
  }
  EXPECT_GT(zMid, zMin + 0.002);
  // The stomach and intestine are curved: the volume is well below that of their bounding box.
  for (const char* name : {"stomach", "intestine"}) {
    const SurfaceMesh m = makePhantom(name);
    EXPECT_LT(signedVolume(m.V, m.F), 0.45 * boundingBox(m.V).size().prod()) << name;
  }
}

}  // namespace
}  // namespace deform
