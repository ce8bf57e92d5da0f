// Per-vertex velocities sampled anywhere near the surface.
#include "lapflow/velocity.hpp"

namespace lapflow {

VelocityField vertex_velocity_field(const SurfaceQuery& query) {
  const TriMesh& mesh = query.mesh();
  // A mesh without velocities (or without triangles) moves nothing; the
  // caller decides whether that is acceptable (--allow-zero-velocity).
  if (!mesh.has_velocities() || mesh.empty()) return [](const Vec3&) { return Vec3{}; };
  // Embree's point query only culls by its radius: an unbounded query visits
  // many far triangles before the radius shrinks. Points sampled here are
  // near the surface (a patch vertex moved by a fraction of a frame, most
  // often one lying on this very surface), so try a radius of a fraction of
  // an edge first and widen only when nothing is that close. The closest
  // point within a small radius, when there is one, is the closest point.
  // (A first radius of 2 edges made Embree test ~18 triangles per query.)
  const double near = 2 * mean_edge_length(mesh) + 1e-9 * norm(bounding_box(mesh).size());
  return [&query, &mesh, near](const Vec3& p) {
    ClosestHit hit = query.closest(p, near / 16);
    if (!hit.found) hit = query.closest(p, near);
    if (!hit.found) hit = query.closest(p, 8 * near);
    if (!hit.found) hit = query.closest(p, INFINITY);
    if (!hit.found) return Vec3{};
    const Tri& f = mesh.triangles[hit.triangle];
    const double b0 = 1.0 - hit.b1 - hit.b2;
    return mesh.velocities[f[0]] * b0 + mesh.velocities[f[1]] * hit.b1 + mesh.velocities[f[2]] * hit.b2;
  };
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
