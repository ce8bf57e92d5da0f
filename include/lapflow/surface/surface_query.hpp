#pragma once
/// \file surface_query.hpp Closest-point and ray queries on a frame's surface
/// (Embree 3 behind a pimpl: no Embree type leaks out).
#include <memory>

#include "lapflow/surface/mesh.hpp"

namespace lapflow {

struct ClosestHit {
  bool found = false;
  int triangle = -1;    ///< index into the mesh's triangles
  Vec3 point;           ///< closest point, refined in double precision
  double b1 = 0, b2 = 0;  ///< barycentric of vertices 1 and 2 (vertex 0 gets 1-b1-b2)
  double distance = 0;  ///< |query - point| in metres
};

/// A point of a triangle with its barycentric coordinates of vertices 1 and 2.
struct TrianglePoint {
  Vec3 point;
  double b1 = 0, b2 = 0;
};

/// Closest point of triangle (a, b, c) to p (Ericson, Real-Time Collision
/// Detection 5.1.5). A degenerate triangle falls through to an edge or vertex
/// region and still gives a point of the triangle.
TrianglePoint closest_point_on_triangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c);

struct RayHit {
  bool found = false;
  int triangle = -1;
  double t = 0, b1 = 0, b2 = 0;
};

/// True when p is within rounding of its closest point `q` on triangle
/// (a, b, c): 16 ulps of the largest coordinate involved. SurfaceQuery::closest
/// then returns p itself, so a point already on the surface projects to itself
/// bit for bit (what makes a still scene bake identical atlases).
bool within_rounding_of_triangle(const Vec3& p, const Vec3& q, const Vec3& a, const Vec3& b, const Vec3& c);

/// Acceleration structure over one TriMesh. The mesh must outlive the query.
/// Thread-safe for concurrent queries once built.
class SurfaceQuery {
 public:
  explicit SurfaceQuery(const TriMesh& mesh);
  ~SurfaceQuery();
  SurfaceQuery(const SurfaceQuery&) = delete;
  SurfaceQuery& operator=(const SurfaceQuery&) = delete;

  const TriMesh& mesh() const { return mesh_; }
  /// Closest surface point within max_distance (metres; infinity = unbounded).
  /// Ties between equidistant triangles go to the lowest triangle index, so
  /// the answer does not depend on traversal order.
  ClosestHit closest(const Vec3& p, double max_distance) const;
  /// First hit along origin + t*dir for t in [t_min, t_max].
  RayHit intersect(const Vec3& origin, const Vec3& dir, double t_min, double t_max) const;

 private:
  struct Impl;
  const TriMesh& mesh_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace lapflow
