// CGAL adapters for patches: isotropic remeshing of a new patch, and CGAL's
// LSCM (kept as the reference lscm_flatten in surface/lscm.cpp is tested
// against). The only translation unit of the patch stages that sees CGAL.
#include <CGAL/Exact_predicates_inexact_constructions_kernel.h>
#include <CGAL/Polygon_mesh_processing/remesh.h>
#include <CGAL/Surface_mesh.h>
#include <CGAL/Surface_mesh_parameterization/Error_code.h>
#include <CGAL/Surface_mesh_parameterization/LSCM_parameterizer_3.h>
#include <CGAL/Surface_mesh_parameterization/Two_vertices_parameterizer_3.h>
#include <CGAL/Surface_mesh_parameterization/parameterize.h>
#include <CGAL/boost/graph/helpers.h>

#include "patches/internal.hpp"

namespace lapflow::detail {
namespace {

using Kernel = CGAL::Exact_predicates_inexact_constructions_kernel;
using Point3 = Kernel::Point_3;
using Point2 = Kernel::Point_2;
using SurfaceMesh = CGAL::Surface_mesh<Point3>;
using VertexIndex = SurfaceMesh::Vertex_index;

// Fills `sm` from the plain arrays; false when a triangle cannot be added
// (non-manifold edge or inconsistent orientation).
bool to_surface_mesh(const PatchMesh& m, SurfaceMesh& sm) {
  sm.reserve(m.positions.size(), m.triangles.size() * 3 / 2 + 8, m.triangles.size());
  for (const Vec3& p : m.positions) sm.add_vertex(Point3(p.x, p.y, p.z));
  for (const Tri& t : m.triangles) {
    if (t[0] == t[1] || t[1] == t[2] || t[0] == t[2]) return false;
    if (sm.add_face(VertexIndex(t[0]), VertexIndex(t[1]), VertexIndex(t[2])) == SurfaceMesh::null_face())
      return false;
  }
  return true;
}

}  // namespace

bool cgal_remesh(PatchMesh& mesh, double target_edge, int iterations) {
  if (mesh.triangles.empty() || !(target_edge > 0)) return false;
  SurfaceMesh sm;
  if (!to_surface_mesh(mesh, sm)) return false;
  // Isolated vertices would survive remeshing as garbage; drop them first.
  for (VertexIndex v : sm.vertices())
    if (sm.is_isolated(v)) sm.remove_vertex(v);
  sm.collect_garbage();
  namespace PMP = CGAL::Polygon_mesh_processing;
  try {
    // Border edges are constraints by default: split and collapsed along the
    // border, never moved off it, so the patch keeps its footprint.
    PMP::isotropic_remeshing(faces(sm), target_edge, sm,
                             PMP::parameters::number_of_iterations(iterations).relax_constraints(true).do_project(false));
  } catch (const std::exception&) {
    return false;
  }
  sm.collect_garbage();
  PatchMesh out;
  out.positions.reserve(sm.number_of_vertices());
  for (VertexIndex v : sm.vertices()) {
    const Point3& p = sm.point(v);
    out.positions.push_back({p.x(), p.y(), p.z()});
  }
  out.triangles.reserve(sm.number_of_faces());
  for (auto f : sm.faces()) {
    Tri t{};
    int k = 0;
    for (VertexIndex v : CGAL::vertices_around_face(sm.halfedge(f), sm)) {
      if (k < 3) t[k] = int32_t(v.idx());
      ++k;
    }
    if (k != 3) return false;
    out.triangles.push_back(t);
  }
  if (out.triangles.empty()) return false;
  mesh = std::move(out);
  return true;
}

bool cgal_lscm_flatten(const PatchMesh& mesh, int pin_a, int pin_b, std::vector<Vec2>& uv) {
  SurfaceMesh sm;
  if (!to_surface_mesh(mesh, sm)) return false;
  namespace SMP = CGAL::Surface_mesh_parameterization;
  using Border = SMP::Two_vertices_parameterizer_3<SurfaceMesh>;
  using Parameterizer = SMP::LSCM_parameterizer_3<SurfaceMesh, Border>;
  SurfaceMesh::Halfedge_index bhd;
  for (auto h : sm.halfedges())
    if (sm.is_border(h)) {
      bhd = h;
      break;
    }
  if (bhd == SurfaceMesh::null_halfedge()) return false;
  auto uvmap = sm.add_property_map<VertexIndex, Point2>("v:uv").first;
  Parameterizer param{Border{VertexIndex(pin_a), VertexIndex(pin_b)}};
  if (SMP::parameterize(sm, param, bhd, uvmap) != SMP::OK) return false;
  uv.assign(mesh.positions.size(), Vec2{});
  for (VertexIndex v : sm.vertices()) uv[v.idx()] = {uvmap[v].x(), uvmap[v].y()};
  return true;
}

}  // namespace lapflow::detail
