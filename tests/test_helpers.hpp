#pragma once

// ---- meshes built in code (patches tests; usable by anyone) ----------------
#include "lapflow/mesh.hpp"

namespace lapflow::test {
/// Icosphere of `subdivisions` levels (20 * 4^s triangles), outward CCW.
TriMesh icosphere(int subdivisions, double radius = 1.0, Vec3 center = {});
/// Regular grid on the plane z = `z` over [0, size_x] x [0, size_y], nx x ny
/// quads split into two CCW triangles each (normal +z).
TriMesh plane_grid(int nx, int ny, double size_x, double size_y, double z = 0);
/// Rotation of `v` about unit `axis` by `angle` radians (Rodrigues).
Vec3 rotate(const Vec3& v, const Vec3& axis, double angle);
}  // namespace lapflow::test
