// Velocity fields: per-vertex (closest point + barycentric), the minimum
// speed filter, and OpenVDB grids against the real solver's vertex velocities.
#include <gtest/gtest.h>

#include <algorithm>

#include "io_test_helpers.hpp"
#include "lapflow/mesh_io.hpp"
#include "lapflow/parallel.hpp"
#include "lapflow/velocity.hpp"
#include "test_helpers.hpp"

using namespace lapflow;

namespace {
// An affine field v(p) = A p + b: barycentric interpolation reproduces it
// exactly on every triangle.
Vec3 affine(const Vec3& p) { return {0.5 * p.x - 2 * p.y + 0.1, p.z + 0.3 * p.x, -p.y + 2 * p.z - 0.7}; }
}  // namespace

TEST(VertexVelocityField, ReproducesAnAffineFieldOnTheSurface) {
  TriMesh m = test::icosphere(2, 0.5, {0.2, -0.1, 0.3});
  for (const Vec3& p : m.positions) m.velocities.push_back(affine(p));
  const SurfaceQuery q(m);
  const VelocityField v = vertex_velocity_field(q);
  const std::vector<Vec3> normals = vertex_normals(m);
  for (int t = 0; t < int(m.triangles.size()); t += 7) {
    const Tri& f = m.triangles[t];
    const double b1 = 0.2 + 0.5 * hash_to_unit(hash64(t, 1)) * 0.6, b2 = 0.1 + 0.2 * hash_to_unit(hash64(t, 2));
    const Vec3 on = m.positions[f[0]] * (1 - b1 - b2) + m.positions[f[1]] * b1 + m.positions[f[2]] * b2;
    const Vec3 got = v(on);
    EXPECT_NEAR(norm(got - affine(on)), 0, 1e-9) << "triangle " << t;
    // Slightly off the surface along the face normal: the closest point (and
    // so the velocity) is the same surface point.
    const Vec3 n = normalized(triangle_normal_area2(m, t));
    EXPECT_NEAR(norm(v(on + n * 1e-3) - affine(on)), 0, 1e-7) << "triangle " << t;
  }
  // At a vertex, the vertex's own velocity.
  EXPECT_NEAR(norm(v(m.positions[17]) - m.velocities[17]), 0, 1e-9);
}

TEST(VertexVelocityField, NoVelocitiesMeansZero) {
  const TriMesh m = test::icosphere(1);
  const SurfaceQuery q(m);
  EXPECT_EQ(vertex_velocity_field(q)({1, 2, 3}), Vec3());
}

TEST(WithMinSpeed, ZeroesOnlyTheSlowVelocities) {
  const VelocityField f = [](const Vec3& p) { return Vec3{p.x, 0, 0}; };
  const VelocityField g = with_min_speed(f, 0.05);
  EXPECT_EQ(g({0.04, 0, 0}), Vec3());
  EXPECT_EQ(g({-0.049, 0, 0}), Vec3());
  EXPECT_EQ(g({0.06, 0, 0}), Vec3(0.06, 0, 0));
  EXPECT_EQ(g({-2, 0, 0}), Vec3(-2, 0, 0));
  EXPECT_EQ(with_min_speed(f, 0)({0.01, 0, 0}), Vec3(0.01, 0, 0));
}

TEST(VelocityGrid, AgreesWithDamBreakVertexVelocities) {
  const std::string dir = test::shared_data_dir();
  if (dir.empty()) GTEST_SKIP() << "../shared/data is absent: VDB sampling test skipped";
  for (int frame : {10, 40}) {
    SCOPED_TRACE(frame);
    const FramePattern ply(dir + "/dam_break/dam_break.%04d.ply"), vdb(dir + "/dam_break/dam_break.%04d.vdb");
    const TriMesh m = read_mesh(ply.path(frame));
    const VelocityGrid grid(vdb.path(frame));
    EXPECT_EQ(grid.grid_name(), "velocity");
    // The liquid surface lies inside the band of active voxels.
    const Box3 active = grid.active_bounds(), mesh = bounding_box(m);
    for (int k = 0; k < 3; ++k) {
      EXPECT_LE(active.lo[k], mesh.lo[k]);
      EXPECT_GE(active.hi[k], mesh.hi[k]);
    }
    const VelocityField field = grid_velocity_field(grid);
    std::vector<Vec3> sampled(m.vertex_count());
    parallel_for(sampled.size(), [&](std::size_t b, std::size_t e) {
      for (std::size_t i = b; i < e; ++i) sampled[i] = field(m.positions[i]);
    });
    std::vector<double> rel;
    for (std::size_t i = 0; i < sampled.size(); ++i) {
      EXPECT_EQ(sampled[i], grid.sample(m.positions[i]));  // concurrent = serial, bit for bit
      const double s = norm(m.velocities[i]);
      if (s > 0.1) rel.push_back(norm(sampled[i] - m.velocities[i]) / s);
    }
    ASSERT_GT(rel.size(), m.vertex_count() / 2);
    std::nth_element(rel.begin(), rel.begin() + rel.size() / 2, rel.end());
    // The data README measures 6-11%.
    EXPECT_LT(rel[rel.size() / 2], 0.2);
    // Far outside the liquid the grid is at its background, zero.
    EXPECT_EQ(grid.sample({10, 10, 10}), Vec3());
  }
}
