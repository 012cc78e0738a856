// The only translation unit that includes CGAL (it compiles slowly): see box_clip.h.
#include <deform/geometry/box_clip.h>
#include <deform/sdk/error.h>

#include <CGAL/Exact_predicates_exact_constructions_kernel.h>
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/corefinement.h>
#include <CGAL/Polygon_mesh_processing/remesh.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/boost/graph/helpers.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <limits>
#include <map>
#include <unordered_map>

namespace deform {

namespace {

namespace PMP = CGAL::Polygon_mesh_processing;
using EK = CGAL::Exact_predicates_exact_constructions_kernel;
using IK = CGAL::Exact_predicates_inexact_constructions_kernel;
using ExactMesh = CGAL::Surface_mesh<EK::Point_3>;
using Mesh = CGAL::Surface_mesh<IK::Point_3>;

ExactMesh exactSurface(const SurfaceMesh& s, const std::string& source) {
  ExactMesh m;
  std::vector<ExactMesh::Vertex_index> v;
  v.reserve(size_t(s.numVertices()));
  for (int i = 0; i < s.numVertices(); ++i)
    v.push_back(m.add_vertex(EK::Point_3(s.V(i, 0), s.V(i, 1), s.V(i, 2))));
  for (int f = 0; f < s.numFaces(); ++f) {
    if (m.add_face(v[size_t(s.F(f, 0))], v[size_t(s.F(f, 1))], v[size_t(s.F(f, 2))]) ==
        ExactMesh::null_face())
      throw InputError(source, "face " + std::to_string(f),
                       "cannot clip by the fixed boxes: the surface is not manifold here");
  }
  return m;
}

/// The box as 12 outward triangles. Corner c has x = hi if bit 0, y = hi if bit 1, z = hi if bit 2.
ExactMesh boxSurface(const Box& b) {
  ExactMesh m;
  std::array<ExactMesh::Vertex_index, 8> c;
  for (int i = 0; i < 8; ++i)
    c[size_t(i)] = m.add_vertex(EK::Point_3(
        i & 1 ? b.hi.x() : b.lo.x(), i & 2 ? b.hi.y() : b.lo.y(), i & 4 ? b.hi.z() : b.lo.z()));
  // Each quad counter-clockwise seen from outside (-x, +x, -y, +y, -z, +z).
  const int quads[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};
  for (const auto& q : quads) {
    m.add_face(c[size_t(q[0])], c[size_t(q[1])], c[size_t(q[2])]);
    m.add_face(c[size_t(q[0])], c[size_t(q[2])], c[size_t(q[3])]);
  }
  return m;
}

bool overlapsOpen(const Box& a, const Box& b) {
  return (a.lo.array() < b.hi.array()).all() && (b.lo.array() < a.hi.array()).all();
}

/// A box face plane x_axis = value; caps on the same plane (of one box or of several) form one
/// remeshing patch.
struct Plane {
  int axis;
  double value;
  bool operator<(const Plane& o) const { return axis != o.axis ? axis < o.axis : value < o.value; }
};

/// The plane of a box face that holds the whole triangle (exact test), or axis -1.
template <class Point>
Plane capPlane(const std::array<Point, 3>& p, const std::vector<Box>& boxes) {
  for (const Box& b : boxes) {
    for (int k = 0; k < 3; ++k) {
      for (const double v : {b.lo[k], b.hi[k]}) {
        if (p[0][k] != v || p[1][k] != v || p[2][k] != v) continue;
        bool inside = true;
        for (int j = 0; j < 3 && inside; ++j)
          for (const Point& q : p)
            if (q[j] < b.lo[j] || q[j] > b.hi[j]) inside = false;
        if (inside) return {k, v};
      }
    }
  }
  return {-1, 0};
}

struct CoordHash {
  size_t operator()(const std::array<double, 3>& a) const {
    std::array<unsigned long long, 3> u;
    std::memcpy(u.data(), a.data(), sizeof(u));
    return size_t(u[0] * 0x9E3779B97F4A7C15ull ^ (u[1] + 0x7F4A7C159E3779B9ull) * 31 ^ u[2]);
  }
};

}  // namespace

namespace {

// The surface with every vertex a small fraction (snapFraction) of its shortest edge away from
// a face of one of the boxes snapped onto that face; snappedInput counts the vertices moved.
SurfaceMesh snapToBoxFaces(const SurfaceMesh& surface, const std::vector<Box>& used,
                           Real snapFraction, int& snappedInput) {
  SurfaceMesh snapped = surface;
  if (!(snapFraction > 0) || used.empty()) return snapped;
  std::vector<Real> shortest(size_t(surface.numVertices()), std::numeric_limits<Real>::max());
  const MatX2i E = uniqueEdges(surface.F);
  for (Eigen::Index e = 0; e < E.rows(); ++e) {
    const Real l = (surface.V.row(E(e, 0)) - surface.V.row(E(e, 1))).norm();
    for (int k = 0; k < 2; ++k) shortest[size_t(E(e, k))] = std::min(shortest[size_t(E(e, k))], l);
  }
  for (int i = 0; i < surface.numVertices(); ++i) {
    const Real tol = snapFraction * shortest[size_t(i)];
    bool moved = false;
    for (const Box& b : used) {
      for (int k = 0; k < 3; ++k) {
        bool over = true;
        for (int j = 0; j < 3; ++j)
          if (j != k && (snapped.V(i, j) < b.lo[j] - tol || snapped.V(i, j) > b.hi[j] + tol))
            over = false;
        if (!over) continue;
        for (const Real v : {b.lo[k], b.hi[k]}) {
          const Real d = std::abs(snapped.V(i, k) - v);
          if (d > 0 && d < tol) {
            snapped.V(i, k) = v;
            moved = true;
          }
        }
      }
    }
    snappedInput += moved;
  }
  return snapped;
}

// organ in doubles, in a canonical order (see clipSurfaceByBoxes), into the empty mesh; each face
// on a box plane gets that plane's id in planeId (from 1) as its patch, the others 0.
void canonicalMesh(const ExactMesh& organ, const std::vector<Box>& used, const std::string& src,
                   Mesh& mesh, Mesh::Property_map<Mesh::Face_index, int>& patch,
                   std::map<Plane, int>& planeId) {
  std::vector<ExactMesh::Vertex_index> order(organ.vertices().begin(), organ.vertices().end());
  std::vector<std::array<double, 3>> x(organ.number_of_vertices() +
                                       organ.number_of_removed_vertices());
  for (ExactMesh::Vertex_index v : order) {
    const EK::Point_3& p = organ.point(v);
    x[size_t(v)] = {CGAL::to_double(CGAL::exact(p.x())), CGAL::to_double(CGAL::exact(p.y())),
                    CGAL::to_double(CGAL::exact(p.z()))};
  }
  std::sort(order.begin(), order.end(), [&](ExactMesh::Vertex_index a, ExactMesh::Vertex_index b) {
    if (x[size_t(a)] != x[size_t(b)]) return x[size_t(a)] < x[size_t(b)];
    return CGAL::compare_xyz(organ.point(a), organ.point(b)) == CGAL::SMALLER;
  });
  std::vector<int> rank(x.size(), -1);
  std::vector<Mesh::Vertex_index> vmap;
  vmap.reserve(order.size());
  for (size_t i = 0; i < order.size(); ++i) {
    rank[size_t(order[i])] = int(i);
    const auto& c = x[size_t(order[i])];
    vmap.push_back(mesh.add_vertex(IK::Point_3(c[0], c[1], c[2])));
  }
  std::vector<std::array<int, 3>> faces;
  faces.reserve(organ.number_of_faces());
  for (ExactMesh::Face_index f : organ.faces()) {
    std::array<int, 3> t;
    int k = 0;
    for (ExactMesh::Vertex_index u : CGAL::vertices_around_face(organ.halfedge(f), organ))
      t[size_t(k++)] = rank[size_t(u)];
    std::rotate(t.begin(), std::min_element(t.begin(), t.end()), t.end());
    faces.push_back(t);
  }
  std::sort(faces.begin(), faces.end());
  for (const auto& t : faces) {
    const Mesh::Face_index g =
        mesh.add_face(vmap[size_t(t[0])], vmap[size_t(t[1])], vmap[size_t(t[2])]);
    if (g == Mesh::null_face())
      throw InputError(src, "fixed boxes", "the clipped surface is not manifold");
    std::array<EK::Point_3, 3> p;
    for (int k = 0; k < 3; ++k) p[size_t(k)] = organ.point(order[size_t(t[size_t(k)])]);
    const Plane pl = capPlane(p, used);
    if (pl.axis >= 0) patch[g] = planeId.emplace(pl, int(planeId.size()) + 1).first->second;
  }
}

}  // namespace

BoxClipResult clipSurfaceByBoxes(const SurfaceMesh& surface, const std::vector<Box>& boxes,
                                 const BoxClipOptions& options) {
  const std::string& src = options.source;
  BoxClipResult out;
  const Box organBox = boundingBox(surface.V);
  std::vector<Box> used;
  for (const Box& b : boxes)
    if (!(b.hi.array() <= b.lo.array()).any() && overlapsOpen(b, organBox)) used.push_back(b);
  // Snap vertices a small fraction of an edge away from a box face onto it (see the header).
  const SurfaceMesh snapped = snapToBoxFaces(surface, used, options.snapFraction, out.snappedInput);
  used.clear();
  ExactMesh organ = exactSurface(snapped, src);
  for (size_t i = 0; i < boxes.size(); ++i) {
    const Box& b = boxes[i];
    if ((b.hi.array() <= b.lo.array()).any() || !overlapsOpen(b, organBox)) continue;
    ExactMesh box = boxSurface(b);
    ExactMesh diff;
    const size_t before = organ.number_of_vertices();
    if (!PMP::corefine_and_compute_difference(organ, box, diff))
      throw InputError(src, "fixed box " + std::to_string(i),
                       "cannot subtract the box from the organ: the result would not be a "
                       "manifold surface (the box touches the surface along an edge or a point)");
    if (diff.number_of_faces() == 0)
      throw InputError(src, "fixed boxes",
                       "the fixed boxes contain the whole organ: nothing is left to deform");
    if (diff.number_of_vertices() != before) ++out.boxesCut;
    used.push_back(b);
    organ = std::move(diff);
  }

  // To doubles, in a canonical order. The corefinement's output order is not a function of its
  // input: its box-intersection pass identifies boxes by their heap addresses
  // (Box_intersection_d::ID_FROM_BOX_ADDRESS), so the order in which cut points and faces are
  // created depends on the process's allocation history, and the cap remeshing below (which is
  // order-dependent) then gave different meshes for the same input in different processes. Nor is
  // CGAL::to_double of a lazy exact number: it returns the midpoint of whatever interval
  // approximation the evaluation path left behind. So every coordinate is rounded from its exact
  // value, vertices are sorted by their coordinates (exact comparison breaks ties) and faces by
  // their vertex indices (rotated to start at the smallest, keeping the orientation).
  // Kept input vertices convert exactly; a cut point's plane coordinate is exactly the box's
  // value, its others are the exact value rounded.
  Mesh mesh;
  std::map<Plane, int> planeId;
  auto patch = mesh.add_property_map<Mesh::Face_index, int>("f:patch", 0).first;
  canonicalMesh(organ, used, src, mesh, patch, planeId);
  if (!CGAL::is_closed(mesh))
    throw InputError(src, "fixed boxes", "the organ minus the fixed boxes is not a closed surface");

  // Remesh the caps: they come out of the boolean as fans of slivers between the cut points.
  std::vector<Mesh::Face_index> caps;
  for (Mesh::Face_index f : mesh.faces())
    if (patch[f] > 0) caps.push_back(f);
  if (!caps.empty()) {
    auto ecm = mesh.add_property_map<Mesh::Edge_index, bool>("e:constrained", false).first;
    auto vcm = mesh.add_property_map<Mesh::Vertex_index, bool>("v:constrained", false).first;
    for (Mesh::Edge_index e : mesh.edges()) {
      const auto h = mesh.halfedge(e);
      ecm[e] = patch[mesh.face(h)] != patch[mesh.face(mesh.opposite(h))];
    }
    // Every vertex of the organ part stays where it is (the input's vertices bit for bit).
    for (Mesh::Face_index f : mesh.faces())
      if (patch[f] == 0)
        for (Mesh::Vertex_index u : CGAL::vertices_around_face(mesh.halfedge(f), mesh))
          vcm[u] = true;
    Real target = options.capEdgeLength;
    if (!(target > 0)) {
      const MatX2i E = uniqueEdges(surface.F);
      Real sum = 0;
      for (Eigen::Index e = 0; e < E.rows(); ++e)
        sum += (surface.V.row(E(e, 0)) - surface.V.row(E(e, 1))).norm();
      target = E.rows() > 0 ? sum / Real(E.rows()) : organBox.diagonal() / 20;
    }
    // Constrained edges may be split (the new vertex stays on the cut line or box edge, and the
    // organ triangle beyond a cut edge is split with it: same flat geometry), never flipped.
    PMP::isotropic_remeshing(caps, target, mesh,
                             CGAL::parameters::number_of_iterations(3)
                                 .edge_is_constrained_map(ecm)
                                 .vertex_is_constrained_map(vcm)
                                 .face_patch_map(patch)
                                 .protect_constraints(false));
    mesh.collect_garbage();
    // Smoothing moved cap vertices within their plane in floating point: put them back on it
    // exactly (a vertex on a box edge lies on two planes and gets both coordinates).
    std::vector<Plane> planes(planeId.size() + 1, Plane{-1, 0});
    for (const auto& [pl, id] : planeId) planes[size_t(id)] = pl;
    for (Mesh::Face_index f : mesh.faces()) {
      if (patch[f] <= 0) continue;
      const Plane pl = planes[size_t(patch[f])];
      for (Mesh::Vertex_index u : CGAL::vertices_around_face(mesh.halfedge(f), mesh)) {
        if (vcm[u]) continue;
        std::array<double, 3> x = {mesh.point(u).x(), mesh.point(u).y(), mesh.point(u).z()};
        x[size_t(pl.axis)] = pl.value;
        mesh.point(u) = IK::Point_3(x[0], x[1], x[2]);
      }
    }
  }

  // Output order: kept input vertices (found by exact coordinates) in input order, then the rest.
  std::unordered_map<std::array<double, 3>, int, CoordHash> inputAt;
  for (int i = 0; i < surface.numVertices(); ++i)
    inputAt.emplace(std::array<double, 3>{snapped.V(i, 0), snapped.V(i, 1), snapped.V(i, 2)}, i);
  std::vector<int> meshVertexOfInput(size_t(surface.numVertices()), -1);
  for (Mesh::Vertex_index v : mesh.vertices()) {
    const auto& p = mesh.point(v);
    const auto it = inputAt.find({p.x(), p.y(), p.z()});
    if (it != inputAt.end() && meshVertexOfInput[size_t(it->second)] < 0)
      meshVertexOfInput[size_t(it->second)] = int(v);
  }
  out.inputToClipped.assign(size_t(surface.numVertices()), -1);
  std::vector<int> index(mesh.number_of_vertices(), -1);
  int next = 0;
  for (int i = 0; i < surface.numVertices(); ++i) {
    if (meshVertexOfInput[size_t(i)] < 0) {
      ++out.removedInput;
      continue;
    }
    index[size_t(meshVertexOfInput[size_t(i)])] = next;
    out.inputToClipped[size_t(i)] = next++;
  }
  for (Mesh::Vertex_index v : mesh.vertices())
    if (index[size_t(v)] < 0) index[size_t(v)] = next++;
  out.surface.V.resize(next, 3);
  for (Mesh::Vertex_index v : mesh.vertices()) {
    const auto& p = mesh.point(v);
    out.surface.V.row(index[size_t(v)]) << p.x(), p.y(), p.z();
  }
  out.surface.F.resize(Eigen::Index(mesh.number_of_faces()), 3);
  out.capFace.assign(mesh.number_of_faces(), 0);
  Eigen::Index r = 0;
  for (Mesh::Face_index f : mesh.faces()) {
    int k = 0;
    std::array<Vec3, 3> p;
    for (Mesh::Vertex_index u : CGAL::vertices_around_face(mesh.halfedge(f), mesh)) {
      out.surface.F(r, k) = index[size_t(u)];
      p[size_t(k++)] = out.surface.V.row(index[size_t(u)]).transpose();
    }
    out.capFace[size_t(r)] = capPlane(p, used).axis >= 0 ? 1 : 0;
    ++r;
  }
  return out;
}

}  // namespace deform
