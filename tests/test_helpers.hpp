#pragma once

// ---- meshes built in code (patches tests; usable by anyone) ----------------
#include "lapflow/surface/mesh.hpp"
#include "lapflow/patches/patches.hpp"

namespace lapflow::test {
/// Icosphere of `subdivisions` levels (20 * 4^s triangles), outward CCW.
TriMesh icosphere(int subdivisions, double radius = 1.0, Vec3 center = {});
/// Regular grid on the plane z = `z` over [0, size_x] x [0, size_y], nx x ny
/// quads split into two CCW triangles each (normal +z).
TriMesh plane_grid(int nx, int ny, double size_x, double size_y, double z = 0);
/// Rotation of `v` about unit `axis` by `angle` radians (Rodrigues).
Vec3 rotate(const Vec3& v, const Vec3& axis, double angle);

// ---- patch sets ------------------------------------------------------------
/// seed_patches(surface, frame 0, options) run on `threads` worker threads
/// (the count goes back to all cores afterwards).
PatchSet seed_on_threads(const SurfaceQuery& surface, const PatchOptions& options, int threads);
/// Adds a failure unless both sets hold the same patches bit for bit: ids,
/// positions, rest uv, triangles, weights and the fluid triangles under the
/// vertices.
void expect_same_patches(const PatchSet& a, const PatchSet& b);
}  // namespace lapflow::test
