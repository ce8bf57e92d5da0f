// Velocity fields: per-vertex (closest point + barycentric), the minimum
// speed filter, and OpenVDB grids against the real solver's vertex velocities.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cmath>

#include "io_test_helpers.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/core/parallel.hpp"
#include "lapflow/surface/surface_query.hpp"
#include "lapflow/surface/velocity.hpp"
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
  LAPFLOW_NEED_SHARED(test::shared_data_path());
  const std::string dir = test::shared_data_dir();
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
    // The shared data's README has the measured error; this bounds it.
    EXPECT_LT(rel[rel.size() / 2], 0.2);
    // Far outside the liquid the grid is at its background, zero.
    EXPECT_EQ(grid.sample({10, 10, 10}), Vec3());
  }
}

namespace lapflow {
namespace {

TEST(BandedVelocityField, ReproducesAnAffineFieldAndFallsBackFarFromTheSurface) {
  // Trilinear interpolation is exact for an affine field, so inside the band
  // the banded field equals the exact one up to float storage.
  TriMesh plane;
  const int n = 20;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) plane.positions.push_back({double(i) / n, double(j) / n, 0.0});
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i;
      plane.triangles.push_back({a, a + 1, a + n + 2});
      plane.triangles.push_back({a, a + n + 2, a + n + 1});
    }
  int exact_calls_far = 0;
  std::atomic<int> calls{0};
  auto affine = [&calls](const Vec3& p) {
    ++calls;
    return Vec3{0.5 + 2 * p.x - p.y, -1 + 0.25 * p.z, 3 * p.x + p.y};
  };
  const double h = mean_edge_length(plane);
  EXPECT_NEAR(h, (2 + std::sqrt(2.0)) / 3 / n, 1e-12);
  const VelocityField band = banded_velocity_field(affine, plane, h, 3);
  const int build_calls = calls;
  EXPECT_GT(build_calls, 0);
  for (int k = 0; k < 100; ++k) {
    const Vec3 p{0.1 + 0.8 * std::fmod(k * 0.618034, 1.0), 0.1 + 0.8 * std::fmod(k * 0.414214, 1.0), 0.01 * (k % 5)};
    const Vec3 a = band(p), e = affine(p);
    EXPECT_LT(norm(a - e), 1e-5) << k;
  }
  EXPECT_EQ(calls - build_calls, 100) << "the 100 exact calls above only";
  // Far above the plane the band knows nothing: the exact field answers.
  const int before = calls;
  const Vec3 far{0.5, 0.5, 2.0};
  EXPECT_LT(norm(band(far) - affine(far)), 1e-12);
  exact_calls_far = calls - before;
  EXPECT_EQ(exact_calls_far, 2);  // one from band(), one from the comparison
}

}  // namespace
}  // namespace lapflow

namespace lapflow {
namespace {

TEST(BandedVelocityField, AgreesWithExactVertexVelocitiesOnDamBreak) {
  LAPFLOW_NEED_SHARED(test::shared_data_path());
  const std::string dir = test::shared_data_dir();
  const TriMesh mesh = read_mesh(dir + "/dam_break/dam_break.0020.ply");
  const SurfaceQuery query(mesh);
  const VelocityField exact = vertex_velocity_field(query);
  const VelocityField band = banded_velocity_field(exact, mesh, 2 * mean_edge_length(mesh), 6);
  // Where advection samples: on the surface and up to a frame's motion off it.
  std::vector<double> rel;
  double max_speed = 0;
  for (const Vec3& v : mesh.velocities) max_speed = std::max(max_speed, norm(v));
  for (std::size_t i = 0; i < mesh.positions.size(); i += 7) {
    const Vec3 p = mesh.positions[i] + mesh.velocities[i] * (0.5 / 24.0);
    const Vec3 e = exact(p);
    rel.push_back(norm(band(p) - e) / max_speed);
  }
  std::sort(rel.begin(), rel.end());
  // Errors relative to the frame's peak speed: median under 1%, 95th under 5%.
  EXPECT_LT(rel[rel.size() / 2], 0.01);
  EXPECT_LT(rel[rel.size() * 95 / 100], 0.05);
}

}  // namespace
}  // namespace lapflow

namespace lapflow {
namespace {

TEST(BandedVelocityField, EveryPointInsideTheBandIsTrilinearAcrossBricksAndNegativeCoordinates) {
  // A sphere around the origin: the band spans negative and positive voxel
  // coordinates and many 8^3-voxel bricks, so samples fall on every side of
  // brick boundaries (where the 8 corners of a cell come from a brick's apron).
  // Trilinear interpolation reproduces an affine field, so inside the band the
  // banded field must equal the exact one up to float storage, without asking
  // the exact field; outside it the exact field answers, bit for bit.
  const TriMesh sphere = test::icosphere(3, 0.6, {-0.05, 0.02, 0.01});
  std::atomic<int> calls{0};
  const VelocityField exact = [&calls](const Vec3& p) {
    ++calls;
    return affine(p);
  };
  const double h = 0.02;  // 30 voxels per radius: several bricks across the sphere
  const VelocityField band = banded_velocity_field(exact, sphere, h, 3);
  const int built = calls;
  int inside = 0;
  for (int k = 0; k < 4000; ++k) {
    // Points on a sphere of radius 0.6 +- 1.5 voxels (inside the band, whose
    // half-width is 3 voxels around the vertices).
    const double u = std::fmod(k * 0.618034, 1.0), w = std::fmod(k * 0.754878, 1.0);
    const double z = 2 * u - 1, phi = 2 * M_PI * w, s = std::sqrt(1 - z * z);
    const double rad = 0.6 + h * (1.5 * std::fmod(k * 0.414214, 2.0) - 1.5);
    const Vec3 p = Vec3{s * std::cos(phi), s * std::sin(phi), z} * rad + Vec3{-0.05, 0.02, 0.01};
    const int before = calls;
    const Vec3 a = band(p);
    inside += calls == before;
    EXPECT_LT(norm(a - affine(p)), 2e-6) << k;
  }
  // The icosphere's chords sit up to ~0.012 m inside the sphere, so nearly
  // every point has all 8 corners in the band.
  EXPECT_GT(inside, 3900);
  EXPECT_EQ(calls - built, 4000 - inside);
  const Vec3 centre{-0.05, 0.02, 0.01};
  const int before = calls;
  EXPECT_EQ(band(centre).x, affine(centre).x);  // far from the surface: the exact field
  EXPECT_EQ(calls - before, 1);
}

}  // namespace
}  // namespace lapflow

namespace lapflow {
namespace {

TEST(BandedVelocityField, RingSearchGivesTheSameBandAsThePlainSearch) {
  // With per-vertex velocities the band searches each voxel's closest point
  // within a radius from its ring (a neighbour's distance plus the step);
  // any other field is sampled by calling it. The two must give the same
  // band bit for bit: the closest point within a radius that holds one is
  // the closest point. Wrapping the field in a lambda forces the plain path.
  TriMesh m = test::icosphere(3, 0.5, {0.1, -0.2, 0.05});
  // A non-affine field, so that any change of closest triangle would show.
  m.velocities.resize(m.positions.size());
  for (std::size_t i = 0; i < m.positions.size(); ++i) {
    const Vec3& p = m.positions[i];
    m.velocities[i] = {std::sin(7 * p.y) + p.z * p.z, std::cos(5 * p.x) * p.z, p.x * p.y - 0.3};
  }
  const SurfaceQuery q(m);
  const VelocityField vertex = vertex_velocity_field(q);
  const VelocityField plain = [&vertex](const Vec3& p) { return vertex(p); };
  const double h = 2 * mean_edge_length(m);
  for (int width : {1, 4}) {
    const VelocityField ringed = banded_velocity_field(vertex, m, h, width);
    const VelocityField searched = banded_velocity_field(plain, m, h, width);
    int compared = 0;
    for (int k = 0; k < 3000; ++k) {
      // Points from inside the sphere to (width + 1) voxels outside it.
      const double u = std::fmod(k * 0.618034, 1.0), w = std::fmod(k * 0.754878, 1.0);
      const double z = 2 * u - 1, phi = 2 * M_PI * w, s = std::sqrt(1 - z * z);
      const double rad = 0.5 + h * ((width + 1) * std::fmod(k * 0.414214, 2.0) - (width + 1));
      const Vec3 p = Vec3{s * std::cos(phi), s * std::sin(phi), z} * rad + Vec3{0.1, -0.2, 0.05};
      const Vec3 a = ringed(p), b = searched(p);
      ASSERT_TRUE(a.x == b.x && a.y == b.y && a.z == b.z) << "width " << width << " point " << k;
      ++compared;
    }
    EXPECT_EQ(compared, 3000);
  }
}

}  // namespace
}  // namespace lapflow
