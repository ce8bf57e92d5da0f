#pragma once
/// \file mesh.hpp The fluid surface of one frame as plain arrays.
#include <string>
#include <vector>

#include "lapflow/core/vec.hpp"

namespace lapflow {

/// A triangle soup with shared vertices. Non-manifold geometry, degenerate
/// triangles, isolated vertices and many components are legal.
struct TriMesh {
  std::vector<Vec3> positions;   ///< metres
  std::vector<Tri> triangles;    ///< counter-clockwise seen from outside
  std::vector<Vec3> velocities;  ///< m/s per vertex; empty when the source has none

  std::size_t vertex_count() const { return positions.size(); }
  std::size_t triangle_count() const { return triangles.size(); }
  bool has_velocities() const { return !velocities.empty(); }
  bool empty() const { return triangles.empty(); }
};

/// Unnormalised face normal (length = 2 * area).
Vec3 triangle_normal_area2(const TriMesh& m, int t);
/// Area of triangle t in square metres.
double triangle_area(const TriMesh& m, int t);
/// Total surface area.
double surface_area(const TriMesh& m);
/// Area-weighted vertex normals (unit length; zero for isolated vertices).
std::vector<Vec3> vertex_normals(const TriMesh& m);
/// Mean curvature H = (k1 + k2) / 2 at each vertex, in 1/metres: positive
/// where the surface is convex seen from outside (a sphere of radius R gives
/// 1/R with counter-clockwise triangles seen from outside). From the
/// cotangent Laplacian over mixed Voronoi areas (Meyer, Desbrun, Schroeder
/// and Barr 2003, "Discrete Differential-Geometry Operators for Triangulated
/// 2-Manifolds"): K = -2 H n is the discrete Laplacian of the position and n
/// the area-weighted vertex normal, so H = -K . n / 2. 0 at boundary vertices (on an edge of one
/// triangle), isolated vertices and where the area is zero. Deterministic and
/// the same at any thread count.
std::vector<float> vertex_mean_curvature(const TriMesh& mesh);
/// Bounding box of the vertices referenced by triangles (all vertices if none).
Box3 bounding_box(const TriMesh& m);
/// Connected components over shared vertices: per-triangle component id, and
/// returns the number of components. Deterministic (ids in triangle order).
int triangle_components(const TriMesh& m, std::vector<int>& component_of_triangle);

/// Statistics a user checks before a long bake (`lapflow inspect`).
struct MeshReport {
  std::size_t vertices = 0, triangles = 0;
  int components = 0;
  std::size_t non_manifold_edges = 0;     ///< edges with more than two triangles
  std::size_t non_manifold_vertices = 0;  ///< vertices whose triangle fan is not one disk/half-disk
  std::size_t boundary_edges = 0;
  std::size_t degenerate_triangles = 0;   ///< repeated index or area below 1e-12 of bbox diagonal^2
  std::size_t isolated_vertices = 0;
  Box3 bounds;
  double area = 0;
  bool has_velocity = false;
  double speed_min = 0, speed_mean = 0, speed_max = 0;  ///< m/s over referenced vertices
};
MeshReport analyze_mesh(const TriMesh& m);

}  // namespace lapflow
