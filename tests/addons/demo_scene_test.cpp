// The demo scene: exact velocities, surfaces consistent with them, a new mesh
// every frame, the start shape back at t = T, closed and volume-preserving.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <unordered_map>
#include <vector>

#include "io_test_helpers.hpp"
#include "lapflow/addons/demo_scene.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "lapflow/core/parallel.hpp"

namespace lapflow {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kVoxel = 1.0 / 64;  // coarse: keeps the suite fast
const Vec3 kCentre{0.35, 0.35, 0.35};
constexpr double kRadius = 0.15;
const double kSphereVolume = 4.0 / 3.0 * kPi * kRadius * kRadius * kRadius;

DemoOptions coarse(DemoCase scene = DemoCase::Vortex) {
  DemoOptions o;
  o.scene = scene;
  o.voxel_size = kVoxel;
  return o;
}
/// Frame at time t (the defaults: 24 fps, T = 2 s, so t = T is frame 49).
int frame_at(const DemoOptions& o, double t) { return int(std::lround(t * o.fps)) + 1; }

double volume(const TriMesh& m) {
  double v = 0;
  for (const Tri& t : m.triangles) v += dot(m.positions[t[0]], cross(m.positions[t[1]], m.positions[t[2]]));
  return v / 6;
}

/// Edges used by other than exactly two triangles.
std::size_t open_edges(const TriMesh& m) {
  std::map<std::pair<int, int>, int> uses;
  for (const Tri& t : m.triangles)
    for (int k = 0; k < 3; ++k) ++uses[{std::min(t[k], t[(k + 1) % 3]), std::max(t[k], t[(k + 1) % 3])}];
  std::size_t n = 0;
  for (const auto& [edge, count] : uses) n += count != 2;
  return n;
}

/// Largest distance from a point of `a` to the nearest vertex of `b` (hash
/// grid of cell `cell`; distances above `cell` are reported as `cell`).
double one_sided_distance(const std::vector<Vec3>& a, const std::vector<Vec3>& b, double cell) {
  auto key = [&](const Vec3& p, int di, int dj, int dk) {
    return (int64_t(std::floor(p.x / cell) + di) * 1024 + int64_t(std::floor(p.y / cell) + dj)) * 1024 +
           int64_t(std::floor(p.z / cell) + dk);
  };
  std::unordered_multimap<int64_t, int> grid;
  for (int i = 0; i < int(b.size()); ++i) grid.emplace(key(b[i], 0, 0, 0), i);
  double worst = 0;
  for (const Vec3& p : a) {
    double best = cell;
    for (int d = 0; d < 27; ++d) {
      const auto range = grid.equal_range(key(p, d % 3 - 1, d / 3 % 3 - 1, d / 9 - 1));
      for (auto it = range.first; it != range.second; ++it) best = std::min(best, norm(b[it->second] - p));
    }
    worst = std::max(worst, best);
  }
  return worst;
}
double hausdorff(const TriMesh& a, const TriMesh& b, double cell) {
  return std::max(one_sided_distance(a.positions, b.positions, cell), one_sided_distance(b.positions, a.positions, cell));
}

TEST(DemoScene, VelocityIsTheEnrightField) {
  // The formula as published, written out independently of the library.
  const double T = 2.0;
  for (const Vec3 p : {Vec3{0.1, 0.2, 0.3}, Vec3{0.35, 0.35, 0.35}, Vec3{0.7, 0.4, 0.9}, Vec3{0.5, 0.5, 0.5}})
    for (double t : {0.0, 0.3, 1.0, 1.7}) {
      const double s = std::cos(kPi * t / T);
      const Vec3 expected{2 * std::pow(std::sin(kPi * p.x), 2) * std::sin(2 * kPi * p.y) * std::sin(2 * kPi * p.z) * s,
                          -std::sin(2 * kPi * p.x) * std::pow(std::sin(kPi * p.y), 2) * std::sin(2 * kPi * p.z) * s,
                          -std::sin(2 * kPi * p.x) * std::sin(2 * kPi * p.y) * std::pow(std::sin(kPi * p.z), 2) * s};
      const Vec3 v = demo_velocity(DemoCase::Vortex, p, t, T);
      EXPECT_NEAR(norm(v - expected), 0, 1e-12) << "p " << p.x << "," << p.y << "," << p.z << " t " << t;
    }
  // The slab's swirl is planar.
  EXPECT_EQ(demo_velocity(DemoCase::Slab, {0.3, 0.6, 0.5}, 0.4, 2).z, 0);
}

TEST(DemoScene, VertexVelocitiesAreTheAnalyticField) {
  for (DemoCase scene : {DemoCase::Vortex, DemoCase::Slab}) {
    const DemoOptions o = coarse(scene);
    const int f = 9;
    const TriMesh m = demo_frame(o, f);
    ASSERT_FALSE(m.empty());
    ASSERT_EQ(m.velocities.size(), m.positions.size());
    const double t = (f - 1) / o.fps;
    for (std::size_t i = 0; i < m.positions.size(); ++i)
      ASSERT_EQ(m.velocities[i], demo_velocity(scene, m.positions[i], t, o.period)) << "vertex " << i;
  }
}

TEST(DemoScene, SurfaceMovesWithItsVelocity) {
  // Vertices of frame f carried by their velocity over one frame (midpoint
  // rule, analytic field) land on frame f+1's surface, and the surface at t
  // traced back to t = 0 is the start sphere: surface and velocity agree.
  const DemoOptions o = coarse();
  const int f = 13;
  const double t = (f - 1) / o.fps, dt = 1 / o.fps;
  const TriMesh a = demo_frame(o, f), b = demo_frame(o, f + 1);
  std::vector<Vec3> moved(a.positions.size());
  for (std::size_t i = 0; i < moved.size(); ++i) {
    const Vec3 mid = a.positions[i] + a.velocities[i] * (dt / 2);
    moved[i] = a.positions[i] + demo_velocity(o.scene, mid, t + dt / 2, o.period) * dt;
  }
  EXPECT_LT(one_sided_distance(moved, b.positions, 4 * kVoxel), 1.0 * kVoxel);
  double worst = 0;
  for (const Vec3& p : a.positions)
    worst = std::max(worst, std::abs(norm(demo_flow_map(o.scene, p, t, 0, o.period) - kCentre) - kRadius));
  // Vertices sit on the voxel-interpolated zero set; traced back, a stretch
  // of at most ~2.5 separates them from the sphere.
  EXPECT_LT(worst, 1.5 * kVoxel);
}

TEST(DemoScene, ConsecutiveFramesAreDifferentMeshes) {
  const DemoOptions o = coarse();
  TriMesh prev = demo_frame(o, 1);
  for (int f = 2; f <= 9; ++f) {
    const TriMesh m = demo_frame(o, f);
    const bool different_counts = m.vertex_count() != prev.vertex_count() || m.triangle_count() != prev.triangle_count();
    EXPECT_TRUE(different_counts || m.positions != prev.positions) << "frame " << f;
    EXPECT_TRUE(different_counts) << "frame " << f << ": the remeshing should change the connectivity";
    prev = m;
  }
}

TEST(DemoScene, VortexReturnsToTheStartShapeAtPeriod) {
  const DemoOptions o = coarse();
  const TriMesh start = demo_frame(o, 1);
  const TriMesh back = demo_frame(o, frame_at(o, o.period));
  const TriMesh mid = demo_frame(o, frame_at(o, o.period / 2));
  EXPECT_NEAR(volume(start), kSphereVolume, 0.02 * kSphereVolume);
  EXPECT_NEAR(volume(back), volume(start), 0.02 * volume(start));
  EXPECT_LT(hausdorff(start, back, 4 * kVoxel), 1.5 * kVoxel);
  // The mid-period shape is far from the start: this is not a still scene.
  EXPECT_GT(hausdorff(start, mid, 0.5), 10 * kVoxel);
  // The start shape is the sphere of Enright et al. to within the voxel.
  for (const Vec3& p : start.positions) ASSERT_LT(std::abs(norm(p - kCentre) - kRadius), 0.5 * kVoxel);
}

TEST(DemoScene, SlabReturnsToTheStartShapeAtPeriod) {
  const DemoOptions o = coarse(DemoCase::Slab);
  const TriMesh start = demo_frame(o, 1);
  const TriMesh back = demo_frame(o, frame_at(o, o.period));
  EXPECT_NEAR(volume(back), volume(start), 0.02 * volume(start));
  EXPECT_LT(hausdorff(start, back, 4 * kVoxel), 1.5 * kVoxel);
  // A thin slab: 4 cm thick around z = 0.5 on every frame.
  for (int f : {1, 25}) {
    const Box3 box = bounding_box(demo_frame(o, f));
    EXPECT_NEAR(box.lo.z, 0.48, kVoxel);
    EXPECT_NEAR(box.hi.z, 0.52, kVoxel);
  }
}

TEST(DemoScene, VortexIsClosedAndKeepsItsVolume) {
  const DemoOptions o = coarse();
  for (int f : {1, 7, 13, 19, 25, 31}) {
    const TriMesh m = demo_frame(o, f);
    EXPECT_EQ(open_edges(m), 0u) << "frame " << f;
    // Divergence-free field: the volume is conserved up to the voxel.
    EXPECT_NEAR(volume(m), kSphereVolume, 0.05 * kSphereVolume) << "frame " << f;
    int components = 0;
    std::vector<int> of_triangle;
    components = triangle_components(m, of_triangle);
    EXPECT_EQ(components, 1) << "frame " << f;
  }
}

TEST(DemoScene, SlabTailSplitsOffAndMergesBack) {
  // At the default voxel (1/128 m) the spiral's thin tail pinches off around
  // frame 14 and rejoins; the slab is one piece again at t = T. Every frame
  // is closed, the thin tail included.
  DemoOptions o;
  o.scene = DemoCase::Slab;
  std::vector<int> of_triangle;
  for (auto [frame, pieces] : {std::pair{1, 1}, std::pair{14, 2}, std::pair{17, 1}, std::pair{49, 1}}) {
    const TriMesh m = demo_frame(o, frame);
    EXPECT_EQ(triangle_components(m, of_triangle), pieces) << "frame " << frame;
    EXPECT_EQ(open_edges(m), 0u) << "frame " << frame;
  }
}

TEST(DemoScene, SameFramesForAnyThreadCount) {
  const DemoOptions o = coarse();
  set_thread_count(1);
  const TriMesh one = demo_frame(o, 17);
  set_thread_count(2);
  const TriMesh two = demo_frame(o, 17);
  set_thread_count(0);
  EXPECT_EQ(one.positions, two.positions);
  EXPECT_EQ(one.triangles, two.triangles);
  EXPECT_EQ(one.velocities, two.velocities);
}

TEST(DemoScene, VoxelSizeForATriangleBudget) {
  for (DemoCase scene : {DemoCase::Vortex, DemoCase::Slab}) {
    DemoOptions o = coarse(scene);
    o.voxel_size = demo_voxel_size_for(scene, 8000);
    const double n = double(demo_frame(o, 1).triangle_count());
    EXPECT_GT(n, 8000 * 0.75);
    EXPECT_LT(n, 8000 * 1.25);
  }
  EXPECT_LT(demo_voxel_size_for(DemoCase::Vortex, 1e5), demo_voxel_size_for(DemoCase::Vortex, 2e4));
}

TEST(DemoScene, WritesAPlySequenceWithVelocities) {
  test::TempDir dir("demo");
  DemoOptions o = coarse();
  o.frames = 3;
  std::vector<int> seen;
  const DemoSequenceStats s =
      write_demo_sequence(o, dir.str(), "blob", [&](int f, const TriMesh&) { seen.push_back(f); });
  EXPECT_EQ(seen, (std::vector<int>{1, 2, 3}));
  EXPECT_EQ(s.frames, 3);
  for (int f = 1; f <= 3; ++f) {
    const TriMesh expected = demo_frame(o, f);
    const TriMesh m = read_mesh(demo_frame_path(dir.str(), "blob", f));
    ASSERT_EQ(m.triangles, expected.triangles);
    ASSERT_EQ(m.velocities.size(), expected.velocities.size());
    for (std::size_t i = 0; i < m.positions.size(); ++i) {
      EXPECT_NEAR(norm(m.positions[i] - expected.positions[i]), 0, 1e-6);
      EXPECT_NEAR(norm(m.velocities[i] - expected.velocities[i]), 0, 1e-6);
    }
    EXPECT_GE(m.triangle_count(), s.triangles_min);
    EXPECT_LE(m.triangle_count(), s.triangles_max);
  }
  EXPECT_TRUE(std::filesystem::exists(dir / "blob.0001.ply"));
}

}  // namespace
}  // namespace lapflow

namespace lapflow {
namespace {

TEST(DemoCommand, WritesTheSequenceAndASummary) {
  test::TempDir scratch("demo_cli");
  const std::string out = scratch / "seq";
  std::string stdout_text, stderr_text;
  const int code = test::run_command(std::string(LAPFLOW_BINARY) + " demo --out '" + out +
                                         "' --frames 3 --resolution 40 --case slab --name s --threads 1 --atlas-resolution 128",
                                     &stdout_text, &stderr_text, scratch);
  EXPECT_EQ(code, 0) << stderr_text;
  for (int f = 1; f <= 3; ++f) EXPECT_TRUE(std::filesystem::exists(demo_frame_path(out, "s", f))) << f;
  EXPECT_FALSE(std::filesystem::exists(demo_frame_path(out, "s", 4)));
  EXPECT_NE(stderr_text.find("triangles per frame: min"), std::string::npos) << stderr_text;
  // Usage mistakes exit with 2.
  EXPECT_EQ(test::run_command(std::string(LAPFLOW_BINARY) + " demo --out '" + out + "' --case ocean", nullptr,
                              nullptr, scratch),
            2);
}

}  // namespace
}  // namespace lapflow
