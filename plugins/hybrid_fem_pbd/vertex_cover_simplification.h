// Hybrid FEM+PBD, hybrid mesh construction step 2 (paper Sec. 5): simplify the fine surface MS
// to a coarse surface MS' whose vertices are a vertex cover V of MS's edge graph (every edge of
// MS has at least one endpoint in V), by merging each vertex not in V into an adjacent vertex of
// V (the edge p_i p_j collapses onto p_j; edges p_i p_k to a common neighbour disappear, the
// others become p_j p_k).
//
// Paper: "A Hybrid Model Method for Accurate Surface Deformation and Incision Based on FEM and
// PBD", Scientific Programming 2021, article 8343312 (file
// /work/shared/papers/hybrid-fem-pbd-incision.md), Sec. 5, Fig. 5.
//
// The paper takes V from "the method of [22]" (a minimum vertex cover algorithm it does not name)
// and picks p_j by a rule on the average neighbour distance d_avg whose formula is missing from
// the text. Our choices (see README.md):
//  - Cover: the complement of a maximal independent set found by the minimum-degree greedy
//    (Halldorsson & Radhakrishnan, "Greed is good: approximating independent sets in sparse and
//    bounded-degree graphs", Algorithmica 18(1), 1997, doi:10.1007/BF02523693). The complement of
//    a maximal independent set is a minimal vertex cover, and because no two non-cover vertices
//    are adjacent every one of them can be collapsed into a cover neighbour, which is exactly what
//    the merging step needs.
//  - Merge target: among the cover neighbours p_j of p_i, the collapse that keeps the worst
//    resulting triangle quality q = 4 sqrt(3) A / (l1^2 + l2^2 + l3^2) highest; ties go to the
//    p_j whose distance d_ij is closest to d_avg = mean_k d_ik (the paper's quantity), then to the
//    lower index. A collapse is rejected (p_i then stays, joining the cover, which keeps the cover
//    property) when it breaks the link condition (non-manifold result; Dey et al. 1999), flips or
//    turns a triangle normal by more than acos(minNormalDot), or leaves a triangle with
//    q < minQuality.
#pragma once

#include <deform/sdk/mesh.h>

#include <vector>

namespace deform::hybrid_fem_pbd {

/// Vertex cover of a graph from the minimum-degree greedy maximal independent set I: cover = all
/// vertices not in I. E: #E by 2 edges over vertices [0, n). Returns #n flags (1 = in cover).
/// Deterministic (ties broken by index).
std::vector<char> vertexCoverFromIndependentSet(const MatX2i& E, int n);

/// True when every edge of E has at least one endpoint with cover[v] != 0.
bool isVertexCover(const MatX2i& E, const std::vector<char>& cover);

/// Quality 4 sqrt(3) A / (l1^2 + l2^2 + l3^2) of a triangle: 1 equilateral, 0 degenerate.
Real triangleQuality(const Vec3& a, const Vec3& b, const Vec3& c);

struct SimplificationOptions {
  int levels = 1;           ///< how many cover-and-merge passes (the paper does one)
  Real minQuality = 0.1;    ///< reject a collapse leaving a triangle of lower quality
  Real minNormalDot = 0.2;  ///< reject a collapse turning a normal further than acos(this)
};

struct SimplificationResult {
  SurfaceMesh coarse;             ///< the coarse surface MS' (closed, manifold, outward)
  std::vector<int> coarseToFine;  ///< #Vc: fine vertex index of each coarse vertex (ascending)
  std::vector<char> firstCover;   ///< #V fine: the first pass's cover, before any merging
  long long collapsed = 0;        ///< vertices merged away (all passes)
  long long rejected = 0;         ///< non-cover vertices kept because no collapse was valid
};

/// Simplifies a closed, manifold, outward-oriented surface. Coarse vertices keep the fine
/// positions (a subset of the fine vertices). Throws InputError("", "hybrid simplification", ...)
/// if the result is not a valid closed surface (not expected for valid input).
SimplificationResult simplifyByVertexCover(const SurfaceMesh& fine,
                                           const SimplificationOptions& options = {});

}  // namespace deform::hybrid_fem_pbd
