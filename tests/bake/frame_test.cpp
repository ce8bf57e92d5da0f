// load_frame(): the one reader of frames and their velocity for bake,
// patches, eval and the benchmark.
#include <gtest/gtest.h>

#include "io_test_helpers.hpp"
#include "lapflow/bake/frame.hpp"
#include "lapflow/core/errors.hpp"
#include "lapflow/io/mesh_io.hpp"
#include "test_helpers.hpp"

namespace lapflow {
namespace {

using test::TempDir;

// A 10 x 10 plane over [0, 1]^2 whose vertices move with v = (speed * x, 0, 0).
TriMesh moving_plane(double speed) {
  TriMesh m = test::plane_grid(10, 10, 1.0, 1.0);
  m.velocities.resize(m.positions.size());
  for (std::size_t i = 0; i < m.positions.size(); ++i) m.velocities[i] = {speed * m.positions[i].x, 0, 0};
  return m;
}

TEST(LoadFrame, VertexVelocityIsInterpolatedOnTheSurface) {
  TempDir dir("load_frame");
  write_ply(dir / "plane.0003.ply", moving_plane(2.0));
  FrameSource source;
  source.mesh_pattern = dir / "plane.%04d.ply";
  source.velocity_band = 0;  // exact: closest point and barycentrics
  const std::unique_ptr<Frame> f = load_frame(source, 3);
  EXPECT_EQ(f->number, 3);
  EXPECT_EQ(f->path, dir / "plane.0003.ply");
  EXPECT_EQ(f->mesh.triangle_count(), 200u);
  EXPECT_EQ(f->velocity_source, "vertex");
  ASSERT_NE(f->surface, nullptr);
  // v is linear in x, so barycentric interpolation is exact between vertices.
  const Vec3 v = f->velocity({0.37, 0.52, 0.0});
  EXPECT_NEAR(v.x, 2.0 * 0.37, 1e-6);  // PLY stores float
  EXPECT_NEAR(v.y, 0.0, 1e-12);
  EXPECT_NEAR(v.z, 0.0, 1e-12);
}

TEST(LoadFrame, BandedVelocityStaysCloseToTheExactOne) {
  TempDir dir("load_frame_band");
  write_ply(dir / "plane.0001.ply", moving_plane(2.0));
  FrameSource source;
  source.mesh_pattern = dir / "plane.%04d.ply";  // the bake's default band
  const std::unique_ptr<Frame> f = load_frame(source, 1);
  EXPECT_NE(f->velocity_source.find("band"), std::string::npos) << f->velocity_source;
  // Trilinear in a linear field: exact up to float storage.
  EXPECT_NEAR(f->velocity({0.37, 0.52, 0.0}).x, 0.74, 1e-5);
}

TEST(LoadFrame, MinSpeedZeroesSlowVelocities) {
  TempDir dir("load_frame_min");
  write_ply(dir / "plane.0001.ply", moving_plane(0.1));  // at most 0.1 m/s
  FrameSource source;
  source.mesh_pattern = dir / "plane.%04d.ply";
  source.velocity_band = 0;
  source.min_speed = 0.05;
  const std::unique_ptr<Frame> f = load_frame(source, 1);
  EXPECT_EQ(norm(f->velocity({0.3, 0.5, 0.0})), 0.0);  // 0.03 m/s: at rest
  EXPECT_NEAR(f->velocity({0.9, 0.5, 0.0}).x, 0.09, 1e-6);  // faster: kept
}

TEST(LoadFrame, MeshWithoutVelocityIsAnErrorUnlessAllowed) {
  TempDir dir("load_frame_zero");
  write_ply(dir / "still.0002.ply", test::plane_grid(4, 4, 1.0, 1.0));
  FrameSource source;
  source.mesh_pattern = dir / "still.%04d.ply";
  try {
    load_frame(source, 2);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), dir / "still.0002.ply");
    EXPECT_NE(std::string(e.what()).find("--allow-zero-velocity"), std::string::npos) << e.what();
    EXPECT_EQ(e.frame(), 2);
  }
  source.allow_zero_velocity = true;
  const std::unique_ptr<Frame> f = load_frame(source, 2);
  EXPECT_EQ(f->velocity_source, "zero");
  EXPECT_EQ(norm(f->velocity({0.5, 0.5, 0.0})), 0.0);
  // read_frame_input, which eval uses, applies the same rule.
  source.allow_zero_velocity = false;
  EXPECT_THROW(read_frame_input(source, 2), InputError);
}

TEST(LoadFrame, MissingFrameNamesTheFile) {
  TempDir dir("load_frame_missing");
  FrameSource source;
  source.mesh_pattern = dir / "gone.%04d.ply";
  try {
    load_frame(source, 7);
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), dir / "gone.0007.ply");
    EXPECT_EQ(e.frame(), 7);
  }
}

}  // namespace
}  // namespace lapflow
