// Per-vertex velocities sampled anywhere near the surface.
#include "lapflow/surface/velocity.hpp"

namespace lapflow {

VertexVelocity::VertexVelocity(const SurfaceQuery& query) : query_(&query) {
  // Embree's point query only culls by its radius: an unbounded query visits
  // many far triangles before the radius shrinks. Points sampled here are
  // near the surface (a patch vertex moved by a fraction of a frame, most
  // often one lying on this very surface), so try a radius of a fraction of
  // an edge first and widen only when nothing is that close. The closest
  // point within a small radius, when there is one, is the closest point.
  const TriMesh& mesh = query.mesh();
  near_ = 2 * mean_edge_length(mesh) + 1e-9 * norm(bounding_box(mesh).size());
}

Vec3 VertexVelocity::interpolate(int t, double b1, double b2) const {
  const TriMesh& mesh = query_->mesh();
  const Tri& f = mesh.triangles[t];
  const double b0 = 1.0 - b1 - b2;
  return mesh.velocities[f[0]] * b0 + mesh.velocities[f[1]] * b1 + mesh.velocities[f[2]] * b2;
}

bool VertexVelocity::within(const Vec3& p, double radius, Vec3& velocity, double& distance) const {
  const ClosestHit hit = query_->closest(p, radius);
  if (!hit.found) return false;
  velocity = interpolate(hit.triangle, hit.b1, hit.b2);
  distance = hit.distance;
  return true;
}

Vec3 VertexVelocity::operator()(const Vec3& p) const {
  Vec3 v;
  double d;
  for (const double radius : {near_ / 16, near_, 8 * near_, double(INFINITY)})
    if (within(p, radius, v, d)) return v;
  return Vec3{};
}

bool VertexVelocity::on_triangle(const Vec3& p, int t, double tolerance, Vec3& velocity) const {
  const TriMesh& mesh = query_->mesh();
  if (t < 0 || std::size_t(t) >= mesh.triangles.size() || !mesh.has_velocities()) return false;
  const Tri& f = mesh.triangles[t];
  const TrianglePoint q = closest_point_on_triangle(p, mesh.positions[f[0]], mesh.positions[f[1]], mesh.positions[f[2]]);
  if (!(norm2(q.point - p) <= tolerance * tolerance)) return false;
  velocity = interpolate(t, q.b1, q.b2);
  return true;
}

VelocityField vertex_velocity_field(const SurfaceQuery& query) {
  const TriMesh& mesh = query.mesh();
  // A mesh without velocities (or without triangles) moves nothing; the
  // caller decides whether that is acceptable (--allow-zero-velocity).
  if (!mesh.has_velocities() || mesh.empty()) return [](const Vec3&) { return Vec3{}; };
  return VertexVelocity(query);
}

VelocityField with_min_speed(VelocityField field, double min_speed) {
  if (!(min_speed > 0)) return field;
  const double min2 = min_speed * min_speed;
  return [field = std::move(field), min2](const Vec3& p) {
    const Vec3 v = field(p);
    return norm2(v) < min2 ? Vec3{} : v;
  };
}

}  // namespace lapflow
